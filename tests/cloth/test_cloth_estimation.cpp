// Cloth parameter estimation (thesis §10.7, issue 26): the observations (silhouette boundaries,
// SIFT correspondences) against analytic images, E_fit and the searches against the ground truth
// of a simulated and rendered skirt, and the bad-input errors.
#include <gtest/gtest.h>

#include <cmath>
#include <condition_variable>
#include <cstring>
#include <filesystem>
#include <memory>
#include <mutex>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include <unistd.h>

#include <omp.h>

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

// Parts of a recording observed apart (ranks of `tbsp cloth estimate` under mpirun): frames 0–2
// in one object, frame 2 primed and frames 3–5 in another, serialized and appended, give what one
// pass over the six frames gives, bit for bit; malformed bytes are refused.
TEST(ClothObservations, PartsObservedApartAndAppendedEqualOnePass) {
  const int w = 200, h = 160;
  const std::vector<Camera> cams{test_camera(w, h), test_camera(w, h)};
  const cv::Mat tex = texture(w + 40, h + 40, 11);
  std::vector<std::vector<cv::Mat>> img(6), sil(6);
  for (int f = 0; f < 6; ++f)
    for (int c = 0; c < 2; ++c) {
      img[std::size_t(f)].push_back(tex(cv::Rect(20 - 2 * f + c, 20 - f, w, h)).clone());  // the texture moves
      sil[std::size_t(f)].push_back(disc(w, h, {100 + 3 * f, 80 + c}, 50 + f));
    }
  ClothObservations one(cams), a(cams), b(cams);
  for (int f = 0; f < 6; ++f) one.addFrame(img[std::size_t(f)], sil[std::size_t(f)]);
  for (int f = 0; f < 3; ++f) a.addFrame(img[std::size_t(f)], sil[std::size_t(f)]);
  b.primeFrame(img[2], sil[2]);
  EXPECT_EQ(b.numFrames(), 0);
  for (int f = 3; f < 6; ++f) b.addFrame(img[std::size_t(f)], sil[std::size_t(f)]);
  EXPECT_THROW(b.primeFrame(img[2], sil[2]), InvalidInput);  // only before the first frame
  ClothObservations all(cams);
  all.append(a.serialize());
  all.append(b.serialize());
  ASSERT_EQ(all.numFrames(), 6);
  EXPECT_EQ(all.numBoundaryPixels(), one.numBoundaryPixels());
  EXPECT_EQ(all.numCorrespondences(), one.numCorrespondences());
  EXPECT_GT(one.correspondences(3, 1).size(), 10u);  // frame 3's come from the primed frame 2
  for (int f = 0; f < 6; ++f)
    for (int c = 0; c < 2; ++c) {
      const auto& p = all.correspondences(f, c);
      const auto& q = one.correspondences(f, c);
      ASSERT_EQ(p.size(), q.size()) << "frame " << f << ", view " << c;
      for (std::size_t i = 0; i < p.size(); ++i) {
        EXPECT_EQ(p[i].from, q[i].from);
        EXPECT_EQ(p[i].to, q[i].to);
      }
      for (const Eigen::Vector2d& x : {Eigen::Vector2d(100, 80), Eigen::Vector2d(3, 150), Eigen::Vector2d(170.3, 41.7)})
        EXPECT_EQ(all.boundaryDistance(f, c, x), one.boundaryDistance(f, c, x));
    }
  EXPECT_THROW(all.addFrame(img[0], sil[0]), InvalidInput);  // after append: add to the parts
  // malformed bytes: each refused, nothing appended
  const std::string good = a.serialize();
  ClothObservations into(cams);
  EXPECT_THROW(into.append(""), InvalidInput);
  EXPECT_THROW(into.append("TBSPOBS0" + good.substr(8)), InvalidInput);  // another header
  for (std::size_t cut : {std::size_t(9), std::size_t(16), good.size() / 2, good.size() - 1})
    EXPECT_THROW(into.append(good.substr(0, cut)), InvalidInput) << "cut at " << cut;
  EXPECT_THROW(into.append(good + "x"), InvalidInput);  // trailing bytes
  std::string huge = good;
  const std::uint32_t many = 0xFFFFFFF0u;
  std::memcpy(&huge[12], &many, sizeof many);  // frame count beyond the data
  EXPECT_THROW(into.append(huge), InvalidInput);
  ClothObservations three({test_camera(w, h), test_camera(w, h), test_camera(w, h)});
  EXPECT_THROW(three.append(good), InvalidInput);  // another view count
  EXPECT_EQ(into.numFrames(), 0);
  into.append(good);
  EXPECT_EQ(into.numFrames(), 3);
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

// The generating body (rigid weights, true δ, limb tubes) with a wrong material to start from.
AnimatableModel generating_model(const SmallGt& g) {
  return synth::generating_model(g.gt.mannequin, g.gt.skeleton, ClothMaterial{}, g.gt.model.settings);
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
  const AnimatableModel model = generating_model(*g);
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
  const AnimatableModel model = generating_model(*g);
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

namespace {

// In-process stand-in for MPI_Allreduce(MPI_SUM) among n threads: each deposits its vector, all
// wait for the last, all get the elementwise sum.
class ThreadAllreduce {
public:
  explicit ThreadAllreduce(int n) : n_(n) {}
  void sum(std::vector<double>& v) {
    std::unique_lock<std::mutex> lock(m_);
    const long generation = generation_;
    if (arrived_ == 0) acc_.assign(v.size(), 0.0);
    if (acc_.size() != v.size()) mismatch_ = true;
    for (std::size_t i = 0; i < v.size() && i < acc_.size(); ++i) acc_[i] += v[i];
    if (++arrived_ == n_) {
      result_ = acc_;
      arrived_ = 0;
      ++generation_;
      cv_.notify_all();
    } else {
      cv_.wait(lock, [&] { return generation_ != generation; });
    }
    v = result_;
  }
  bool mismatch() const { return mismatch_; }

private:
  int n_, arrived_ = 0;
  long generation_ = 0;
  bool mismatch_ = false;
  std::vector<double> acc_, result_;
  std::mutex m_;
  std::condition_variable cv_;
};

// Runs fn(rank, share) on n threads, each a "process" of one work share.
template <class F>
void as_processes(int n, ThreadAllreduce& net, F fn) {
  std::vector<std::thread> t;
  for (int r = 0; r < n; ++r)
    t.emplace_back([&, r] {
      ClothWorkShare share;
      share.rank = r;
      share.size = n;
      share.sum = [&net](std::vector<double>& v) { net.sum(v); };
      fn(r, share);
    });
  for (auto& x : t) x.join();
}

}  // namespace

// The thesis' search draws its greedy samples in batches of a fixed size (greedy_batch), not of
// the thread count: the same estimate and the same samples on one thread and on three.
TEST(ClothParameterEstimation, ThesisSearchGivesTheSameEstimateOnAnyThreadCount) {
  const ClothMaterial truth{1.0, 10.0, 0.6};
  TBSP_REQUIRE_FILE(std::string(TBSP_SHARED_DATA_DIR) + "/capture/dopomoc__BVH/02_05.bvh");
  const SmallGt* g = small_gt(truth);
  ASSERT_NE(g, nullptr);
  const AnimatableModel model = generating_model(*g);
  ClothEstimationOptions o;
  o.search = ClothSearch::Thesis;
  o.grid_k = 1;
  o.greedy_samples = 12;  // with seed 1 the second greedy sample improves on the grid's
  o.greedy_batch = 3;
  auto run = [&](int threads) {
    const int saved = omp_get_max_threads();
    omp_set_num_threads(threads);
    ClothParameterEstimation est(model, g->gt.poses, *g->obs);
    est.setReferenceSequence(g->gt.frames);
    est.setOptions(o);
    const ClothEstimationResult r = est.estimate();
    omp_set_num_threads(saved);
    return r;
  };
  // batches of the thread count (the behaviour before greedy_batch) would draw the third sample
  // after that improvement on one thread and before it on three
  const ClothEstimationResult one = run(1), three = run(3);
  ASSERT_EQ(one.samples.size(), three.samples.size());
  for (std::size_t i = 0; i < one.samples.size(); ++i) {
    EXPECT_EQ(one.samples[i].rho.d_n, three.samples[i].rho.d_n) << "sample " << i;
    EXPECT_EQ(one.samples[i].rho.k_bend, three.samples[i].rho.k_bend) << "sample " << i;
    EXPECT_EQ(one.samples[i].energy.e_fit, three.samples[i].energy.e_fit) << "sample " << i;
  }
  EXPECT_EQ(one.regions[0].rho.d_n, three.regions[0].rho.d_n);
  EXPECT_EQ(one.regions[0].rho.d_t, three.regions[0].rho.d_t);
  EXPECT_EQ(one.regions[0].rho.k_bend, three.regions[0].rho.k_bend);
  o.greedy_batch = 0;
  ClothParameterEstimation est(model, g->gt.poses, *g->obs);
  EXPECT_THROW(est.setOptions(o), InvalidInput);
}

// The simulations shared among processes (ClothWorkShare, what `tbsp cloth estimate` does under
// mpirun) give every process the energies one process computes, bit for bit (each simulation runs
// on one process; the exchange adds zeros to it); an error in any simulation reaches every process
// with its type and message, and a cancel on one process stops all of them.
TEST(ClothParameterEstimation, ProcessesSharingTheSimulationsGetTheSameBitsAndTheSameErrors) {
  const ClothMaterial truth{1.0, 10.0, 0.6};
  TBSP_REQUIRE_FILE(std::string(TBSP_SHARED_DATA_DIR) + "/capture/dopomoc__BVH/02_05.bvh");
  const SmallGt* g = small_gt(truth);
  ASSERT_NE(g, nullptr);
  const AnimatableModel model = generating_model(*g);
  ClothParameterEstimation one(model, g->gt.poses, *g->obs);
  one.setReferenceSequence(g->gt.frames);
  const std::vector<ClothMaterial> rhos{truth, {4.0, 30.0, 0.3}};
  const std::vector<ClothFitEnergy> want = one.evaluate(0, rhos);  // 2 samples x 3 windows
  constexpr int kProcesses = 4;                                     // more processes than a sample has windows
  ThreadAllreduce net(kProcesses);
  std::vector<std::vector<ClothFitEnergy>> got(kProcesses);
  // one "process": its own estimation object on the shared observations
  auto process = [&](const ClothWorkShare& share) {
    auto est = std::make_unique<ClothParameterEstimation>(model, g->gt.poses, *g->obs);
    est->setReferenceSequence(g->gt.frames);
    est->setWorkShare(share);
    return est;
  };
  as_processes(kProcesses, net, [&](int r, const ClothWorkShare& share) { got[std::size_t(r)] = process(share)->evaluate(0, rhos); });
  EXPECT_FALSE(net.mismatch());
  for (int r = 0; r < kProcesses; ++r) {
    ASSERT_EQ(got[std::size_t(r)].size(), want.size());
    for (std::size_t i = 0; i < want.size(); ++i) {
      EXPECT_EQ(got[std::size_t(r)][i].e_fit, want[i].e_fit) << "process " << r << ", sample " << i;
      EXPECT_EQ(got[std::size_t(r)][i].e_sil, want[i].e_sil);
      EXPECT_EQ(got[std::size_t(r)][i].e_sift, want[i].e_sift);
      EXPECT_EQ(got[std::size_t(r)][i].rim_samples, want[i].rim_samples);
      EXPECT_EQ(got[std::size_t(r)][i].feature_samples, want[i].feature_samples);
      EXPECT_EQ(got[std::size_t(r)][i].frames, want[i].frames);
    }
  }
  // a material the simulator refuses: its first window's error, on every process (it ran on one)
  const std::vector<ClothMaterial> bad{truth, {-1.0, 10.0, 0.6}};
  std::string single;
  try {
    one.evaluate(0, bad);
  } catch (const InvalidInput& e) {
    single = e.what();
  }
  ASSERT_FALSE(single.empty()) << "a negative drag must be refused";
  std::vector<std::string> messages(kProcesses);
  as_processes(kProcesses, net, [&](int r, const ClothWorkShare& share) {
    try {
      process(share)->evaluate(0, bad);
      messages[std::size_t(r)] = "no error";
    } catch (const InvalidInput& e) {
      messages[std::size_t(r)] = e.what();
    } catch (const std::exception& e) {
      messages[std::size_t(r)] = std::string("wrong type: ") + e.what();
    }
  });
  for (int r = 0; r < kProcesses; ++r) EXPECT_EQ(messages[std::size_t(r)], single) << "process " << r;
  // a cancel on process 1 only (after the first batch of the search): every process stops
  std::vector<int> cancelled(kProcesses, 0);
  as_processes(kProcesses, net, [&](int r, const ClothWorkShare& share) {
    const auto est = process(share);
    ClothEstimationOptions o;
    o.start_samples = 1;
    o.max_evaluations = 3;
    est->setOptions(o);
    est->setProgressCallback([r](double, const std::string&) { return r != 1; });
    try {
      est->estimate();
    } catch (const Cancelled&) {
      cancelled[std::size_t(r)] = 1;
    }
  });
  for (int r = 0; r < kProcesses; ++r) EXPECT_EQ(cancelled[std::size_t(r)], 1) << "process " << r;
  // an invalid share
  ClothWorkShare s;
  s.rank = 2;
  s.size = 2;
  EXPECT_THROW(one.setWorkShare(s), InvalidInput);
  s.rank = 0;
  EXPECT_THROW(one.setWorkShare(s), InvalidInput);  // several processes without a sum
}
