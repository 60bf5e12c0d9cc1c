// TrajectorySmoother: analytic cases (constant and linear motion kept, a noisy sine denoised,
// the attenuation of a pure sine as documented), streaming = batch, bad input.
#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "tbsp/core/error.h"
#include "tbsp/mesh/trajectory_smoother.h"

using namespace tbsp;

namespace {
// Two vertices: vertex 0 moves along x as f(t), vertex 1 along y as g(t).
std::vector<Eigen::MatrixX3d> sequence(int n, double (*f)(double), double (*g)(double)) {
  std::vector<Eigen::MatrixX3d> out;
  for (int t = 0; t < n; ++t) {
    Eigen::MatrixX3d V = Eigen::MatrixX3d::Zero(2, 3);
    V(0, 0) = f(t);
    V(1, 1) = g(t);
    V(1, 2) = 5.0;
    out.push_back(V);
  }
  return out;
}
}  // namespace

TEST(TrajectorySmoother, KeepsConstantAndLinearMotionAwayFromTheEnds) {
  const auto in = sequence(40, [](double t) { return 0.3 * t - 2; }, [](double) { return 1.5; });
  const auto out = smooth_trajectories(in, 1.5);
  ASSERT_EQ(out.size(), in.size());
  const int r = TrajectorySmoother(1.5).radius();
  EXPECT_EQ(r, 5);
  for (int t = 0; t < 40; ++t) {
    EXPECT_NEAR(out[std::size_t(t)](1, 1), 1.5, 1e-12);  // constant: everywhere
    EXPECT_NEAR(out[std::size_t(t)](1, 2), 5.0, 1e-12);
    if (t >= r && t < 40 - r) {
      EXPECT_NEAR(out[std::size_t(t)](0, 0), 0.3 * t - 2, 1e-12) << t;  // linear: symmetric window
    }
  }
}

TEST(TrajectorySmoother, DenoisesAndAttenuatesAsDocumented) {
  // A slow swing (period 100 frames) with 2 % of its amplitude as seeded noise: sigma = 1 frame
  // averages ~3.5 frames' noise (rms x ~0.53) and flattens the swing by 0.2 % only.
  std::mt19937 rng(3);
  std::normal_distribution<double> noise(0.0, 0.02);
  std::vector<Eigen::MatrixX3d> clean, noisy, fast;
  for (int t = 0; t < 200; ++t) {
    Eigen::MatrixX3d V = Eigen::MatrixX3d::Zero(1, 3);
    V(0, 0) = std::sin(2 * M_PI * t / 25.0);
    fast.push_back(V);
    V(0, 0) = std::sin(2 * M_PI * t / 100.0);
    clean.push_back(V);
    V(0, 0) += noise(rng);
    noisy.push_back(V);
  }
  auto rms = [&](const std::vector<Eigen::MatrixX3d>& s) {
    double e = 0;
    for (int t = 10; t < 190; ++t) e += std::pow(s[std::size_t(t)](0, 0) - clean[std::size_t(t)](0, 0), 2);
    return std::sqrt(e / 180);
  };
  const double before = rms(noisy), after = rms(smooth_trajectories(noisy, 1.0));
  EXPECT_LT(after, 0.7 * before) << before << " -> " << after;
  // A 1 Hz swing at 25 frames/s keeps exp(-2 pi^2 sigma^2 f^2) = 96.9 % of its amplitude
  // (continuous-kernel value; the sampled, truncated kernel and the sampling of the peak are
  // within 0.5 % of it): at this speed the flattening (3 % of the swing) outweighs 2 % noise.
  const auto s = smooth_trajectories(fast, 1.0);
  double amp = 0;
  for (int t = 50; t < 150; ++t) amp = std::max(amp, std::abs(s[std::size_t(t)](0, 0)));
  EXPECT_NEAR(amp, std::exp(-2 * M_PI * M_PI / 625.0), 0.005);
}

TEST(TrajectorySmoother, StreamsWithALagOfItsRadiusAndMatchesTheBatchResult) {
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> u(-1, 1);
  std::vector<Eigen::MatrixX3d> in;
  for (int t = 0; t < 17; ++t) in.push_back(Eigen::MatrixX3d::NullaryExpr(4, 3, [&](Eigen::Index, Eigen::Index) { return u(rng); }));
  const auto batch = smooth_trajectories(in, 0.8);
  TrajectorySmoother s(0.8);
  std::vector<TrajectorySmoother::Frame> got;
  for (int t = 0; t < 17; ++t) {
    const auto out = s.push(100 + t, in[std::size_t(t)]);
    EXPECT_EQ(int(out.size()), t >= s.radius() ? 1 : 0) << t;  // lag = radius
    got.insert(got.end(), out.begin(), out.end());
  }
  for (auto& f : s.flush()) got.push_back(f);
  ASSERT_EQ(got.size(), 17u);
  for (int t = 0; t < 17; ++t) {
    EXPECT_EQ(got[std::size_t(t)].first, 100 + t);
    EXPECT_EQ(got[std::size_t(t)].second, batch[std::size_t(t)]);  // same arithmetic, same order
  }
  // sigma 0: a pass-through without lag
  TrajectorySmoother none(0);
  const auto p = none.push(7, in[0]);
  ASSERT_EQ(p.size(), 1u);
  EXPECT_EQ(p[0].second, in[0]);
}

TEST(TrajectorySmoother, BadInputNamesTheFrame) {
  EXPECT_THROW(TrajectorySmoother(-1), InvalidInput);
  EXPECT_THROW(TrajectorySmoother(std::nan("")), InvalidInput);
  EXPECT_THROW(TrajectorySmoother(51), InvalidInput);
  TrajectorySmoother s(1);
  s.push(0, Eigen::MatrixX3d::Zero(3, 3));
  try {
    s.push(1, Eigen::MatrixX3d::Zero(4, 3));
    ADD_FAILURE() << "no error";
  } catch (const InvalidInput& e) {
    EXPECT_NE(std::string(e.what()).find("frame 1 has 4 vertices"), std::string::npos) << e.what();
  }
  Eigen::MatrixX3d bad = Eigen::MatrixX3d::Zero(3, 3);
  bad(1, 1) = std::nan("");
  EXPECT_THROW(s.push(2, bad), InvalidInput);
}
