// Skeleton, bone-heat weights and dual-quaternion skinning against analytic cases.
#include <gtest/gtest.h>

#include <cmath>

#include "cloth_test_util.h"
#include "tbsp/cloth/skeleton.h"
#include "tbsp/core/error.h"

using namespace tbsp;

namespace {

Eigen::Isometry3d random_rigid(unsigned seed) {
  std::srand(seed);
  const Eigen::Vector3d axis = Eigen::Vector3d::Random().normalized();
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.rotate(Eigen::AngleAxisd(2.5 * (std::rand() / double(RAND_MAX)) - 1.2, axis));
  T.translation() = Eigen::Vector3d::Random();
  return T;
}

SkinningWeights weights(const std::vector<std::vector<std::pair<int, double>>>& rows, int joints) {
  std::vector<Eigen::Triplet<double>> t;
  for (std::size_t i = 0; i < rows.size(); ++i)
    for (auto [j, w] : rows[i]) t.emplace_back(int(i), j, w);
  SkinningWeights W(Eigen::Index(rows.size()), joints);
  W.setFromTriplets(t.begin(), t.end());
  return W;
}

}  // namespace

TEST(Skinning, OneJointIsExactlyRigid) {
  Eigen::MatrixX3d V = Eigen::MatrixX3d::Random(50, 3);
  const std::vector<Eigen::Isometry3d> T = {random_rigid(3), random_rigid(4)};
  std::vector<std::vector<std::pair<int, double>>> rows(50);
  for (int i = 0; i < 50; ++i) rows[std::size_t(i)] = {{i % 2, 1.0}};
  const Eigen::MatrixX3d dq = dual_quaternion_skinning(V, weights(rows, 2), T);
  const Eigen::MatrixX3d lb = linear_blend_skinning(V, weights(rows, 2), T);
  for (int i = 0; i < 50; ++i) {
    const Eigen::Vector3d expect = T[std::size_t(i % 2)] * V.row(i).transpose();
    EXPECT_LT((dq.row(i).transpose() - expect).norm(), 1e-12);
    EXPECT_LT((lb.row(i).transpose() - expect).norm(), 1e-12);
  }
}

TEST(Skinning, EqualTransformsBlendToTheSameRigidMotionWhateverTheQuaternionSign) {
  // q and −q are the same rotation: the blend must align signs to the dominant joint
  const Eigen::Isometry3d T = random_rigid(7);
  Eigen::MatrixX3d V = Eigen::MatrixX3d::Random(20, 3);
  std::vector<std::vector<std::pair<int, double>>> rows(20, {{0, 0.3}, {1, 0.7}});
  const Eigen::MatrixX3d dq = dual_quaternion_skinning(V, weights(rows, 2), {T, T});
  for (int i = 0; i < 20; ++i) EXPECT_LT((dq.row(i).transpose() - T * V.row(i).transpose()).norm(), 1e-12);
}

TEST(Skinning, DualQuaternionsKeepTheRadiusOfATwistWhereLinearBlendCollapses) {
  // a ring around the x axis, half weighted to identity and half to a 160° twist about x:
  // DQS rotates it by 80° (radius kept); LBS shrinks it to cos(80°)
  const double r = 0.1, twist = 160.0 * M_PI / 180;
  Eigen::MatrixX3d V(36, 3);
  for (int i = 0; i < 36; ++i) V.row(i) << 0.5, r * std::cos(i * M_PI / 18), r * std::sin(i * M_PI / 18);
  Eigen::Isometry3d R = Eigen::Isometry3d::Identity();
  R.rotate(Eigen::AngleAxisd(twist, Eigen::Vector3d::UnitX()));
  std::vector<std::vector<std::pair<int, double>>> rows(36, {{0, 0.5}, {1, 0.5}});
  const Eigen::MatrixX3d dq = dual_quaternion_skinning(V, weights(rows, 2), {Eigen::Isometry3d::Identity(), R});
  const Eigen::MatrixX3d lb = linear_blend_skinning(V, weights(rows, 2), {Eigen::Isometry3d::Identity(), R});
  for (int i = 0; i < 36; ++i) {
    EXPECT_NEAR(Eigen::Vector2d(dq(i, 1), dq(i, 2)).norm(), r, 1e-12);
    EXPECT_NEAR(dq(i, 0), 0.5, 1e-12);
    EXPECT_NEAR(Eigen::Vector2d(lb(i, 1), lb(i, 2)).norm(), r * std::cos(twist / 2), 1e-12);
  }
}

