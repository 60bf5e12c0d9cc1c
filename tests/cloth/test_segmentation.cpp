// ClothSegmentation and fit_collision_proxies against sequences and shapes with known answers.
#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "cloth_test_util.h"
#include "tbsp/cloth/cloth_segmentation.h"
#include "tbsp/cloth/collision_proxies.h"
#include "tbsp/core/error.h"
#include "tbsp/mesh/primitives.h"

using namespace tbsp;

namespace {

// A closed tube along x (a "leg" 1 m long, radius 0.1 m); the part with x < 0.45 is a "skirt"
// whose radius waves over time (±3 cm, different phases around the tube), the rest is body.
// Every frame is moved rigidly (a swing and a walk) and gets 0.5 mm of tracking noise.
struct SkirtedLeg {
  TriMesh tube = make_tube(41, 32, 1.0, 0.1);
  std::vector<int> truth;  // 1 = cloth
  SkirtedLeg() {
    truth.resize(std::size_t(tube.V.rows()));
    // cloth = every vertex that waves (the ramp 0.4 < x < 0.5 is the skirt's waistband)
    for (Eigen::Index i = 0; i < tube.V.rows(); ++i) truth[std::size_t(i)] = amplitude(tube.V(i, 0)) > 0;
  }
  static double amplitude(double x) { return std::clamp((0.5 - x) / 0.1, 0.0, 1.0); }  // 1 below x = 0.4, 0 above 0.5
  Eigen::MatrixX3d frame(int f, std::mt19937& rng) const {
    std::normal_distribution<double> noise(0, 0.0005);
    Eigen::MatrixX3d V = tube.V;
    for (Eigen::Index i = 0; i < V.rows(); ++i) {
      const double a = amplitude(V(i, 0));
      const double theta = std::atan2(V(i, 2), V(i, 1));
      const double r = std::hypot(V(i, 1), V(i, 2));
      if (r < 1e-9) continue;  // cap centres
      const double dr = 0.03 * a * std::sin(0.4 * f + 2 * theta);
      V(i, 1) *= (r + dr) / r;
      V(i, 2) *= (r + dr) / r;
    }
    Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
    T.translate(Eigen::Vector3d(0.02 * f, 0, 0)).rotate(Eigen::AngleAxisd(0.3 * std::sin(0.2 * f), Eigen::Vector3d::UnitZ()));
    Eigen::MatrixX3d out(V.rows(), 3);
    for (Eigen::Index i = 0; i < V.rows(); ++i)
      out.row(i) = (T * Eigen::Vector3d(V.row(i).transpose())).transpose() + Eigen::RowVector3d(noise(rng), noise(rng), noise(rng));
    return out;
  }
};

}  // namespace

TEST(ClothSegmentation, FindsTheWavingSkirtOnARigidlyMovingNoisyLeg) {
  SkirtedLeg leg;
  std::mt19937 rng(5);
  ClothSegmentation seg;
  seg.begin(leg.frame(0, rng), leg.tube.F);
  for (int f = 1; f < 60; ++f) seg.addFrame(leg.frame(f, rng));
  const ClothSegmentation::Result r = seg.finish();
  EXPECT_EQ(r.frames, 60);
  const Eigen::VectorXi labels = r.clothLabels();
  int correct = 0, with_ray = 0;
  for (Eigen::Index i = 0; i < labels.size(); ++i) {
    correct += labels(i) == leg.truth[std::size_t(i)];
    with_ray += r.opposite_face(i) >= 0;
  }
  const double accuracy = double(correct) / double(labels.size());
  EXPECT_GE(accuracy, 0.95);
  EXPECT_GE(with_ray, labels.size() * 9 / 10);
  RecordProperty("accuracy", std::to_string(accuracy));
  // body σ is the noise level, skirt σ the wave
  double body = 0, cloth = 0;
  int nb = 0, nc = 0;
  for (Eigen::Index i = 0; i < labels.size(); ++i) {
    if (std::isnan(r.sigma(i))) continue;
    const double x = leg.tube.V(i, 0);
    if (x > 0.6) body += r.sigma(i), ++nb;
    if (x < 0.35) cloth += r.sigma(i), ++nc;
  }
  EXPECT_LT(body / nb, 0.0015);
  EXPECT_GT(cloth / nc, 0.02);
}

