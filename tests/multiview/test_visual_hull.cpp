// Visual hull by voxel carving and the registration of a template to it, against analytic cases:
// a sphere seen by a ring of cameras (the hull contains it, its samples lie on the silhouette
// cones), and an asymmetric blob moved by a known similarity.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <string>

#include <opencv2/imgproc.hpp>

#include "tbsp/core/error.h"
#include "tbsp/mesh/primitives.h"
#include "tbsp/multiview/rasterizer.h"
#include "tbsp/multiview/visual_hull.h"

using namespace tbsp;

namespace {

// `n` cameras on a ring of radius `radius` at two heights, looking at `target`.
std::vector<Camera> ring(int n, double radius, int size, const Eigen::Vector3d& target = Eigen::Vector3d::Zero(), double arc = 2 * M_PI) {
  std::vector<Camera> cams;
  for (int k = 0; k < n; ++k) {
    const double a = arc * k / (arc >= 2 * M_PI ? n : std::max(1, n - 1));
    const double h = (k % 2 ? 0.8 : -0.5);
    const Eigen::Vector3d eye(radius * std::cos(a), radius * std::sin(a), h);
    cams.push_back(Camera::lookAt("cam" + std::to_string(k), size, size, 50 * M_PI / 180, eye, target, Eigen::Vector3d::UnitZ()));
  }
  return cams;
}

std::vector<cv::Mat> silhouettes_of(const TriMesh& m, const std::vector<Camera>& cams) {
  const std::vector<RenderBuffers> buf = Rasterizer().renderViews(m, cams);
  std::vector<cv::Mat> s;
  for (const auto& b : buf) s.push_back(cv::Mat(b.height, b.width, CV_8U, const_cast<std::uint8_t*>(b.mask.data())).clone());
  return s;
}

// Distance (pixels) from pixel p to the nearest boundary between foreground and background.
double contour_distance(const cv::Mat& sil, const Eigen::Vector2d& p) {
  double best = 1e9;
  const int x0 = int(std::lround(p.x())), y0 = int(std::lround(p.y()));
  for (int y = std::max(0, y0 - 6); y <= std::min(sil.rows - 2, y0 + 6); ++y)
    for (int x = std::max(0, x0 - 6); x <= std::min(sil.cols - 2, x0 + 6); ++x) {
      const bool a = sil.at<std::uint8_t>(y, x) >= 128;
      if (a != (sil.at<std::uint8_t>(y, x + 1) >= 128)) best = std::min(best, std::hypot(x + 0.5 - p.x(), y - p.y()));
      if (a != (sil.at<std::uint8_t>(y + 1, x) >= 128)) best = std::min(best, std::hypot(x - p.x(), y + 0.5 - p.y()));
    }
  return best;
}

TriMesh blob() {
  TriMesh s = make_icosphere(4, 0.5);
  const Eigen::Vector3d bump = Eigen::Vector3d(0.6, 0.6, 0.5).normalized();
  for (Eigen::Index i = 0; i < s.V.rows(); ++i) {
    const Eigen::Vector3d v = s.V.row(i).transpose();
    const double g = 0.5 * std::exp(-(v.normalized() - bump).squaredNorm() / 0.15);
    s.V.row(i) = ((1.0 + g) * v).cwiseProduct(Eigen::Vector3d(1.0, 0.7, 1.4)).transpose();
  }
  return s;
}

}  // namespace

