// Real calibrations from ../shared/data: Middlebury dino/temple SparseRing (P = K[R|t]) and the
// INRIA "dancer" 8-camera P matrices.
#include <gtest/gtest.h>

#include <algorithm>

#include <opencv2/features2d.hpp>
#include <opencv2/imgcodecs.hpp>

#include "test_util.h"
#include "tbsp/io/camera_io.h"

using namespace tbsp;

namespace {
struct PairStats {
  int matches = 0, consistent = 0, in_box = 0;
  double median_px = 0;
};

// SIFT matches between two views (ratio test + mutual), each triangulated with the two
// cameras; a match is consistent when it reprojects within 1 px in both views.
PairStats match_and_triangulate(const std::string& dir, const Camera& a, const Camera& b,
                                const Eigen::Vector3d& lo, const Eigen::Vector3d& hi) {
  cv::Mat ia = cv::imread(dir + "/" + a.name(), cv::IMREAD_GRAYSCALE), ib = cv::imread(dir + "/" + b.name(), cv::IMREAD_GRAYSCALE);
  EXPECT_FALSE(ia.empty());
  EXPECT_FALSE(ib.empty());
  auto sift = cv::SIFT::create(4000);
  std::vector<cv::KeyPoint> ka, kb;
  cv::Mat da, db;
  sift->detectAndCompute(ia, cv::noArray(), ka, da);
  sift->detectAndCompute(ib, cv::noArray(), kb, db);
  cv::BFMatcher bf(cv::NORM_L2);
  std::vector<std::vector<cv::DMatch>> ab, ba;
  bf.knnMatch(da, db, ab, 2);
  bf.knnMatch(db, da, ba, 1);
  PairStats s;
  std::vector<double> errs;
  for (const auto& m : ab) {
    if (m.size() < 2 || m[0].distance > 0.7f * m[1].distance) continue;
    if (ba[m[0].trainIdx].empty() || ba[m[0].trainIdx][0].trainIdx != m[0].queryIdx) continue;
    const Eigen::Vector2d pa(ka[m[0].queryIdx].pt.x, ka[m[0].queryIdx].pt.y), pb(kb[m[0].trainIdx].pt.x, kb[m[0].trainIdx].pt.y);
    const Eigen::Vector3d X = triangulate({a, b}, {pa, pb});
    const double e = std::max((a.project(X) - pa).norm(), (b.project(X) - pb).norm());
    ++s.matches;
    errs.push_back(e);
    if (e < 1.0) {
      ++s.consistent;
      const Eigen::Vector3d m3 = Eigen::Vector3d::Constant(0.005);  // 5 mm margin
      s.in_box += (X.array() >= (lo - m3).array()).all() && (X.array() <= (hi + m3).array()).all();
    }
  }
  if (!errs.empty()) {
    std::nth_element(errs.begin(), errs.begin() + errs.size() / 2, errs.end());
    s.median_px = errs[errs.size() / 2];
  }
  return s;
}
}  // namespace

TEST(MiddleburyReal, ViewsReprojectConsistently) {
  struct Set { const char* dir; const char* par; Eigen::Vector3d lo, hi; };
  const Set sets[] = {
      {"capture/maximm8__VisualHull/templeSparseRing", "templeSR_par.txt", {-0.073568, 0.021728, -0.012445}, {0.028892, 0.181892, 0.062676}},
      {"capture/maximm8__VisualHull/dinoSparseRing", "dinoSR_par.txt", {-0.061897, -0.018874, -0.057845}, {0.010897, 0.068227, 0.015495}}};
  for (const Set& set : sets) {
    const std::string dir = test::shared(set.dir);
    TBSP_REQUIRE_FILE(dir + "/" + set.par);
    const auto cams = read_middlebury_par(dir + "/" + set.par);
    ASSERT_EQ(cams.size(), 16u);
    EXPECT_EQ(cams[0].width(), 640);
    EXPECT_EQ(cams[0].height(), 480);
    // The centre of the bounding box projects inside every image.
    const Eigen::Vector3d mid = 0.5 * (set.lo + set.hi);
    for (const auto& c : cams) EXPECT_TRUE(c.inImage(c.project(mid))) << c.name();
    int total = 0, consistent = 0, in_box = 0;
    for (int i = 0; i < 16; i += 2) {
      const PairStats s = match_and_triangulate(dir, cams[i], cams[(i + 1) % 16], set.lo, set.hi);
      total += s.matches;
      consistent += s.consistent;
      in_box += s.in_box;
      std::printf("  %s %s-%s: %d matches, %d within 1 px (median %.2f px), %d of those in the bbox\n", set.dir,
                  cams[i].name().c_str(), cams[(i + 1) % 16].name().c_str(), s.matches, s.consistent, s.median_px, s.in_box);
    }
    ASSERT_GT(total, 100) << set.dir;
    // Most SIFT matches are consistent with the calibration to 1 px, and those triangulate into the
    // published tight bounding box.
    EXPECT_GT(double(consistent) / total, 0.6) << set.dir;
    EXPECT_GT(double(in_box) / consistent, 0.95) << set.dir;
  }
}

