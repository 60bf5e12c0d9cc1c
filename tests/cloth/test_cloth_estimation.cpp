// Cloth parameter estimation (thesis §10.7, issue 26): the observations (silhouette boundaries,
// SIFT correspondences) against analytic images, E_fit and the searches against the ground truth
// of a simulated and rendered skirt, and the bad-input errors.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <random>
#include <string>

#include <unistd.h>

#include <opencv2/imgproc.hpp>

#include "test_util.h"
#include "tbsp/cloth/cloth_parameter_estimation.h"
#include "tbsp/core/error.h"
#include "tbsp/io/studio.h"
#include "tbsp/plugins/skirt_studio.h"

using namespace tbsp;

namespace {

Camera test_camera(int w = 200, int h = 160) {
  Eigen::Matrix3d K;
  K << 150, 0, w / 2.0, 0, 150, h / 2.0, 0, 0, 1;
  return Camera("c0", w, h, K, Eigen::Matrix3d::Identity(), Eigen::Vector3d(0, 0, 2));
}

cv::Mat disc(int w, int h, cv::Point c, int r) {
  cv::Mat m(h, w, CV_8U, cv::Scalar(0));
  cv::circle(m, c, r, cv::Scalar(255), cv::FILLED);
  return m;
}

// A random blob texture (smoothed noise: SIFT finds many keypoints on it), deterministic.
cv::Mat texture(int w, int h, unsigned seed) {
  cv::Mat n(h, w, CV_8U);
  cv::RNG rng(seed);
  rng.fill(n, cv::RNG::UNIFORM, 0, 255);
  cv::GaussianBlur(n, n, cv::Size(0, 0), 2.0);
  cv::normalize(n, n, 0, 255, cv::NORM_MINMAX);
  return n;
}

}  // namespace

TEST(ClothObservations, BoundaryDistanceOfADisc) {
  ClothObservations obs({test_camera()});
  const cv::Mat sil = disc(200, 160, {100, 80}, 40);
  obs.addFrame({texture(200, 160, 1)}, {sil});
  ASSERT_EQ(obs.numFrames(), 1);
  // centre: the radius (the boundary pixels are the disc's outermost ring: r − 0.5 ± 0.5)
  EXPECT_NEAR(obs.boundaryDistance(0, 0, {100, 80}), 40.0, 1.0);
  // a point 10 px outside the disc
  EXPECT_NEAR(obs.boundaryDistance(0, 0, {150, 80}), 10.0, 1.0);
  EXPECT_NEAR(obs.boundaryDistance(0, 0, {140, 80}), 0.0, 0.6);
  EXPECT_TRUE(obs.correspondences(0, 0).empty());
}

TEST(ClothObservations, CorrespondencesFollowATranslatedTexture) {
  const int w = 240, h = 200;
  ClothObservations obs({test_camera(w, h)});
  const cv::Mat tex = texture(w + 20, h + 20, 7);
  const cv::Mat a = tex(cv::Rect(10, 10, w, h)).clone();
  const cv::Mat b = tex(cv::Rect(7, 8, w, h)).clone();  // content moves by (+3, +2)
  const cv::Mat sil(h, w, CV_8U, cv::Scalar(255));
  obs.addFrame({a}, {sil});
  obs.addFrame({b}, {sil});
  const auto& pairs = obs.correspondences(1, 0);
  ASSERT_GE(pairs.size(), 20u);
  int good = 0;
  for (const FeaturePair& p : pairs) good += ((p.to - p.from) - Eigen::Vector2f(3, 2)).norm() < 0.5f;
  EXPECT_GE(double(good) / double(pairs.size()), 0.95) << good << " of " << pairs.size();
}