TEST(ClothSegmentation, BadSequencesAreClearErrors) {
  SkirtedLeg leg;
  std::mt19937 rng(1);
  ClothSegmentation seg;
  EXPECT_THROW(seg.addFrame(leg.tube.V), InvalidInput);  // before begin
  seg.begin(leg.tube.V, leg.tube.F);
  EXPECT_THROW(seg.finish(), InvalidInput);  // one frame only
  Eigen::MatrixX3d fewer = leg.tube.V.topRows(10);
  try {
    seg.addFrame(fewer);
    FAIL();
  } catch (const InvalidInput& e) {
    EXPECT_NE(std::string(e.what()).find("frame 2"), std::string::npos) << e.what();
  }
  Eigen::MatrixX3d nan = leg.tube.V;
  nan(7, 1) = std::nan("");
  try {
    seg.addFrame(nan);
    FAIL();
  } catch (const InvalidInput& e) {
    EXPECT_NE(std::string(e.what()).find("vertex 7"), std::string::npos) << e.what();
  }
  seg.addFrame(leg.frame(1, rng));  // the bad frames were not counted
  EXPECT_EQ(seg.finish().frames, 2);
  ClothSegmentationOptions o;
  o.t_cloth = o.t_rigid;
  EXPECT_THROW(seg.setOptions(o), InvalidInput);
}

TEST(CollisionProxies, ConesMatchATaperedLimbAndStayInside) {
  // a limb along x from 0 to 1 whose radius goes from 0.12 to 0.06, bone = the axis
  TriMesh limb = make_tube(51, 32, 1.0, 1.0);
  for (Eigen::Index i = 0; i < limb.V.rows(); ++i) {
    const double r = 0.12 - 0.06 * limb.V(i, 0);
    limb.V(i, 1) *= r;
    limb.V(i, 2) *= r;
  }
  Skeleton s;
  s.names = {"LeftUpLeg", "LeftLeg"};
  s.parents = {-1, 0};
  s.rest = {Eigen::Isometry3d::Identity(), Eigen::Isometry3d(Eigen::Translation3d(1, 0, 0))};
  const auto proxies = fit_collision_proxies(limb.V, limb.F, s, Eigen::VectorXd(), Eigen::VectorXd());
  ASSERT_EQ(proxies.size(), 1u);
  const RoundCone& c = proxies[0].cone;
  EXPECT_NEAR(c.ra, 0.12, 0.12 * 0.05);
  EXPECT_NEAR(c.rb, 0.06, 0.06 * 0.05);
  EXPECT_LE(proxies[0].penetration, 0.02 * 0.5 * (c.ra + c.rb) * (1 + 1e-9));
  RecordProperty("radii", std::to_string(c.ra) + " " + std::to_string(c.rb));
}

TEST(CollisionProxies, ClothVerticesAreMovedInByTheirSigmaAndWeightedDown) {
  // body radius 0.08; the first bone is covered by a skirt at radius 0.2 whose vertices moved with
  // σ = 0.12 (the 1-D model: the body lies σ inside the cloth): the proxies follow the body
  TriMesh limb = make_tube(41, 32, 1.0, 0.08);
  Eigen::VectorXd sigma = Eigen::VectorXd::Zero(limb.V.rows()), delta = Eigen::VectorXd::Zero(limb.V.rows());
  for (Eigen::Index i = 0; i < limb.V.rows(); ++i)
    if (limb.V(i, 0) < 0.5 && std::hypot(limb.V(i, 1), limb.V(i, 2)) > 1e-9) {
      limb.V(i, 1) *= 2.5;
      limb.V(i, 2) *= 2.5;
      sigma(i) = 0.12;
      delta(i) = 1;
    }
  const Skeleton s = cloth_test::two_bone_skeleton();
  const auto proxies = fit_collision_proxies(limb.V, limb.F, s, sigma, delta);
  ASSERT_EQ(proxies.size(), 2u);
  for (const auto& p : proxies) {
    EXPECT_NEAR(p.cone.ra, 0.08, 0.08 * 0.1) << "bone " << p.bone.joint;
    EXPECT_NEAR(p.cone.rb, 0.08, 0.08 * 0.1) << "bone " << p.bone.joint;
  }
  // posed with the skeleton: the cone moves with its joint
  const auto T = skinning_transforms(s, cloth_test::bend_elbow(s, M_PI / 2));
  const auto posed = posed_proxies(proxies, T);
  EXPECT_LT((posed[1].b - Eigen::Vector3d(0.5, 0.5, 0)).norm(), 1e-12);
}
