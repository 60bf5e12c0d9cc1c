// closest_point_barycentric (hand-written, Ericson §5.1.5) against analytic cases and against
// CGAL's exact AABB-tree query (MeshDistance) on random triangles and points; MeshDistance and
// point_mesh_distances (Embree's BVH) against brute force over every face, also far from the
// origin, where Embree's single-precision boxes must not cost exactness.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <random>

#include "tbsp/core/error.h"
#include "tbsp/mesh/point_mesh_distance.h"
#include "tbsp/mesh/primitives.h"

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

namespace {
// distance to the closest face, checking every face: the reference
double brute_force(const Eigen::MatrixX3d& V, const Eigen::MatrixX3i& F, const Eigen::Vector3d& p) {
  double best = std::numeric_limits<double>::infinity();
  for (Eigen::Index f = 0; f < F.rows(); ++f) {
    const Eigen::Vector3d a = V.row(F(f, 0)).transpose(), b = V.row(F(f, 1)).transpose(), c = V.row(F(f, 2)).transpose();
    best = std::min(best, (at(closest_point_barycentric(p, a, b, c), a, b, c) - p).norm());
  }
  return best;
}

// queries all around, just off the surface and on it (near-ties between faces)
void expect_exact(const TriMesh& m, const Eigen::Vector3d& centre, double extent, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-1, 1);
  std::uniform_int_distribution<Eigen::Index> pick(0, m.V.rows() - 1);
  Eigen::MatrixX3d Q(600, 3);
  for (Eigen::Index i = 0; i < Q.rows(); ++i) {
    const Eigen::RowVector3d r(u(rng), u(rng), u(rng));
    if (i % 3 == 0) Q.row(i) = centre.transpose() + 3 * extent * r;
    else if (i % 3 == 1) Q.row(i) = m.V.row(pick(rng)) + 1e-3 * extent * r;
    else Q.row(i) = m.V.row(pick(rng)) + 1e-9 * extent * r;
  }
  // rounding: relative to the extent, and to the coordinates (CGAL's arithmetic at 1e4 loses
  // ~1e-13 absolute to cancellation)
  const double tol = 1e-12 * extent + 1e-15 * m.V.cwiseAbs().maxCoeff();
  Eigen::VectorXi fast_faces;
  const Eigen::VectorXd fast = point_mesh_distances(m.V, m.F, Q, &fast_faces);
  Eigen::VectorXi faces;
  const Eigen::VectorXd cgal = MeshDistance(m.V, m.F).distances(Q, &faces);
  for (Eigen::Index i = 0; i < Q.rows(); ++i) {
    const Eigen::Vector3d p = Q.row(i).transpose();
    const double ref = brute_force(m.V, m.F, p);
    ASSERT_NEAR(fast(i), ref, tol) << "point_mesh_distances, query " << i;
    ASSERT_NEAR(cgal(i), ref, tol) << "MeshDistance, query " << i;
    const Eigen::Index f = faces(i);  // the face MeshDistance reports holds a closest point
    const Eigen::Vector3d a = m.V.row(m.F(f, 0)).transpose(), b = m.V.row(m.F(f, 1)).transpose(), c = m.V.row(m.F(f, 2)).transpose();
    EXPECT_NEAR((at(closest_point_barycentric(p, a, b, c), a, b, c) - p).norm(), ref, tol) << "query " << i;
    const Eigen::Index g = fast_faces(i);  // and so does the one point_mesh_distances reports
    ASSERT_TRUE(g >= 0 && g < m.F.rows()) << "query " << i;
    const Eigen::Vector3d ga = m.V.row(m.F(g, 0)).transpose(), gb = m.V.row(m.F(g, 1)).transpose(),
                          gc = m.V.row(m.F(g, 2)).transpose();
    EXPECT_NEAR((at(closest_point_barycentric(p, ga, gb, gc), ga, gb, gc) - p).norm(), ref, tol) << "query " << i;
  }
}
}  // namespace

TEST(PointMeshDistances, MatchBruteForceOnASphereAndABumpyGrid) {
  TriMesh s = make_icosphere(4, 1.0);  // 5,120 faces
  std::mt19937 rng(3);
  std::normal_distribution<double> n(0, 0.01);
  for (Eigen::Index v = 0; v < s.V.rows(); ++v) s.V.row(v) *= 1 + n(rng);
  expect_exact(s, Eigen::Vector3d::Zero(), 1.0, 11);
  TriMesh g = make_grid(40, 30, 2.0, 1.5, 0.1, 5);
  for (Eigen::Index v = 0; v < g.V.rows(); ++v) g.V(v, 2) = 0.1 * std::sin(5 * g.V(v, 0)) * std::cos(4 * g.V(v, 1));
  expect_exact(g, Eigen::Vector3d(1, 0.75, 0), 2.0, 12);
}

