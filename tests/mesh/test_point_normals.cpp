// estimate_normals_pca and orient_normals_consistently (mesh/point_normals.h) on analytic clouds.
#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <vector>

#include "tbsp/core/error.h"
#include "tbsp/mesh/point_normals.h"

using namespace tbsp;

namespace {
// points on the surface of a dumbbell: spheres of radius 1 at x = ±2 joined by a cylinder of
// radius 0.4 along x; with the true outward normals
void dumbbell(Eigen::MatrixX3d& P, Eigen::MatrixX3d& N) {
  std::vector<Eigen::Vector3d> p, n;
  const int ns = 6000;
  const double golden = M_PI * (3.0 - std::sqrt(5.0));
  for (double cx : {-2.0, 2.0})
    for (int i = 0; i < ns; ++i) {
      const double z = 1 - 2 * (i + 0.5) / ns, r = std::sqrt(1 - z * z), a = golden * i;
      const Eigen::Vector3d d(z, r * std::cos(a), r * std::sin(a));  // sphere axis along x
      const Eigen::Vector3d q = Eigen::Vector3d(cx, 0, 0) + d;
      if (std::abs(q.x()) < 2 && q.y() * q.y() + q.z() * q.z() < 0.16) continue;  // inside the neck
      p.push_back(q);
      n.push_back(d);
    }
  const double h = 0.04;  // about the spacing on the spheres
  for (double x = -1.9; x <= 1.9; x += h)
    for (int k = 0; k < 63; ++k) {
      const double a = 2 * M_PI * k / 63;
      const Eigen::Vector3d q(x, 0.4 * std::cos(a), 0.4 * std::sin(a));
      if ((q - Eigen::Vector3d(2, 0, 0)).norm() < 1 || (q - Eigen::Vector3d(-2, 0, 0)).norm() < 1) continue;
      p.push_back(q);
      n.push_back(Eigen::Vector3d(0, std::cos(a), std::sin(a)));
    }
  P.resize(Eigen::Index(p.size()), 3);
  N.resize(Eigen::Index(p.size()), 3);
  for (std::size_t i = 0; i < p.size(); ++i) {
    P.row(Eigen::Index(i)) = p[i].transpose();
    N.row(Eigen::Index(i)) = n[i].transpose();
  }
}

int disagreeing(const Eigen::MatrixX3d& A, const Eigen::MatrixX3d& B) {
  int c = 0;
  for (Eigen::Index i = 0; i < A.rows(); ++i) c += A.row(i).dot(B.row(i)) < 0;
  return c;
}
}  // namespace

// Orientation by a "sphere template" (radial from the origin) is wrong on the inner caps of the
// dumbbell's spheres, next to the neck; consistency with the neighbours fixes every point.
TEST(ConsistentNormals, DumbbellInnerCapsAreFixed) {
  Eigen::MatrixX3d P, truth;
  dumbbell(P, truth);
  std::mt19937 rng(7);
  Eigen::MatrixX3d N = truth;
  Eigen::VectorXd conf(P.rows());
  for (Eigen::Index i = 0; i < P.rows(); ++i) {
    if (rng() % 2) N.row(i) *= -1;  // unoriented, as from PCA
    const Eigen::RowVector3d radial = P.row(i).normalized();
    if (N.row(i).dot(radial) < 0) N.row(i) *= -1;  // the reference
    conf(i) = std::abs(N.row(i).dot(radial));
  }
  const int wrong_before = disagreeing(N, truth);
  ASSERT_GT(wrong_before, 300) << "the radial reference must be wrong somewhere for this test to mean something";
  const PointSearch tree(P);
  const NormalOrientationResult r = orient_normals_consistently(tree, N, conf, 16);
  EXPECT_EQ(disagreeing(N, truth), 0);
  EXPECT_EQ(r.flipped, wrong_before);
  EXPECT_GT(r.edges, P.rows());
  std::printf("  %ld points, radial reference wrong at %d; %d pairs, %d components, %d conflicts, %d flipped\n",
              long(P.rows()), wrong_before, r.edges, r.components, r.conflicts, r.flipped);
  // idempotent: consistent normals stay as they are
  const Eigen::MatrixX3d again = N;
  EXPECT_EQ(orient_normals_consistently(tree, N, conf, 16).flipped, 0);
  EXPECT_EQ(N, again);
}

