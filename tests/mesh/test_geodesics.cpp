#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>

#include "tbsp/core/error.h"
#include "tbsp/mesh/geodesics.h"
#include "tbsp/mesh/primitives.h"
#include "tbsp/mesh/topology.h"

using namespace tbsp;

TEST(Geodesics, DijkstraOnGridMatchesAnalyticBounds) {
  const TriMesh m = make_grid(10, 10);  // unit square, alternating diagonals
  const auto adj = vertex_adjacency(m.F, m.V.rows());
  const Eigen::VectorXd d = dijkstra_distances(m.V, adj, {0});
  EXPECT_DOUBLE_EQ(d(0), 0.0);
  EXPECT_NEAR(d(10), 1.0, 1e-12);  // along the bottom edge: exact
  // to the far corner: at least the Euclidean distance, at most the L1 path
  EXPECT_GE(d(120), std::sqrt(2.0) - 1e-12);
  EXPECT_LE(d(120), 2.0 + 1e-12);
  // on a sphere the graph distance over-estimates the great-circle distance (zig-zag paths:
  // at most ~2/sqrt(3) for equilateral triangulations) plus up to one edge near the source
  const TriMesh s = make_icosphere(4);
  const auto sadj = vertex_adjacency(s.F, s.V.rows());
  const Eigen::VectorXd ds = dijkstra_distances(s.V, sadj, {0});
  for (Eigen::Index i = 0; i < s.V.rows(); i += 97) {
    const double exact = std::acos(std::clamp(s.V.row(0).dot(s.V.row(i)), -1.0, 1.0));
    EXPECT_GE(ds(i), exact - 1e-9);
    EXPECT_LE(ds(i), 1.16 * exact + 0.06);  // level-4 edge length is ~0.06
  }
}

TEST(Geodesics, GlobalScaleFromGeodesicRatios) {
  const TriMesh m = make_tube(20, 10, 1.0, 0.2);
  const std::vector<int> marks{0, 55, 120, 199, 150};
  const Eigen::Matrix3d R = Eigen::AngleAxisd(1.1, Eigen::Vector3d(1, 2, 3).normalized()).toRotationMatrix();
  const Eigen::MatrixX3d scaled = ((3.0 * m.V) * R.transpose()).rowwise() + Eigen::RowVector3d(4, 5, 6);
  EXPECT_NEAR(global_scale_from_geodesics(m.V, scaled, m.F, marks), 3.0, 1e-12);
  EXPECT_NEAR(global_scale_from_geodesics(scaled, m.V, m.F, marks), 1.0 / 3.0, 1e-12);
  EXPECT_THROW(global_scale_from_geodesics(m.V, scaled, m.F, {3}), InvalidInput);
  EXPECT_THROW(global_scale_from_geodesics(m.V, scaled, m.F, {3, 100000}), InvalidInput);
  EXPECT_THROW(global_scale_from_geodesics(m.V, Eigen::MatrixX3d(m.V.topRows(5)), m.F, marks), InvalidInput);
}

TEST(Geodesics, DistanceMatrixSymmetricAndInfiniteAcrossComponents) {
  TriMesh a = make_icosphere(1);
  TriMesh m;
  m.V.resize(2 * a.V.rows(), 3);
  m.V << a.V, (a.V.rowwise() + Eigen::RowVector3d(3, 0, 0));
  m.F.resize(2 * a.F.rows(), 3);
  m.F << a.F, (a.F.array() + int(a.V.rows())).matrix();
  const Eigen::MatrixXd D = geodesic_distance_matrix(m.V, m.F, {0, 5, int(a.V.rows()) + 2});
  EXPECT_LT((D.topLeftCorner(2, 2) - D.topLeftCorner(2, 2).transpose()).norm(), 1e-12);
  EXPECT_TRUE(std::isinf(D(0, 2)));
  int calls = 0;
  EXPECT_THROW(geodesic_distance_matrix(m.V, m.F, {0, 5}, [&](double, const std::string&) { return ++calls < 1; }),
               Cancelled);
}

TEST(Geodesics, PathsMatchTheDistancesAndRescaleExactly) {
  const TriMesh m = make_tube(20, 10, 1.0, 0.2);
  const std::vector<int> marks{0, 55, 120, 199};
  const Eigen::MatrixXd D = geodesic_distance_matrix(m.V, m.F, marks);
  const auto paths = geodesic_paths(m.V, m.F, marks);
  ASSERT_EQ(paths.size(), marks.size());
  const auto adj = vertex_adjacency(m.F, m.V.rows());
  for (std::size_t a = 0; a < marks.size(); ++a)
    for (std::size_t b = 0; b < marks.size(); ++b) {
      const auto& p = paths[a][b];
      if (a == b) { EXPECT_TRUE(p.empty()); continue; }
      ASSERT_GE(p.size(), 2u);
      EXPECT_EQ(p.front(), marks[a]);
      EXPECT_EQ(p.back(), marks[b]);
      for (std::size_t k = 1; k < p.size(); ++k)  // consecutive vertices share an edge
        EXPECT_NE(std::find(adj[std::size_t(p[k - 1])].begin(), adj[std::size_t(p[k - 1])].end(), p[k]),
                  adj[std::size_t(p[k - 1])].end());
      EXPECT_NEAR(path_length(m.V, p), D(Eigen::Index(a), Eigen::Index(b)), 1e-9);
      // a rigid motion + uniform scale multiplies the length of the same path exactly
      const Eigen::MatrixX3d S = (2.5 * m.V).rowwise() + Eigen::RowVector3d(1, -2, 3);
      EXPECT_NEAR(path_length(S, p), 2.5 * path_length(m.V, p), 1e-9);
    }
  // different components: no path
  TriMesh a = make_icosphere(1), two;
  two.V.resize(2 * a.V.rows(), 3);
  two.V << a.V, (a.V.rowwise() + Eigen::RowVector3d(3, 0, 0));
  two.F.resize(2 * a.F.rows(), 3);
  two.F << a.F, (a.F.array() + int(a.V.rows())).matrix();
  const auto p2 = geodesic_paths(two.V, two.F, {0, int(a.V.rows()) + 2});
  EXPECT_TRUE(p2[0][1].empty());
  EXPECT_THROW(geodesic_paths(m.V, m.F, {0, 100000}), InvalidInput);
}