TEST(PointMeshDistances, StayExactFarFromTheOrigin) {
  // small triangles at 1e4, where a float step (~1e-3) is a tenth of a triangle
  TriMesh s = make_icosphere(3, 0.01);
  for (Eigen::Index v = 0; v < s.V.rows(); ++v) s.V.row(v) += Eigen::RowVector3d(1e4, -2e4, 3e3);
  expect_exact(s, Eigen::Vector3d(1e4, -2e4, 3e3), 0.01, 13);
}

TEST(PointMeshDistances, EquallyCloseFacesGiveTheLowestIndex) {
  // a fan of 6 faces around vertex 0 in the plane z = 0; a query above the centre is equally
  // close to all of them, one above an edge to the two that share it
  Eigen::MatrixX3d V(7, 3);
  V.row(0) << 0, 0, 0;
  for (int k = 0; k < 6; ++k) V.row(k + 1) << std::cos(k * M_PI / 3), std::sin(k * M_PI / 3), 0;
  Eigen::MatrixX3i F(6, 3);
  for (int k = 0; k < 6; ++k) F.row(5 - k) << 0, k + 1, (k + 1) % 6 + 1;  // reversed: index order != fan order
  Eigen::MatrixX3d Q(2, 3);
  Q << 0, 0, 0.5, 0.5 * V(2, 0), 0.5 * V(2, 1), 0.25;  // above vertex 0; above the edge 0-2
  Eigen::VectorXi faces;
  const Eigen::VectorXd d = point_mesh_distances(V, F, Q, &faces);
  EXPECT_NEAR(d(0), 0.5, 1e-15);
  EXPECT_EQ(faces(0), 0);
  // the edge 0-2 is shared by fan faces k = 0 (row 5) and k = 1 (row 4): one of them (the lower
  // index where their rounded distances tie)
  EXPECT_NEAR(d(1), 0.25, 1e-15);
  EXPECT_TRUE(faces(1) == 4 || faces(1) == 5) << faces(1);
}

TEST(PointMeshDistances, DegenerateFacesNonFiniteQueriesAndBadInput) {
  Eigen::MatrixX3d V(4, 3);
  V << 0, 0, 0, 1, 0, 0, 2, 0, 0, 0, 1, 0;
  Eigen::MatrixX3i F(2, 3);
  F << 0, 1, 2,  // collinear: a segment
      0, 1, 3;
  Eigen::MatrixX3d Q(3, 3);
  Q << 2.5, 0, 1, 0.2, 0.2, 1, std::numeric_limits<double>::infinity(), 0, 0;
  const Eigen::VectorXd d = point_mesh_distances(V, F, Q);
  EXPECT_NEAR(d(0), std::sqrt(0.25 + 1), 1e-15);
  EXPECT_NEAR(d(1), 1.0, 1e-15);
  EXPECT_TRUE(std::isnan(d(2)));
  Eigen::VectorXi faces;
  point_mesh_distances(V, F, Q, &faces);
  EXPECT_EQ(faces(2), -1);  // no face for a non-finite query
  // bad meshes: the message names the face or the vertex
  F(1, 2) = 4;
  try {
    point_mesh_distances(V, F, Q);
    ADD_FAILURE() << "no error for an index out of range";
  } catch (const InvalidInput& e) {
    EXPECT_NE(std::string(e.what()).find("face 1 refers to vertex 4"), std::string::npos) << e.what();
  }
  F(1, 2) = 3;
  V(3, 1) = std::nan("");
  try {
    point_mesh_distances(V, F, Q);
    ADD_FAILURE() << "no error for a NaN vertex";
  } catch (const InvalidInput& e) {
    EXPECT_NE(std::string(e.what()).find("vertex 3 (of face 1) is not finite"), std::string::npos) << e.what();
  }
  EXPECT_THROW(point_mesh_distances(V, Eigen::MatrixX3i(0, 3), Q), InvalidInput);
}