TEST(VisualHull, ContainsASphereAndItsSamplesLieOnTheSilhouetteCones) {
  const double r = 0.5;
  const TriMesh sphere = make_icosphere(5, r);
  const std::vector<Camera> cams = ring(8, 3.0, 240);
  const std::vector<cv::Mat> sil = silhouettes_of(sphere, cams);
  VisualHullOptions o;
  o.resolution = 64;
  const VisualHull h = compute_visual_hull(cams, sil, o);
  ASSERT_GT(h.points.rows(), 1000);
  // contains the sphere: every voxel centre inside the sphere (with a pixel of slack) is occupied
  const double px = 3.0 / cams[0].K()(0, 0);  // a pixel at the sphere's distance, world units
  long inner = 0, missed = 0;
  for (int z = 0; z < h.dims.z(); ++z)
    for (int y = 0; y < h.dims.y(); ++y)
      for (int x = 0; x < h.dims.x(); ++x)
        if (h.center(x, y, z).norm() < r - 2 * px) {
          ++inner;
          missed += !h.occupied[h.index(x, y, z)];
        }
  EXPECT_GT(inner, 10000);
  EXPECT_EQ(missed, 0);
  // samples: outside the sphere (up to a pixel), inside every silhouette, on one view's contour
  double min_r = 1e9, max_r = 0, worst_contour = 0;
  int outward = 0;
  for (Eigen::Index i = 0; i < h.points.rows(); ++i) {
    const Eigen::Vector3d p = h.points.row(i).transpose();
    min_r = std::min(min_r, p.norm());
    max_r = std::max(max_r, p.norm());
    double best = 1e9;
    for (std::size_t k = 0; k < cams.size(); ++k) best = std::min(best, contour_distance(sil[k], cams[k].project(p)));
    worst_contour = std::max(worst_contour, best);
    outward += h.normals.row(i).dot(p.normalized().transpose()) > 0.8;
  }
  std::printf("sphere r 0.5: %ld samples, voxel %.4f, radius %.4f..%.4f, worst distance to a contour %.2f px, %.1f %% normals outward, "
              "volume %.4f (sphere %.4f), %d doublings\n",
              long(h.points.rows()), h.voxel, min_r, max_r, worst_contour, 100.0 * outward / double(h.points.rows()), h.volume(),
              4.0 / 3.0 * M_PI * r * r * r, h.box_doublings);
  EXPECT_GT(min_r, r - 2 * px);
  EXPECT_LT(max_r, 1.3 * r);  // 8 views: the hull bulges between them, never by 30 %
  EXPECT_LT(worst_contour, 1.5);
  EXPECT_GT(outward, 0.95 * double(h.points.rows()));
  EXPECT_GT(h.volume(), 4.0 / 3.0 * M_PI * std::pow(r - 2 * px, 3));
}

TEST(VisualHull, AutomaticBoxGrowsWhenTheCamerasSitOnOneSide) {
  // five cameras on a 90° arc of radius 4: their centres span a box that does not hold the object
  const TriMesh sphere = make_icosphere(4, 0.4);
  const std::vector<Camera> cams = ring(5, 4.0, 200, Eigen::Vector3d::Zero(), M_PI / 2);
  VisualHullOptions o;
  o.resolution = 48;
  const VisualHull h = compute_visual_hull(cams, silhouettes_of(sphere, cams), o);
  std::printf("one-sided cameras: %d doublings, %ld samples\n", h.box_doublings, long(h.points.rows()));
  EXPECT_GE(h.box_doublings, 1);
  ASSERT_GT(h.points.rows(), 100);
  // the part of the sphere facing the cameras is inside the hull
  for (Eigen::Index i = 0; i < sphere.V.rows(); i += 7) {
    const Eigen::Vector3d v = 0.95 * sphere.V.row(i).transpose();
    const Eigen::Vector3d c = (v - h.origin) / h.voxel;
    const int x = int(std::lround(c.x())), y = int(std::lround(c.y())), z = int(std::lround(c.z()));
    ASSERT_TRUE(x >= 0 && y >= 0 && z >= 0 && x < h.dims.x() && y < h.dims.y() && z < h.dims.z()) << "vertex " << i << " outside the grid";
    EXPECT_TRUE(h.occupied[h.index(x, y, z)]) << "vertex " << i;
  }
}

