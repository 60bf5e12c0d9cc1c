// tbsp::Visualizer offscreen (label ui: runs under xvfb-run, see tests/CMakeLists.txt).
#include <gtest/gtest.h>

#include <cstdlib>
#include <opencv2/imgcodecs.hpp>
#include <pcl/point_cloud.h>
#include <pcl/point_types.h>

#include "tbsp/core/error.h"
#include "tbsp/mesh/primitives.h"
#include "tbsp/vtk/visualizer.h"
#include "test_util.h"

namespace {

using tbsp::test::temp_dir;

// pixels that differ from the white background
int foreground(const cv::Mat& img, cv::Point2d* centroid = nullptr) {
  int n = 0;
  double sx = 0, sy = 0;
  for (int y = 0; y < img.rows; ++y)
    for (int x = 0; x < img.cols; ++x) {
      const cv::Vec3b p = img.at<cv::Vec3b>(y, x);
      if (p[0] < 245 || p[1] < 245 || p[2] < 245) {
        ++n;
        sx += x;
        sy += y;
      }
    }
  if (centroid && n > 0) *centroid = {sx / n, sy / n};
  return n;
}

// pixels within `tol` (per channel, 0-255) of an RGB colour in [0, 1]
int pixels_near(const cv::Mat& bgr, const Eigen::Vector3d& rgb, int tol) {
  int n = 0;
  for (int y = 0; y < bgr.rows; ++y)
    for (int x = 0; x < bgr.cols; ++x) {
      const cv::Vec3b p = bgr.at<cv::Vec3b>(y, x);
      if (std::abs(p[2] - rgb.x() * 255) <= tol && std::abs(p[1] - rgb.y() * 255) <= tol && std::abs(p[0] - rgb.z() * 255) <= tol) ++n;
    }
  return n;
}

tbsp::VisualizerOptions offscreen(int w, int h) {
  tbsp::VisualizerOptions o;
  o.offscreen = true;
  o.width = w;
  o.height = h;
  return o;
}

}  // namespace

TEST(Visualizer, PclCloudWithAHeatmapRendersOffscreenInItsColours) {
  // a PCL cloud on a plane, coloured by x: the left third low (dark blue), the right third high (yellow)
  pcl::PointCloud<pcl::PointXYZ> cloud;
  Eigen::VectorXd value;
  std::vector<double> vals;
  for (int i = 0; i < 60; ++i)
    for (int j = 0; j < 40; ++j) {
      cloud.push_back(pcl::PointXYZ(float(i) / 59.f, float(j) / 59.f, 0.f));
      vals.push_back(i < 20 ? 0.0 : (i >= 40 ? 1.0 : 0.5));
    }
  cloud.push_back(pcl::PointXYZ(NAN, 0, 0));  // skipped
  value = Eigen::Map<Eigen::VectorXd>(vals.data(), Eigen::Index(vals.size()));
  tbsp::Visualizer viz(offscreen(400, 300));
  viz.addPointCloud("cloud", cloud, 8.0);
  viz.setScalars("cloud", value, {"value", tbsp::ColorMap::Viridis, 0.0, 1.0});
  EXPECT_THROW(viz.setScalars("cloud", Eigen::VectorXd::Zero(5), {}), tbsp::InvalidInput);
  EXPECT_THROW(viz.setScalars("nope", value, {}), tbsp::InvalidInput);
  viz.addSpheres("balls", Eigen::MatrixX3d::Zero(1, 3), 0.1);
  EXPECT_THROW(viz.setScalars("balls", Eigen::VectorXd::Zero(1), {}), tbsp::InvalidInput) << "spheres have no per-point colours";
  viz.remove("balls");
  viz.resetCamera();
  const auto dir = temp_dir("viz_cloud");
  const std::string png = (dir / "cloud.png").string();
  viz.saveScreenshot(png);
  const cv::Mat img = cv::imread(png);
  ASSERT_FALSE(img.empty());
  EXPECT_EQ(img.cols, 400);
  EXPECT_EQ(img.rows, 300);
  // both ends of the colour map appear (points are unlit: their colour is the map's)
  const int low = pixels_near(img, tbsp::colormap_color(tbsp::ColorMap::Viridis, 0, 0, 1), 12);
  const int high = pixels_near(img, tbsp::colormap_color(tbsp::ColorMap::Viridis, 1, 0, 1), 12);
  EXPECT_GT(low, 500) << "dark-blue (low) pixels";
  EXPECT_GT(high, 500) << "yellow (high) pixels";
}