TEST(UpdatePointMeshDistances, EqualAFullQueryAfterLocalMoves) {
  // an icosphere whose vertices near a spot are pushed out and pulled in several times (closest
  // faces change, some points' faces move away from them), queries near and far: after each
  // update the distances and faces are the full query's to the bit
  TriMesh s = make_icosphere(4, 1.0);  // 5,120 faces
  std::mt19937 rng(21);
  std::uniform_real_distribution<double> u(-1.6, 1.6);
  Eigen::MatrixX3d Q(4001, 3);
  for (Eigen::Index i = 0; i < 4000; ++i) Q.row(i) << u(rng), u(rng), u(rng);
  Q.row(4000) << std::numeric_limits<double>::quiet_NaN(), 0, 0;
  Eigen::VectorXi faces;
  Eigen::VectorXd d = point_mesh_distances(s.V, s.F, Q, &faces);
  std::normal_distribution<double> n(0, 1);
  for (int step = 0; step < 6; ++step) {
    Eigen::Vector3d spot(n(rng), n(rng), n(rng));
    spot.normalize();
    const double amount = step % 2 ? -0.3 : 0.25;  // out, in, out...: points change sides
    std::vector<char> moved(std::size_t(s.V.rows()), 0);
    for (Eigen::Index v = 0; v < s.V.rows(); ++v) {
      const double w = 1 - (s.V.row(v).transpose() - spot).norm() / 0.5;
      if (w <= 0) continue;
      s.V.row(v) *= 1 + amount * w;
      moved[std::size_t(v)] = 1;
    }
    update_point_mesh_distances(s.V, s.F, Q, moved, d, faces);
    Eigen::VectorXi full_faces;
    const Eigen::VectorXd full = point_mesh_distances(s.V, s.F, Q, &full_faces);
    for (Eigen::Index i = 0; i < 4000; ++i) {
      ASSERT_EQ(d(i), full(i)) << "step " << step << " point " << i;
      ASSERT_EQ(faces(i), full_faces(i)) << "step " << step << " point " << i;
    }
    EXPECT_TRUE(std::isnan(d(4000)));
    EXPECT_EQ(faces(4000), -1);
  }
  // nothing moved: nothing changes
  const Eigen::VectorXd before = d;
  update_point_mesh_distances(s.V, s.F, Q, std::vector<char>(std::size_t(s.V.rows()), 0), d, faces);
  for (Eigen::Index i = 0; i < 4000; ++i) ASSERT_EQ(d(i), before(i));
}

TEST(UpdatePointMeshDistances, EquallyCloseFacesStillGiveTheLowestIndex) {
  // the fan of EquallyCloseFacesGiveTheLowestIndex: lifting the rim of faces 3..5 and putting
  // it back leaves the query above the centre equally close to all six faces again: face 0,
  // whether its old face moved or not
  Eigen::MatrixX3d V(7, 3);
  V.row(0) << 0, 0, 0;
  for (int k = 0; k < 6; ++k) V.row(k + 1) << std::cos(k * M_PI / 3), std::sin(k * M_PI / 3), 0;
  Eigen::MatrixX3i F(6, 3);
  for (int k = 0; k < 6; ++k) F.row(5 - k) << 0, k + 1, (k + 1) % 6 + 1;
  Eigen::MatrixX3d Q(1, 3);
  Q << 0, 0, 0.5;
  Eigen::VectorXi faces;
  Eigen::VectorXd d = point_mesh_distances(V, F, Q, &faces);
  ASSERT_EQ(faces(0), 0);
  std::vector<char> moved(7, 0);
  moved[0] = 1;  // the centre: every face moves
  V(0, 2) = 0.1;
  update_point_mesh_distances(V, F, Q, moved, d, faces);
  EXPECT_EQ(d(0), 0.4);
  V(0, 2) = 0;
  update_point_mesh_distances(V, F, Q, moved, d, faces);  // farther again: measured anew
  EXPECT_EQ(d(0), 0.5);
  EXPECT_EQ(faces(0), 0);
}

TEST(UpdatePointMeshDistances, BadInputIsNamed) {
  TriMesh s = make_icosphere(1, 1.0);
  Eigen::MatrixX3d Q(2, 3);
  Q << 0, 0, 2, 0, 2, 0;
  Eigen::VectorXi faces;
  Eigen::VectorXd d = point_mesh_distances(s.V, s.F, Q, &faces);
  std::vector<char> moved(std::size_t(s.V.rows()), 1);
  EXPECT_THROW(update_point_mesh_distances(s.V, s.F, Q, std::vector<char>(3, 1), d, faces), InvalidInput);
  Eigen::VectorXd d1 = d.head(1);
  EXPECT_THROW(update_point_mesh_distances(s.V, s.F, Q, moved, d1, faces), InvalidInput);
  faces(1) = -1;
  try {
    update_point_mesh_distances(s.V, s.F, Q, moved, d, faces);
    ADD_FAILURE() << "no error for a point without a face";
  } catch (const InvalidInput& e) {
    EXPECT_NE(std::string(e.what()).find("point 1 has no closest face"), std::string::npos) << e.what();
  }
}