TEST(VisualHull, RegistersAMovedTemplate) {
  const TriMesh truth = blob();
  const std::vector<Camera> cams = ring(8, 3.5, 320);
  const std::vector<cv::Mat> sil = silhouettes_of(truth, cams);
  const double diag = (truth.V.colwise().maxCoeff() - truth.V.colwise().minCoeff()).norm();
  // the template: the truth turned by 15°, scaled by 0.9 and moved by 8 % of its diagonal
  Eigen::Matrix4d off = Eigen::Matrix4d::Identity();
  off.topLeftCorner<3, 3>() = 0.9 * Eigen::AngleAxisd(15 * M_PI / 180, Eigen::Vector3d(0.2, 1, 0.4).normalized()).toRotationMatrix();
  off.topRightCorner<3, 1>() = 0.08 * diag * Eigen::Vector3d(1, -0.5, 0.3).normalized();
  TriMesh templ = truth;
  templ.V = transform_points(off, truth.V);
  const HullRegistration reg = register_to_visual_hull(templ, cams, sil);
  const Eigen::MatrixX3d X = transform_points(reg.icp.transform, templ.V);
  const double before = (templ.V - truth.V).rowwise().norm().mean() / diag;
  const double after = (X - truth.V).rowwise().norm().mean() / diag;
  std::printf("blob: mean vertex error %.2f %% -> %.3f %% of the diagonal, IoU %.3f -> %.4f, %d hull samples, voxel %.4f, %d iterations, "
              "%.2f s; scale %.4f (truth %.4f), rotation %.2f deg (truth 15)\n",
              100 * before, 100 * after, reg.iou_before, reg.iou_after, reg.hull_points, reg.voxel, reg.icp.iterations, reg.seconds, reg.icp.scale, 1 / 0.9, reg.icp.rotation_deg);
  EXPECT_LT(after, 0.01);
  EXPECT_LT(after, 0.15 * before);
  EXPECT_GT(reg.iou_after, 0.97);
  EXPECT_GT(reg.iou_after, reg.iou_before + 0.1);
}

TEST(VisualHull, BadInputIsAClearError) {
  const TriMesh sphere = make_icosphere(3, 0.5);
  const std::vector<Camera> cams = ring(6, 3.0, 120);
  std::vector<cv::Mat> sil = silhouettes_of(sphere, cams);
  auto message = [&](const std::vector<Camera>& c, const std::vector<cv::Mat>& s, const VisualHullOptions& o) -> std::string {
    try {
      compute_visual_hull(c, s, o);
    } catch (const InvalidInput& e) {
      return e.what();
    }
    return "";
  };
  EXPECT_NE(message({}, {}, {}).find("no camera"), std::string::npos);
  EXPECT_NE(message(cams, std::vector<cv::Mat>(sil.begin(), sil.end() - 1), {}).find("one silhouette per camera"), std::string::npos);
  std::vector<cv::Mat> wrong = sil;
  wrong[2] = cv::Mat(60, 60, CV_8U, cv::Scalar(255));
  EXPECT_NE(message(cams, wrong, {}).find("cam2"), std::string::npos);
  std::vector<cv::Mat> empty = sil;
  empty[1] = cv::Mat(120, 120, CV_8U, cv::Scalar(0));
  EXPECT_NE(message(cams, empty, {}).find("empty"), std::string::npos);
  // one silhouette in a corner: the cones do not meet
  std::vector<cv::Mat> apart = sil;
  apart[3] = cv::Mat(120, 120, CV_8U, cv::Scalar(0));
  cv::rectangle(apart[3], cv::Rect(0, 0, 6, 6), cv::Scalar(255), cv::FILLED);
  const std::string m = message(cams, apart, {});
  EXPECT_TRUE(m.find("do not intersect") != std::string::npos || m.find("no voxel") != std::string::npos) << m;
  VisualHullOptions o;
  o.resolution = 8;
  EXPECT_NE(message(cams, sil, o).find("resolution"), std::string::npos);
  o = {};
  o.margin_px = -1;
  EXPECT_NE(message(cams, sil, o).find("margin_px"), std::string::npos);
  o = {};
  o.box = Eigen::AlignedBox3d(Eigen::Vector3d::Zero(), Eigen::Vector3d(1, 0, 1));
  EXPECT_NE(message(cams, sil, o).find("box"), std::string::npos);
  // a camera centre box of zero size needs a box
  std::vector<Camera> same(3, cams[0]);
  EXPECT_NE(message(same, std::vector<cv::Mat>(3, sil[0]), {}).find("coincide"), std::string::npos);
  TriMesh none;
  EXPECT_THROW(register_to_visual_hull(none, cams, sil), InvalidInput);
}
