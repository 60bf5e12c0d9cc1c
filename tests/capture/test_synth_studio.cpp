// The synthetic studio round-trips: cameras written and read back project the ground-truth
// vertices to the same pixels, silhouettes equal re-renders, markers equal GT vertices, and the
// texture is trackable by SIFT (matches follow the surface).
#include <gtest/gtest.h>

#include <opencv2/features2d.hpp>
#include <opencv2/imgcodecs.hpp>

#include "test_util.h"
#include "tbsp/io/render_images.h"
#include "tbsp/io/mesh_io.h"
#include "tbsp/io/mocap_io.h"
#include "tbsp/io/studio.h"
#include "tbsp/multiview/rasterizer.h"
#include "tbsp/plugins/synth_studio.h"

using namespace tbsp;

TEST(SynthStudio, RoundTripsThroughTheStudioFormat) {
  const auto dir = test::temp_dir("synth_studio");
  synth::StudioOptions o;
  o.cameras = 4;
  o.width = 320;
  o.height = 280;
  o.frames = 2;
  o.markers = 8;
  o.detail = 0;
  const synth::StudioResult res = synth::write_synthetic_studio(dir.string(), o);
  const Studio s = read_studio((dir / "studio.yaml").string());
  ASSERT_EQ(s.cameras.size(), 4u);
  EXPECT_EQ(s.numFrames(), 2);
  EXPECT_TRUE(check_studio(s).ok()) << check_studio(s).summary();
  const MarkerTrajectories mk = read_trc(s.resolve(s.markers));
  ASSERT_EQ(mk.numMarkers(), 8);
  double worst_px = 0, worst_marker = 0;
  for (int f = 0; f < 2; ++f) {
    const TriMesh gt = read_mesh(s.groundTruthPath(f));
    ASSERT_EQ(gt.V.rows(), res.vertices);
    for (std::size_t c = 0; c < s.cameras.size(); ++c) {
      const Camera& back = s.cameras[c].camera;
      const Camera& orig = res.studio.cameras[c].camera;
      for (Eigen::Index v = 0; v < gt.V.rows(); ++v)
        worst_px = std::max(worst_px, (back.project(gt.V.row(v).transpose()) - orig.project(gt.V.row(v).transpose())).norm());
      // The silhouette on disk is the mask of the ground-truth mesh seen by the read-back camera.
      RenderBuffers b;
      Rasterizer().render(gt, back, b);
      const cv::Mat disk = cv::imread(s.silhouettePath(static_cast<int>(c), f), cv::IMREAD_GRAYSCALE);
      ASSERT_FALSE(disk.empty());
      const double diff = cv::countNonZero(disk != mask_image(b));
      EXPECT_LE(diff, 0.0005 * disk.total()) << "camera " << c << " frame " << f;
      EXPECT_GT(cv::countNonZero(disk), 2000);
    }
    for (int k = 0; k < mk.numMarkers(); ++k) {
      const int v = std::stoi(mk.names[k].substr(1));
      worst_marker = std::max(worst_marker, (mk.position(f, k) - gt.V.row(v).transpose()).norm());
    }
  }
  std::printf("  reprojection difference (written vs read cameras): %.2e px; markers vs GT vertices %.2e m\n", worst_px, worst_marker);
  EXPECT_LT(worst_px, 0.01);
  EXPECT_LT(worst_marker, 1e-6);
}

TEST(SynthStudio, TextureIsTrackableBySift) {
  const auto dir = test::temp_dir("synth_sift");
  synth::StudioOptions o;
  o.cameras = 1;
  o.width = o.height = 640;
  o.frames = 2;
  o.markers = 0;
  o.frame_rate = 12.5;  // 80 ms between frames: a visible motion
  o.image_noise = 2.0;
  synth::write_synthetic_studio(dir.string(), o);
  const Studio s = read_studio((dir / "studio.yaml").string());
  const Camera& cam = s.cameras[0].camera;
  const cv::Mat a = cv::imread(s.imagePath(0, 0), cv::IMREAD_GRAYSCALE), b = cv::imread(s.imagePath(0, 1), cv::IMREAD_GRAYSCALE);
  auto sift = cv::SIFT::create(2000);
  std::vector<cv::KeyPoint> ka, kb;
  cv::Mat da, db;
  sift->detectAndCompute(a, cv::noArray(), ka, da);
  sift->detectAndCompute(b, cv::noArray(), kb, db);
  std::vector<std::vector<cv::DMatch>> m;
  cv::BFMatcher(cv::NORM_L2).knnMatch(da, db, m, 2);
  // Ground truth: the rest-pose point under each keypoint (rasterize both frames).
  const TriMesh rest = read_mesh(s.resolve(s.template_mesh));
  const TriMesh g0 = read_mesh(s.groundTruthPath(0)), g1 = read_mesh(s.groundTruthPath(1));
  RenderBuffers b0, b1;
  Rasterizer().render(g0, cam, b0);
  Rasterizer().render(g1, cam, b1);
  auto rest_point = [&](const RenderBuffers& rb, const cv::Point2f& p, Eigen::Vector3d& out) {
    const int x = int(std::lround(p.x)), y = int(std::lround(p.y));
    const std::size_t i = std::size_t(y) * rb.width + x;
    const int f = rb.face[i];
    if (f < 0) return false;
    const double w1 = rb.bary[2 * i], w2 = rb.bary[2 * i + 1];
    out = (1 - w1 - w2) * rest.V.row(rest.F(f, 0)) + w1 * rest.V.row(rest.F(f, 1)) + w2 * rest.V.row(rest.F(f, 2));
    return true;
  };
  int good = 0, total = 0;
  for (const auto& mm : m) {
    if (mm.size() < 2 || mm[0].distance > 0.7f * mm[1].distance) continue;
    Eigen::Vector3d pa, pb;
    if (!rest_point(b0, ka[mm[0].queryIdx].pt, pa) || !rest_point(b1, kb[mm[0].trainIdx].pt, pb)) continue;
    ++total;
    good += (pa - pb).norm() < 0.02;  // same surface point within 2 cm (pixel ~ 1 cm here)
  }
  std::printf("  %zu / %zu SIFT keypoints, %d matches on the performer, %d on the same surface point (< 2 cm)\n", ka.size(), kb.size(), total, good);
  EXPECT_GT(total, 100);
  EXPECT_GT(double(good) / total, 0.9);
}
