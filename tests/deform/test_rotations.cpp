#include <gtest/gtest.h>

#include <Eigen/Geometry>

#include "tbsp/deform/rotation_field.h"
#include "tbsp/deform/rotations.h"
#include "tbsp/mesh/primitives.h"

using namespace tbsp;

TEST(ClosestRotation, PolarIterationRecoversRotationFromStretch) {
  const Eigen::Matrix3d R = Eigen::AngleAxisd(2.5, Eigen::Vector3d(1, -2, 0.5).normalized()).toRotationMatrix();
  Eigen::Matrix3d S;
  S << 2.0, 0.3, 0.1, 0.3, 1.5, -0.2, 0.1, -0.2, 0.7;  // symmetric positive definite
  int it = 0;
  const Eigen::Matrix3d Q = closest_rotation(R * S, &it);
  EXPECT_LT((Q - R).norm(), 1e-10);
  EXPECT_GT(it, 0) << "eq. 3.15 iteration was used";
  EXPECT_LT(it, 50);
}

TEST(ClosestRotation, ReflectionAndRankDeficientInputsGiveProperRotations) {
  Eigen::Matrix3d M = Eigen::Vector3d(1, 1, -1).asDiagonal();  // a reflection
  Eigen::Matrix3d Q = closest_rotation(M);
  EXPECT_NEAR(Q.determinant(), 1.0, 1e-12);
  EXPECT_LT((Q.transpose() * Q - Eigen::Matrix3d::Identity()).norm(), 1e-12);
  // rank 2: a rotation applied to a planar configuration
  const Eigen::Matrix3d R = Eigen::AngleAxisd(0.7, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  const Eigen::Matrix3d P = Eigen::Vector3d(1, 1, 0).asDiagonal();
  Q = closest_rotation(R * P);
  EXPECT_LT((Q - R).norm(), 1e-10);
  EXPECT_TRUE(closest_rotation(Eigen::Matrix3d::Zero()).allFinite());
}

TEST(RotationField, NodeRotationsOfARigidMotionAreExact) {
  const TriMesh m = make_icosphere(2);
  const std::vector<int> nodes{0, 1, 2, 3, 4, 5, 6, 7};
  const ConstraintGraph g = ConstraintGraph::build(m.V, m.F, nodes);
  // MST has k-1 edges, every node has >= 3 neighbours
  for (const auto& nb : g.neighbours) EXPECT_GE(nb.size(), 3u);
  int tree_edges = 0;
  for (int p : g.tree_parent) tree_edges += p >= 0;
  EXPECT_EQ(tree_edges, 7);
  Eigen::MatrixX3d P(8, 3);
  for (int i = 0; i < 8; ++i) P.row(i) = m.V.row(nodes[std::size_t(i)]);
  const Eigen::Matrix3d R = Eigen::AngleAxisd(2.6, Eigen::Vector3d(0.2, 1, 0.3).normalized()).toRotationMatrix();
  const Eigen::MatrixX3d Q = (P * R.transpose()).rowwise() + Eigen::RowVector3d(1, 2, 3);
  for (const auto& Ri : node_rotations(g, P, Q)) EXPECT_LT((Ri - R).norm(), 1e-9);
  // dense field of one rotation everywhere is that rotation everywhere (hemisphere signs)
  RotationField f;
  f.compute(m.V, m.F, nodes, g.tree_parent, g.tree_order);
  std::vector<Eigen::Matrix3d> same(8, R);
  for (int i = 0; i < 8; i += 2) same[std::size_t(i)] = R;  // identical, signs may differ after conversion
  for (const auto& Rv : f.interpolate(same)) EXPECT_LT((Rv - R).norm(), 1e-9);
}

TEST(RotationField, HemisphereConsistencyFlipsSigns) {
  std::vector<Eigen::Quaterniond> q{Eigen::Quaterniond(1, 0, 0, 0), Eigen::Quaterniond(-0.9, -0.1, 0, 0)};
  q[1].normalize();
  make_hemisphere_consistent(q, {0, 1}, {-1, 0});
  EXPECT_GT(q[1].w(), 0);
}