TEST(Visualizer, MeshIsCentredAndSelectionSeesOnlyTheFrontSide) {
  const tbsp::TriMesh sphere = tbsp::make_icosphere(3);
  tbsp::Visualizer viz(offscreen(320, 240));
  viz.addMesh("s", sphere);
  viz.setCameraPose({0, 0, 5}, {0, 0, 0}, {0, 1, 0});
  viz.resetCamera();
  const auto dir = temp_dir("viz_mesh");
  viz.saveScreenshot((dir / "s.png").string());
  const cv::Mat img = cv::imread((dir / "s.png").string());
  cv::Point2d c;
  const int n = foreground(img, &c);
  EXPECT_GT(n, 320 * 240 / 10) << "the sphere covers a good part of the view";
  EXPECT_NEAR(c.x, 160, 8);
  EXPECT_NEAR(c.y, 120, 8);
  // whole-window rubber band from +z: the front hemisphere only
  const std::vector<int> sel = viz.selectVisiblePoints("s", 0, 0, 319, 239);
  ASSERT_FALSE(sel.empty());
  int back = 0;
  for (int v : sel) back += sphere.V(v, 2) < -0.05;
  EXPECT_EQ(back, 0) << "vertices behind the sphere are hidden";
  int front = 0;
  for (Eigen::Index v = 0; v < sphere.V.rows(); ++v) front += sphere.V(v, 2) > 0.3;
  EXPECT_GE(int(sel.size()), front) << "every clearly visible vertex is selected";
  // a rectangle on the left half selects only x < 0.1
  for (int v : viz.selectVisiblePoints("s", 0, 0, 150, 239)) EXPECT_LT(sphere.V(v, 0), 0.1);
  // moving the vertices moves the picture
  Eigen::MatrixX3d V = sphere.V;
  V.col(0).array() += 0.8;
  viz.updatePositions("s", V);
  EXPECT_THROW(viz.updatePositions("s", V.topRows(3)), tbsp::InvalidInput);
  viz.saveScreenshot((dir / "moved.png").string());
  cv::Point2d c2;
  foreground(cv::imread((dir / "moved.png").string()), &c2);
  EXPECT_GT(c2.x, c.x + 20);
}

TEST(Visualizer, TetMeshCameraSpheresLinesAndBadArguments) {
  tbsp::TetMesh t;
  t.V.resize(4, 3);
  t.V << 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1;
  t.T.resize(1, 4);
  t.T << 0, 1, 2, 3;
  tbsp::Visualizer viz(offscreen(200, 150));
  viz.addTetMesh("t", t);
  tbsp::Camera cam("c", 40, 30, (Eigen::Matrix3d() << 40, 0, 20, 0, 40, 15, 0, 0, 1).finished(), Eigen::Matrix3d::Identity(),
                   Eigen::Vector3d(0, 0, 3));
  viz.addCamera("cam", cam, 0.5, std::vector<unsigned char>(40 * 30 * 3, 128));
  EXPECT_THROW(viz.addCamera("bad", cam, 0.5, std::vector<unsigned char>(10, 0)), tbsp::InvalidInput);
  viz.addSpheres("h", Eigen::MatrixX3d::Zero(2, 3), 0.05);
  viz.addLines("l", Eigen::MatrixX3d::Zero(1, 3), Eigen::MatrixX3d::Ones(1, 3));
  EXPECT_THROW(viz.addLines("l2", Eigen::MatrixX3d::Zero(2, 3), Eigen::MatrixX3d::Ones(1, 3)), tbsp::InvalidInput);
  EXPECT_THROW(viz.addSpheres("h2", Eigen::MatrixX3d::Zero(2, 3), 0.0), tbsp::InvalidInput);
  tbsp::TriMesh bad;
  bad.V = Eigen::MatrixX3d::Zero(3, 3);
  bad.F.resize(1, 3);
  bad.F << 0, 1, 7;
  EXPECT_THROW(viz.addMesh("bad", bad), tbsp::InvalidInput);
  EXPECT_EQ(viz.ids(), (std::vector<std::string>{"t", "cam", "h", "l"}));
  viz.remove("h");
  EXPECT_FALSE(viz.contains("h"));
  viz.setCameraFrom(cam);
  const auto dir = temp_dir("viz_tet");
  viz.saveScreenshot((dir / "t.png").string());
  EXPECT_GT(foreground(cv::imread((dir / "t.png").string())), 200);
  // an unwritable path: FileError, nothing left behind
  EXPECT_THROW(viz.saveScreenshot((dir / "no_such_dir" / "x.png").string()), tbsp::FileError);
  tbsp::VisualizerOptions bad_o;
  bad_o.width = 3;
  EXPECT_THROW(tbsp::Visualizer{bad_o}, tbsp::InvalidInput);
}

TEST(Visualizer, WithoutADisplayItSaysHowToGetOne) {
  const char* d = std::getenv("DISPLAY");
  const std::string saved = d ? d : "";
  ::unsetenv("DISPLAY");
  try {
    tbsp::Visualizer viz;
    FAIL() << "expected InvalidInput";
  } catch (const tbsp::InvalidInput& e) {
    EXPECT_NE(std::string(e.what()).find("xvfb-run"), std::string::npos) << e.what();
  }
  if (!saved.empty()) ::setenv("DISPLAY", saved.c_str(), 1);
}
