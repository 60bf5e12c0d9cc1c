#include <gtest/gtest.h>

#include <Eigen/Geometry>

#include "tbsp/core/error.h"
#include "tbsp/deform/deformation_transfer.h"
#include "tet_test_util.h"

using namespace tbsp;

namespace {
TetMesh box_tets() { return test::make_bar_tets(1.0, 0.4, 5, 2); }
Eigen::MatrixX3d samples() {
  // a finer surface of the same box plus interior points
  TriMesh fine = make_box(25, 10, 10, 1.0, 0.4, 0.4);
  Eigen::MatrixX3d P(fine.V.rows() + 3, 3);
  P << fine.V, Eigen::RowVector3d(0.5, 0.2, 0.2), Eigen::RowVector3d(0.1, 0.3, 0.05), Eigen::RowVector3d(0.93, 0.01, 0.38);
  return P;
}
}  // namespace

TEST(DeformationTransfer, ReproducesIdentityRigidAndAffineMotions) {
  const TetMesh t = box_tets();
  const Eigen::MatrixX3d P = samples();
  DeformationTransfer dt;
  dt.precompute(t, P);
  EXPECT_NEAR(dt.radius(), 0.05 * bbox_diagonal(t.V), 1e-15);
  EXPECT_LT((dt.apply(t.V) - P).cwiseAbs().maxCoeff(), 1e-12);
  dt.precompute(t, P, 0.3);  // a wider blend on this coarse mesh
  EXPECT_GT(dt.meanTetsPerVertex(), 5);
  EXPECT_LT((dt.apply(t.V) - P).cwiseAbs().maxCoeff(), 1e-12);
  const Eigen::Matrix3d R = Eigen::AngleAxisd(1.1, Eigen::Vector3d(1, -2, 0.5).normalized()).toRotationMatrix();
  const Eigen::RowVector3d tr(3, -1, 2);
  const Eigen::MatrixX3d X = (t.V * R.transpose()).rowwise() + tr;
  const Eigen::MatrixX3d expect = (P * R.transpose()).rowwise() + tr;
  EXPECT_LT((dt.apply(X) - expect).cwiseAbs().maxCoeff(), 1e-12);
  Eigen::Matrix3d A;
  A << 1.3, 0.2, 0, -0.1, 0.7, 0.4, 0, 0, 2;
  EXPECT_LT((dt.apply(t.V * A.transpose()) - P * A.transpose()).cwiseAbs().maxCoeff(), 1e-12);
  // every row sums to one (partition of unity)
  const Eigen::VectorXd ones = dt.matrix() * Eigen::VectorXd::Ones(t.V.rows());
  EXPECT_LT((ones.array() - 1).abs().maxCoeff(), 1e-12);
}

TEST(DeformationTransfer, FarPointsFallBackToTheNearestTet) {
  const TetMesh t = box_tets();
  Eigen::MatrixX3d P(1, 3);
  P << 5, 5, 5;
  DeformationTransfer dt;
  dt.precompute(t, P, 0.01);
  EXPECT_EQ(dt.fallbackVertices(), 1);
  const Eigen::MatrixX3d X = t.V.rowwise() + Eigen::RowVector3d(1, 2, 3);
  EXPECT_LT((dt.apply(X) - (P.rowwise() + Eigen::RowVector3d(1, 2, 3))).norm(), 1e-9);
}

TEST(DeformationTransfer, BadInputGivesClearErrors) {
  const TetMesh t = box_tets();
  DeformationTransfer dt;
  EXPECT_THROW(dt.apply(t.V), InvalidInput);
  EXPECT_THROW(dt.precompute(t, Eigen::MatrixX3d(0, 3)), InvalidInput);
  Eigen::MatrixX3d P = samples();
  P(3, 1) = NAN;
  EXPECT_THROW(dt.precompute(t, P), InvalidInput);
  dt.precompute(t, samples());
  EXPECT_THROW(dt.apply(Eigen::MatrixX3d::Zero(3, 3)), InvalidInput);
}

TEST(DeformationTransfer, PartsDoNotDragEachOther) {
  // Two separate tetrahedralized boxes 2 cm apart, well within the blending radius: moving one
  // must not move the surface points of the other.
  TetMesh a = tetrahedralize(make_box(2, 2, 2, 0.2, 0.2, 0.2)), b = a;
  b.V.rowwise() += Eigen::RowVector3d(0.22, 0, 0);
  TetMesh both;
  both.V.resize(a.V.rows() + b.V.rows(), 3);
  both.V << a.V, b.V;
  both.T.resize(a.T.rows() + b.T.rows(), 4);
  both.T << a.T, (b.T.array() + int(a.V.rows())).matrix();
  // hires points: on the facing sides of the two boxes
  Eigen::MatrixX3d P(2, 3);
  P << 0.2, 0.1, 0.1, 0.22, 0.1, 0.1;
  DeformationTransfer dt;
  dt.precompute(both, P, 0.3);  // the radius covers both boxes
  Eigen::MatrixX3d X = both.V;
  X.bottomRows(b.V.rows()).rowwise() += Eigen::RowVector3d(0, 0.5, 0);  // move b up
  const Eigen::MatrixX3d Q = dt.apply(X);
  EXPECT_NEAR((Q.row(0) - P.row(0)).norm(), 0.0, 1e-9);                         // on a: stays
  EXPECT_NEAR((Q.row(1) - P.row(1) - Eigen::RowVector3d(0, 0.5, 0)).norm(), 0.0, 1e-9);  // on b: moves with b
}