// The two sides of a thin slab (twice the sample spacing thick: within each other's 16
// nearest neighbours) have opposite outward normals: the offset test keeps them apart. Without
// it (max_normal_offset 1) one side is made to agree with the other — wrongly.
TEST(ConsistentNormals, ThinSlabSidesStayOpposite) {
  const double h = 0.05, gap = 2 * h;
  std::vector<Eigen::Vector3d> p, n;
  for (int i = 0; i < 30; ++i)
    for (int j = 0; j < 30; ++j) {
      p.emplace_back(i * h, j * h, 0);
      n.emplace_back(0, 0, -1);
      p.emplace_back(i * h, j * h, gap);
      n.emplace_back(0, 0, 1);
    }
  Eigen::MatrixX3d P(Eigen::Index(p.size()), 3), N(Eigen::Index(p.size()), 3);
  for (std::size_t i = 0; i < p.size(); ++i) {
    P.row(Eigen::Index(i)) = p[i].transpose();
    N.row(Eigen::Index(i)) = n[i].transpose();
  }
  const Eigen::MatrixX3d truth = N;
  const Eigen::VectorXd conf = Eigen::VectorXd::Ones(P.rows());
  const PointSearch tree(P);
  const NormalOrientationResult r = orient_normals_consistently(tree, N, conf, 16);
  EXPECT_EQ(r.flipped, 0);
  EXPECT_EQ(r.components, 2);
  EXPECT_EQ(N, truth);
  Eigen::MatrixX3d M = truth;
  EXPECT_GT(orient_normals_consistently(tree, M, conf, 16, 0.7, 1.0).flipped, 0);
}

TEST(ConsistentNormals, BadInput) {
  Eigen::MatrixX3d P = Eigen::MatrixX3d::Random(50, 3);
  const PointSearch tree(P);
  Eigen::MatrixX3d N = Eigen::MatrixX3d::Zero(49, 3);
  EXPECT_THROW(orient_normals_consistently(tree, N, Eigen::VectorXd::Ones(50)), InvalidInput);
  N = Eigen::MatrixX3d::Zero(50, 3);
  N.col(2).setOnes();
  EXPECT_THROW(orient_normals_consistently(tree, N, Eigen::VectorXd::Ones(10)), InvalidInput);
  EXPECT_THROW(orient_normals_consistently(tree, N, Eigen::VectorXd::Ones(50), 1), InvalidInput);
  // non-finite normals are left out, not propagated
  N(3, 0) = std::nan("");
  EXPECT_NO_THROW(orient_normals_consistently(tree, N, Eigen::VectorXd::Ones(50)));
}

TEST(PointNormals, PcaNormalsFollowTheSurfaceUpToSign) {
  // analytic surfaces: on the dumbbell (spheres r = 1, neck r = 0.4, spacing ~0.04) the PCA
  // normal over 12 neighbours is the true normal up to the curvature of a patch of ~2 spacings:
  // |n · n_true| ≥ 0.99 (the patch subtends ~5° on the neck); on a plane it is ±z exactly
  Eigen::MatrixX3d P, Ntrue;
  dumbbell(P, Ntrue);
  const PointSearch tree(P);
  const Eigen::MatrixX3d N = estimate_normals_pca(tree, 12);
  ASSERT_EQ(N.rows(), P.rows());
  // away from the two creases where the neck meets the spheres (|x| = 2 - sqrt(0.84) ≈ 1.08:
  // there a neighbourhood spans two surfaces and PCA averages them)
  double worst = 1;
  for (Eigen::Index i = 0; i < P.rows(); ++i) {
    EXPECT_NEAR(N.row(i).norm(), 1.0, 1e-12);
    if (std::abs(std::abs(P(i, 0)) - (2 - std::sqrt(0.84))) < 0.15) continue;
    worst = std::min(worst, std::abs(N.row(i).dot(Ntrue.row(i))));
  }
  EXPECT_GE(worst, 0.99);

  Eigen::MatrixX3d G(400, 3);
  for (int i = 0; i < 400; ++i) G.row(i) << i % 20, i / 20, 3.0;
  const Eigen::MatrixX3d NG = estimate_normals_pca(PointSearch(G), 8);
  for (Eigen::Index i = 0; i < G.rows(); ++i) EXPECT_NEAR(std::abs(NG(i, 2)), 1.0, 1e-12);
  EXPECT_THROW(estimate_normals_pca(tree, 2), InvalidInput);
}