TEST(Skinning, SizeMismatchesAreClearErrors) {
  Eigen::MatrixX3d V = Eigen::MatrixX3d::Random(5, 3);
  std::vector<std::vector<std::pair<int, double>>> rows(4, {{0, 1.0}});
  EXPECT_THROW(dual_quaternion_skinning(V, weights(rows, 1), {Eigen::Isometry3d::Identity()}), InvalidInput);
  const Skeleton s = cloth_test::two_bone_skeleton();
  EXPECT_THROW(skinning_transforms(s, SkeletonPose(2)), InvalidInput);
  Skeleton bad = s;
  bad.parents = {-1, 2, 1};
  EXPECT_THROW(validate_skeleton(bad), InvalidInput);
}

TEST(BoneHeat, TubeWeightsFollowTheBonesAndBendRigidlyAwayFromTheJoint) {
  const TriMesh tube = make_tube(41, 24, 1.0, 0.08);
  const Skeleton s = cloth_test::two_bone_skeleton();
  const SkinningWeights W = bone_heat_weights(tube.V, tube.F, s);
  ASSERT_EQ(W.rows(), tube.V.rows());
  ASSERT_EQ(W.cols(), 3);
  for (Eigen::Index i = 0; i < W.rows(); ++i) {
    double sum = 0;
    for (SkinningWeights::InnerIterator it(W, i); it; ++it) {
      EXPECT_GE(it.value(), 0);
      sum += it.value();
    }
    EXPECT_NEAR(sum, 1.0, 1e-12);
    EXPECT_EQ(W.coeff(i, 2), 0) << "the end joint has no bone";
  }
  // far from the elbow a single bone rules; the weight of joint 1 grows along x
  double prev = -1;
  for (int ring = 0; ring < 41; ring += 4) {
    const double x = ring / 40.0;
    const double w1 = W.coeff(ring * 24, 1);
    if (x < 0.3) {
      EXPECT_LT(w1, 0.02) << "x=" << x;
    }
    if (x > 0.7) {
      EXPECT_GT(w1, 0.98) << "x=" << x;
    }
    EXPECT_GE(w1, prev - 1e-9);
    prev = w1;
  }
  EXPECT_NEAR(W.coeff(20 * 24, 1), 0.5, 0.15);  // the elbow ring shares
  // bending the elbow by 90°: the far end moves rigidly with bone 2
  const SkeletonPose pose = cloth_test::bend_elbow(s, M_PI / 2);
  const auto T = skinning_transforms(s, pose);
  const Eigen::MatrixX3d P = dual_quaternion_skinning(tube.V, W, T);
  for (int s_ = 0; s_ < 24; ++s_) {
    const int i = 40 * 24 + s_;
    EXPECT_LT((P.row(i).transpose() - T[1] * tube.V.row(i).transpose()).norm(), 1e-9);
  }
}

TEST(BoneHeat, BadInputIsAClearError) {
  const TriMesh tube = make_tube(5, 8, 1.0, 0.08);
  const Skeleton s = cloth_test::two_bone_skeleton();
  EXPECT_THROW(bone_heat_weights(Eigen::MatrixX3d(), tube.F, s), InvalidInput);
  Skeleton single;
  single.names = {"Root"};
  single.parents = {-1};
  single.rest = {Eigen::Isometry3d::Identity()};
  EXPECT_THROW(bone_heat_weights(tube.V, tube.F, single), InvalidInput);  // no bones
  Eigen::MatrixX3d nan = tube.V;
  nan(3, 1) = std::nan("");
  EXPECT_THROW(bone_heat_weights(nan, tube.F, s), InvalidInput);
}
