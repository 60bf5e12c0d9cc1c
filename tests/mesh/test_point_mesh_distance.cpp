// closest_point_barycentric (hand-written, Ericson §5.1.5) against analytic cases and against
// CGAL's exact AABB-tree query (MeshDistance) on random triangles and points.
#include <gtest/gtest.h>

#include <random>

#include "tbsp/core/error.h"
#include "tbsp/mesh/point_mesh_distance.h"

using namespace tbsp;

namespace {
Eigen::Vector3d at(const Eigen::Vector3d& w, const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& c) {
  return w(0) * a + w(1) * b + w(2) * c;
}
}  // namespace

TEST(ClosestPointBarycentric, VoronoiRegionsOfTheUnitTriangle) {
  const Eigen::Vector3d a(0, 0, 0), b(1, 0, 0), c(0, 1, 0);
  // above the face: the orthogonal projection
  EXPECT_TRUE(closest_point_barycentric({0.2, 0.3, 5}, a, b, c).isApprox(Eigen::Vector3d(0.5, 0.2, 0.3), 1e-14));
  // beyond a vertex: that vertex
  EXPECT_EQ(closest_point_barycentric({-1, -2, 0.5}, a, b, c), Eigen::Vector3d(1, 0, 0));
  EXPECT_EQ(closest_point_barycentric({3, -0.5, -1}, a, b, c), Eigen::Vector3d(0, 1, 0));
  EXPECT_EQ(closest_point_barycentric({-0.1, 4, 0}, a, b, c), Eigen::Vector3d(0, 0, 1));
  // beyond an edge: the projection onto it
  EXPECT_TRUE(closest_point_barycentric({0.25, -3, 1}, a, b, c).isApprox(Eigen::Vector3d(0.75, 0.25, 0), 1e-14));
  EXPECT_TRUE(closest_point_barycentric({-2, 0.4, 0}, a, b, c).isApprox(Eigen::Vector3d(0.6, 0, 0.4), 1e-14));
  EXPECT_TRUE(closest_point_barycentric({1, 1, 0}, a, b, c).isApprox(Eigen::Vector3d(0, 0.5, 0.5), 1e-14));
}

TEST(ClosestPointBarycentric, DegenerateTrianglesGiveAPointOfTheLongestEdge) {
  const Eigen::Vector3d a(0, 0, 0), b(1, 0, 0), c(2, 0, 0);  // collinear: longest edge a-c
  const Eigen::Vector3d w = closest_point_barycentric({1.5, 1, 0}, a, b, c);
  EXPECT_TRUE(w.allFinite());
  EXPECT_NEAR(w.sum(), 1.0, 1e-14);
  EXPECT_TRUE(at(w, a, b, c).isApprox(Eigen::Vector3d(1.5, 0, 0), 1e-14));
  const Eigen::Vector3d z = closest_point_barycentric({1, 2, 3}, a, a, a);  // a point
  EXPECT_TRUE(z.allFinite());
  EXPECT_TRUE(at(z, a, a, a).isZero());
}

TEST(ClosestPointBarycentric, AgreesWithCgalOnRandomTriangles) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-1, 1);
  auto rnd = [&] { return Eigen::Vector3d(u(rng), u(rng), u(rng)); };
  double worst = 0;
  for (int t = 0; t < 200; ++t) {
    Eigen::MatrixX3d V(3, 3);
    V.row(0) = rnd().transpose();
    V.row(1) = rnd().transpose();
    V.row(2) = rnd().transpose();
    if (t % 10 == 0) V.row(2) = V.row(0) + 1e-3 * (V.row(1) - V.row(0)) + 1e-6 * rnd().transpose();  // sliver
    Eigen::MatrixX3i F(1, 3);
    F << 0, 1, 2;
    const MeshDistance md(V, F);
    for (int k = 0; k < 50; ++k) {
      const Eigen::Vector3d p = 2 * rnd();
      const Eigen::Vector3d w = closest_point_barycentric(p, V.row(0).transpose(), V.row(1).transpose(), V.row(2).transpose());
      ASSERT_TRUE(w.allFinite());
      EXPECT_GE(w.minCoeff(), -1e-12);
      EXPECT_NEAR(w.sum(), 1.0, 1e-12);
      const Eigen::Vector3d q = at(w, V.row(0).transpose(), V.row(1).transpose(), V.row(2).transpose());
      const double d_ours = (q - p).norm(), d_cgal = (md.closest(p) - p).norm();
      worst = std::max(worst, std::abs(d_ours - d_cgal));
    }
  }
  EXPECT_LT(worst, 1e-9) << "largest distance difference to CGAL";
}