TEST(MiddleburyReal, APerturbedCalibrationIsDetected) {
  // Negative control: the same check fails when one camera is moved by 3 mm.
  const std::string dir = test::shared("capture/maximm8__VisualHull/templeSparseRing");
  TBSP_REQUIRE_FILE(dir + "/templeSR_par.txt");
  auto cams = read_middlebury_par(dir + "/templeSR_par.txt");
  const Camera& a = cams[0];
  const Camera b(cams[1].name(), 640, 480, cams[1].K(), cams[1].R(), cams[1].t() + Eigen::Vector3d(0.003, 0, 0));
  const PairStats good = match_and_triangulate(dir, cams[0], cams[1], {-0.0736, 0.0217, -0.0124}, {0.0289, 0.1819, 0.0627});
  const PairStats bad = match_and_triangulate(dir, a, b, {-0.0736, 0.0217, -0.0124}, {0.0289, 0.1819, 0.0627});
  std::printf("  true calibration: median %.2f px; camera moved 3 mm: median %.2f px\n", good.median_px, bad.median_px);
  EXPECT_LT(good.median_px, 0.5);
  EXPECT_GT(bad.median_px, 2 * good.median_px);
}

TEST(DancerReal, EightProjectionMatricesDecompose) {
  const std::string dir = test::shared("capture/Nikhil-void__Computer-Vision-Projects/Visual Hull 3D Surface Estimation/input_data/calibration");
  TBSP_REQUIRE_FILE(dir + "/cam00.xml");
  for (int i = 0; i < 8; ++i) {
    const std::string f = dir + "/cam0" + std::to_string(i) + ".xml";
    const Camera c = read_projection_matrix(f, 780, 582);
    EXPECT_EQ(c.name(), "cam0" + std::to_string(i));
    // Manifest facts: metres, z up, floor at z ~ 0, centres 1.5-3.8 m high; P normalised so that
    // P[2]·X is depth: after decomposition the re-composed P equals the file's up to scale.
    const Eigen::Vector3d C = c.center();
    EXPECT_GT(C.z(), 1.4) << f;
    EXPECT_LT(C.z(), 4.0) << f;
    // The studio volume centre (0, 0, 1) m is in front of every camera and inside its image.
    EXPECT_GT(c.depth({0, 0, 1}), 0) << f;
    EXPECT_TRUE(c.inImage(c.project({0, 0, 1}))) << f;
    EXPECT_GT(c.K()(0, 0), 300);
    EXPECT_LT(c.K()(0, 0), 3000);
  }
}

TEST(DomeReal, Wd2TwentyCamerasOnARing) {
  const std::string f = test::shared("capture/wl-zhao__VisualHull/calibParamsI.txt");
  TBSP_REQUIRE_FILE(f);
  const auto cams = read_dome_calibration(f, 1024, 768);
  ASSERT_EQ(cams.size(), 20u);
  // Manifest facts: camera 0 is [I|0]; f ~ 895-902 px; centres on a ring of radius ~22 units.
  EXPECT_NEAR(cams[0].center().norm(), 0, 1e-9);
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (const auto& c : cams) mean += c.center() / 20.0;
  for (const auto& c : cams) {
    EXPECT_GT(c.K()(0, 0), 890) << c.name();
    EXPECT_LT(c.K()(0, 0), 905) << c.name();
    EXPECT_NEAR((c.center() - mean).norm(), 22, 3) << c.name();
    EXPECT_LT(c.distortion().k1, 0) << c.name();  // barrel, k1 ~ -0.04
    // The subject stands near the ring's centre, in front of every camera.
    EXPECT_GT(c.depth(mean), 0) << c.name();
  }
}