TEST(ClothObservations, BadFramesAreRejectedWithTheCameraNamed) {
  ClothObservations obs({test_camera()});
  const cv::Mat img = texture(200, 160, 3), sil = disc(200, 160, {100, 80}, 30);
  EXPECT_THROW(obs.addFrame({}, {}), InvalidInput);
  EXPECT_THROW(obs.addFrame({img}, {sil(cv::Rect(0, 0, 100, 80)).clone()}), InvalidInput);
  cv::Mat empty(160, 200, CV_8U, cv::Scalar(0));
  try {
    obs.addFrame({img}, {empty});
    FAIL() << "an empty silhouette must be rejected";
  } catch (const InvalidInput& e) {
    EXPECT_NE(std::string(e.what()).find("c0"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("empty"), std::string::npos) << e.what();
  }
  EXPECT_EQ(obs.numFrames(), 0);  // nothing added by the failed calls
  EXPECT_THROW(ClothObservations({}), InvalidInput);
  ClothObservationOptions bad;
  bad.ratio = 0;
  EXPECT_THROW(ClothObservations({test_camera()}, bad), InvalidInput);
}

namespace {

// A small ground truth: the mannequin's skirt driven by the CMU walk with a known material,
// rendered into 4 views; built once per process.
struct SmallGt {
  synth::SkirtStudio gt;
  std::unique_ptr<ClothObservations> obs;
};

const SmallGt* small_gt(const ClothMaterial& truth) {
  static std::unique_ptr<SmallGt> cached;
  const std::string clip_path = std::string(TBSP_SHARED_DATA_DIR) + "/capture/dopomoc__BVH/02_05.bvh";
  if (!std::filesystem::exists(clip_path)) return nullptr;
  if (cached) return cached.get();
  cached = std::make_unique<SmallGt>();
  synth::SkirtStudioOptions o;
  o.mannequin.skirt_rings = 16;
  o.mannequin.skirt_segments = 40;
  o.sequence.frames = 24;
  o.sequence.material = truth;
  o.studio.cameras = 4;
  o.studio.width = o.studio.height = 400;
  const std::string dir = (std::filesystem::temp_directory_path() / ("tbsp_test_cloth_estimation_" + std::to_string(::getpid()))).string();
  cached->gt = synth::write_skirt_studio(dir, read_bvh(clip_path), o);
  const Studio studio = read_studio(cached->gt.studio.studio.path);
  cached->obs = std::make_unique<ClothObservations>(studio.cameraList());
  StudioFrameStream stream(studio, {});
  StudioFrame fr;
  while (stream.next(fr)) cached->obs->addFrame(fr.images, fr.silhouettes);
  std::filesystem::remove_all(dir);
  return cached.get();
}

}  // namespace

TEST(ClothParameterEstimation, BadInputsAreClearErrors) {
  const ClothMaterial truth{1.0, 10.0, 0.6};
  const SmallGt* g = small_gt(truth);
  TBSP_REQUIRE_FILE(std::string(TBSP_SHARED_DATA_DIR) + "/capture/dopomoc__BVH/02_05.bvh");
  ASSERT_NE(g, nullptr);
  // one pose per observed frame
  std::vector<SkeletonPose> fewer(g->gt.poses.begin(), g->gt.poses.end() - 1);
  EXPECT_THROW(ClothParameterEstimation(g->gt.model, fewer, *g->obs), InvalidInput);
  // a region without cloth
  AnimatableModel rigid = g->gt.model;
  rigid.clothness.setZero();
  try {
    ClothParameterEstimation e(rigid, g->gt.poses, *g->obs);
    FAIL() << "a model without cloth must be rejected";
  } catch (const InvalidInput& e) {
    EXPECT_NE(std::string(e.what()).find("no vertex with clothness"), std::string::npos) << e.what();
  }
  ClothParameterEstimation est(g->gt.model, g->gt.poses, *g->obs);
  // windows need the reference sequence
  EXPECT_THROW(est.evaluate(0, truth), InvalidInput);
  std::vector<Eigen::MatrixX3d> short_ref(g->gt.frames.begin(), g->gt.frames.end() - 1);
  EXPECT_THROW(est.setReferenceSequence(short_ref), InvalidInput);
  ClothEstimationOptions o;
  o.max_evaluations = 2;  // < start_samples
  EXPECT_THROW(est.setOptions(o), InvalidInput);
  o = {};
  o.upper.k_bend = 2;
  EXPECT_THROW(est.setOptions(o), InvalidInput);
  o = {};
  o.window_phases = 0;
  EXPECT_THROW(est.setOptions(o), InvalidInput);
  o.window_phases = o.window + 1;  // more phases than frames in a window
  EXPECT_THROW(est.setOptions(o), InvalidInput);
  EXPECT_THROW(est.evaluate(1, truth), InvalidInput);  // no region 1
}

// E_fit along k_bend (the parameter the images constrain best; docs/cloth.md): the truth is not
// worse than a softer cloth and clearly better than a stiffer one; the same sample gives the same
// bits on any thread count.
TEST(ClothParameterEstimation, TrueBendingStiffnessIsNotWorseThanSofterAndBetterThanStiffer) {
  const ClothMaterial truth{1.0, 10.0, 0.6};
  TBSP_REQUIRE_FILE(std::string(TBSP_SHARED_DATA_DIR) + "/capture/dopomoc__BVH/02_05.bvh");
  const SmallGt* g = small_gt(truth);
  ASSERT_NE(g, nullptr);
  // the generating body (rigid weights, true δ, limb tubes), a wrong material to start from
  const AnimatableModel model = synth::generating_model(g->gt.mannequin, g->gt.skeleton, ClothMaterial{}, g->gt.model.settings);
  ClothParameterEstimation est(model, g->gt.poses, *g->obs);
  est.setReferenceSequence(g->gt.frames);
  std::vector<ClothMaterial> rhos;
  for (double kb : {0.2, 0.6, 1.0}) rhos.push_back({truth.d_n, truth.d_t, kb});
  const std::vector<ClothFitEnergy> e = est.evaluate(0, rhos);
  std::printf("E_fit at k_bend 0.2 / 0.6 (true) / 1.0: %.3f / %.3f / %.3f (E_sil %.3f, E_sift %.3f at the truth; %ld rim, %ld features)\n",
              e[0].e_fit, e[1].e_fit, e[2].e_fit, e[1].e_sil, e[1].e_sift, e[1].rim_samples, e[1].feature_samples);
  EXPECT_GT(e[1].rim_samples, 100);
  EXPECT_GT(e[1].feature_samples, 50);
  // On this short sequence the soft side of the valley is flat: E at k_bend 0.2 and at the truth
  // differ by about the sample noise (588.8 / 586.6, and 587.3 / 619.9 with the self-contact pairs
  // visited in another order; windows of 5: 495.7 / 490.7), so only "not clearly worse" is
  // asserted there; the stiff side is well above (795.7 / 822.3; 730.7 with windows of 5).
  EXPECT_LT(e[1].e_fit, 1.1 * e[0].e_fit);
  EXPECT_LT(1.15 * e[1].e_fit, e[2].e_fit);
  const ClothFitEnergy again = est.evaluate(0, rhos[1]);  // serial (the batch ran one sample per thread)
  EXPECT_EQ(again.e_fit, e[1].e_fit);
}

// Restart phases: with window 10 and 2 phases on 24 frames the grids are [0,10) [10,20) [20,24)
// and [0,5) [5,15) [15,24); a window's first frame is not scored, so 9 + 9 + 3 and 4 + 9 + 8
// frames: 42 with both phases against 21 with one, and the averaged E_fit is near the one-phase value.
TEST(ClothParameterEstimation, RestartPhasesScoreEveryShiftedWindow) {
  const ClothMaterial truth{1.0, 10.0, 0.6};
  TBSP_REQUIRE_FILE(std::string(TBSP_SHARED_DATA_DIR) + "/capture/dopomoc__BVH/02_05.bvh");
  const SmallGt* g = small_gt(truth);
  ASSERT_NE(g, nullptr);
  ASSERT_EQ(g->gt.frames.size(), 24u);
  const AnimatableModel model = synth::generating_model(g->gt.mannequin, g->gt.skeleton, ClothMaterial{}, g->gt.model.settings);
  ClothParameterEstimation est(model, g->gt.poses, *g->obs);
  est.setReferenceSequence(g->gt.frames);
  const ClothFitEnergy one = est.evaluate(0, truth);
  ClothEstimationOptions o;
  o.window_phases = 2;
  est.setOptions(o);
  const ClothFitEnergy two = est.evaluate(0, truth);
  EXPECT_EQ(one.frames, 21);
  EXPECT_EQ(two.frames, 42);
  EXPECT_GT(two.rim_samples, one.rim_samples);
  EXPECT_NEAR(two.e_fit, one.e_fit, 0.25 * one.e_fit);
}
