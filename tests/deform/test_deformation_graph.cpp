// DeformationGraph (embedded deformation, Sumner et al. 2007): analytic cases.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <algorithm>
#include <limits>
#include <set>
#include <vector>

#include "tbsp/core/error.h"
#include "tbsp/deform/deformation_graph.h"
#include "tbsp/mesh/geodesics.h"
#include "tbsp/mesh/primitives.h"
#include "tbsp/mesh/topology.h"

using namespace tbsp;

TEST(DeformationGraph, ReproducesARigidMotionExactly) {
  const TriMesh m = make_tube(21, 12, 1.0, 0.1);
  DeformationGraph g;
  g.build(m.V, m.F, 40);
  EXPECT_EQ(g.nodeCount(), 40);
  const Eigen::Matrix3d R = Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, 2, 3).normalized()).toRotationMatrix();
  const Eigen::Vector3d t(0.3, -0.2, 0.5);
  std::vector<GraphConstraint> c;
  for (Eigen::Index v = 0; v < m.V.rows(); v += 3) c.push_back({int(v), R * m.V.row(v).transpose() + t, Eigen::Vector3d::Zero(), 1.0});
  for (int it = 0; it < 8; ++it) g.solve(c, 1.0);
  const Eigen::MatrixX3d X = g.deform();
  for (Eigen::Index v = 0; v < m.V.rows(); ++v)
    EXPECT_LT((X.row(v).transpose() - (R * m.V.row(v).transpose() + t)).norm(), 1e-9) << v;  // also the unconstrained ones
  for (const Eigen::Matrix3d& Rj : g.rotations()) EXPECT_LT((Rj - R).norm(), 1e-8);
  for (const Eigen::Matrix3d& Rv : g.vertexRotations()) EXPECT_LT((Rv - R).norm(), 1e-8);
}

TEST(DeformationGraph, BendsABarLikeAJointAndKeepsItsLength) {
  // a tube along x: the left end held, the right end turned by 90° about z around the middle
  const TriMesh m = make_tube(41, 12, 1.0, 0.05);
  DeformationGraph g;
  g.build(m.V, m.F, 60);
  const Eigen::Matrix3d R = Eigen::AngleAxisd(M_PI / 2, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  const Eigen::Vector3d pivot(0.5, 0, 0);
  std::vector<GraphConstraint> c;
  for (Eigen::Index v = 0; v < m.V.rows(); ++v) {
    const Eigen::Vector3d p = m.V.row(v).transpose();
    if (p.x() < 0.2) c.push_back({int(v), p, Eigen::Vector3d::Zero(), 1.0});
    if (p.x() > 0.8) c.push_back({int(v), pivot + R * (p - pivot), Eigen::Vector3d::Zero(), 1.0});
  }
  for (int it = 0; it < 20; ++it) g.solve(c, 1.0);
  const Eigen::MatrixX3d X = g.deform();
  // the axis keeps its length (as rigid as possible): the centre line through the cap centres and
  // the ring centroids; ring i's centroid at arc length i/40
  double length = 0;
  Eigen::Vector3d prev = Eigen::Vector3d::Zero();
  for (int i = 0; i < 41; ++i) {
    Eigen::Vector3d ctr = Eigen::Vector3d::Zero();
    for (int k = 0; k < 12; ++k) ctr += X.row(i * 12 + k).transpose() / 12.0;
    if (i > 0) length += (ctr - prev).norm();
    prev = ctr;
  }
  EXPECT_NEAR(length, 1.0, 0.08);  // measured 0.945: blending between nodes cuts the corner a little
  // the constrained ends are reached, the middle node turned by about half of the angle
  for (const GraphConstraint& gc : c) EXPECT_LT((X.row(gc.vertex).transpose() - gc.target).norm(), 0.02);
  const std::vector<Eigen::Matrix3d> Rv = g.vertexRotations();
  const int mid = 20 * 12;  // a vertex of the middle ring
  const double angle = Eigen::AngleAxisd(Rv[std::size_t(mid)]).angle();
  EXPECT_GT(angle, 0.25 * M_PI / 2);
  EXPECT_LT(angle, 0.75 * M_PI / 2);
}

TEST(DeformationGraph, PointToPlaneConstraintsLeaveTheTangentFree) {
  // a grid pulled only along its normal: no vertex slides within the plane
  const TriMesh m = make_grid(20, 20, 1.0, 1.0);
  DeformationGraph g;
  g.build(m.V, m.F, 30);
  std::vector<GraphConstraint> c;
  for (Eigen::Index v = 0; v < m.V.rows(); ++v)
    c.push_back({int(v), m.V.row(v).transpose() + Eigen::Vector3d(0.3, -0.1, 0.05), Eigen::Vector3d::UnitZ(), 1.0});
  for (int it = 0; it < 5; ++it) g.solve(c, 1.0);
  const Eigen::MatrixX3d X = g.deform();
  for (Eigen::Index v = 0; v < m.V.rows(); ++v) {
    EXPECT_NEAR(X(v, 2), 0.05, 1e-9);
    EXPECT_NEAR(X(v, 0), m.V(v, 0), 1e-9);
    EXPECT_NEAR(X(v, 1), m.V(v, 1), 1e-9);
  }
}

namespace {
// Two 20 x 20 grids of 1 m (edges 5 cm), the second `gap` above the first (two components),
// deformed by a graph of 80 nodes: the top sheet pulled up by 0.2 m, the bottom sheet held in
// place (`hold_bottom`) or left free; `steps` Gauss-Newton steps at stiffness `alpha`. Returns
// each vertex's rise; `cross` gets the graph's edges between the sheets.
std::vector<double> pull_top_sheet(double gap, bool hold_bottom, double alpha, int steps, std::size_t* cross = nullptr) {
  TriMesh a = make_grid(20, 20, 1.0, 1.0), b = a;
  b.V.col(2).array() += gap;
  TriMesh m;
  m.V.resize(a.V.rows() * 2, 3);
  m.V << a.V, b.V;
  m.F.resize(a.F.rows() * 2, 3);
  m.F << a.F, (b.F.array() + int(a.V.rows())).matrix();
  DeformationGraph g;
  g.build(m.V, m.F, 80);
  if (cross) *cross = g.crossComponentEdges();
  std::vector<GraphConstraint> c;
  for (Eigen::Index v = 0; v < m.V.rows(); v += 2) {
    const bool top = v >= a.V.rows();
    if (top || hold_bottom)
      c.push_back({int(v), m.V.row(v).transpose() + Eigen::Vector3d(0, 0, top ? 0.2 : 0.0), Eigen::Vector3d::Zero(), 1.0});
  }
  for (int it = 0; it < steps; ++it) g.solve(c, alpha);
  const Eigen::MatrixX3d X = g.deform();
  std::vector<double> rise;
  for (Eigen::Index v = 0; v < m.V.rows(); ++v) rise.push_back(X(v, 2) - m.V(v, 2));
  return rise;
}
}  // namespace

TEST(DeformationGraph, SeparateSurfacesAreBoundToTheirOwnNodes) {
  // Vertices bind to nodes along their own surface, never across the gap: each sheet reaches
  // its own target exactly when they lie apart, and within 1 mm when they touch (2 mm apart:
  // then joined by soft regulariser edges only, which a small stiffness lets bend).
  for (const double gap : {0.3, 0.002}) {
    std::size_t cross = 0;
    const std::vector<double> rise = pull_top_sheet(gap, true, gap < 0.05 ? 1e-5 : 1.0, 5, &cross);
    EXPECT_EQ(cross > 0, gap < 0.05) << gap;
    const std::size_t half = rise.size() / 2;
    for (std::size_t v = 0; v < rise.size(); ++v) EXPECT_NEAR(rise[v], v >= half ? 0.2 : 0.0, gap < 0.05 ? 1e-3 : 1e-6) << gap << " " << v;
  }
}

TEST(DeformationGraph, PartsThatTouchMoveTogetherPartsApartDoNot) {
  // Only the top sheet has targets (+0.2 m). Touching (2 mm apart, under the 5 cm edges), the
  // bottom sheet is joined to it by regulariser edges and follows as one part; 0.3 m apart it is
  // a separate part with nothing to move it.
  for (const double gap : {0.002, 0.3}) {
    const std::vector<double> rise = pull_top_sheet(gap, false, 1.0, 10);
    for (std::size_t v = 0; v < rise.size() / 2; ++v) EXPECT_NEAR(rise[v], gap < 0.05 ? 0.2 : 0.0, 1e-3) << gap << " " << v;
  }
}

// fitTransformsTo: a rigid motion is reproduced exactly (every node gets it); a tube bent about
// its middle by a smooth rotation field is reproduced up to what blended rigid pieces lose, and
// the regulariser then sees the bend (not the rest) as the deformation.
TEST(DeformationGraph, TransformsFittedToAPoseReproduceIt) {
  const TriMesh m = make_tube(41, 12, 1.0, 0.05);
  DeformationGraph g;
  g.build(m.V, m.F, 60);
  const Eigen::Matrix3d R = Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, 2, 3).normalized()).toRotationMatrix();
  const Eigen::Vector3d t(0.3, -0.2, 0.5);
  Eigen::MatrixX3d X = (m.V * R.transpose()).rowwise() + t.transpose();
  g.fitTransformsTo(X);
  EXPECT_LT((g.deform() - X).cwiseAbs().maxCoeff(), 1e-12);
  for (const Eigen::Matrix3d& Rj : g.rotations()) EXPECT_LT((Rj - R).norm(), 1e-12);
  // bent: the right half turned by up to 90° about z, the angle rising smoothly over x in [0.3, 0.7]
  const Eigen::Vector3d pivot(0.5, 0, 0);
  for (Eigen::Index v = 0; v < m.V.rows(); ++v) {
    const Eigen::Vector3d p = m.V.row(v).transpose();
    const double s = std::clamp((p.x() - 0.3) / 0.4, 0.0, 1.0);
    const double a = 0.5 * M_PI * s * s * (3 - 2 * s);
    X.row(v) = (pivot + Eigen::AngleAxisd(a, Eigen::Vector3d::UnitZ()) * (p - pivot)).transpose();
  }
  g.fitTransformsTo(X);
  const double err = (g.deform() - X).rowwise().norm().maxCoeff();
  EXPECT_LT(err, 0.01);  // 1 % of the length (measured 0.0073: the bend between a node and the next)
  // the end rings turned by the full and by no angle
  const std::vector<Eigen::Matrix3d> Rv = g.vertexRotations();
  EXPECT_NEAR(Eigen::AngleAxisd(Rv.front()).angle(), 0.0, 1e-9);
  EXPECT_NEAR(Eigen::AngleAxisd(Rv.back()).angle(), 0.5 * M_PI, 1e-9);
  DeformationGraph empty;
  EXPECT_THROW(empty.fitTransformsTo(X), InvalidInput);
  EXPECT_THROW(g.fitTransformsTo(X.topRows(10)), InvalidInput);
  X(3, 1) = std::nan("");
  EXPECT_THROW(g.fitTransformsTo(X), InvalidInput);
}

TEST(DeformationGraph, DeterministicAndBadInputIsAClearError) {
  const TriMesh m = make_icosphere(3);
  DeformationGraph g;
  EXPECT_THROW(g.solve({}, 1.0), InvalidInput);  // not built
  EXPECT_THROW(g.build(Eigen::MatrixX3d(0, 3), m.F, 10), InvalidInput);
  EXPECT_THROW(g.build(m.V, m.F, 10, 0), InvalidInput);
  EXPECT_THROW(g.build(m.V, m.F, 10, 9), InvalidInput);
  Eigen::MatrixX3i bad = m.F;
  bad(0, 0) = int(m.V.rows());
  EXPECT_THROW(g.build(m.V, bad, 10), InvalidInput);
  g.build(m.V, m.F, 50);
  EXPECT_THROW(g.solve({{int(m.V.rows()), Eigen::Vector3d::Zero(), Eigen::Vector3d::Zero(), 1.0}}, 1.0), InvalidInput);
  EXPECT_THROW(g.solve({{0, Eigen::Vector3d::Constant(std::nan("")), Eigen::Vector3d::Zero(), 1.0}}, 1.0), InvalidInput);
  EXPECT_THROW(g.solve({{0, Eigen::Vector3d::Zero(), Eigen::Vector3d::Zero(), -1.0}}, 1.0), InvalidInput);
  EXPECT_THROW(g.solve({}, 0.0), InvalidInput);
  // same input, same bits (the assembly is sequential; nodes by farthest-point sampling)
  std::vector<GraphConstraint> c;
  for (Eigen::Index v = 0; v < m.V.rows(); v += 7) c.push_back({int(v), 1.2 * m.V.row(v).transpose(), Eigen::Vector3d::Zero(), 1.0});
  DeformationGraph h;
  h.build(m.V, m.F, 50);
  for (int it = 0; it < 3; ++it) { g.solve(c, 0.1); h.solve(c, 0.1); }
  EXPECT_EQ((g.deform() - h.deform()).cwiseAbs().maxCoeff(), 0.0);
  DeformationGraph copy = g;  // a copy solves on its own factorization
  copy.solve(c, 0.1);
  g.solve(c, 0.1);
  EXPECT_EQ((g.deform() - copy.deform()).cwiseAbs().maxCoeff(), 0.0);
}

// The graph's edges come from the bindings: nodes that share a vertex among its k nearest along
// the surface (weight > 0: nearer than its (k+1)-th). Checked against a plain Dijkstra from each
// node on a jittered grid (distinct distances), with few nodes and with more nodes than the
// search keeps queued per vertex in place (its overflow lists).
TEST(DeformationGraph, EdgesJoinNodesSharingAVertexAmongItsKNearestAlongTheSurface) {
  const TriMesh m = make_grid(30, 30, 1.0, 1.0, 0.3, 5);
  const std::vector<std::vector<int>> adj = vertex_adjacency(m.F, m.V.rows());
  for (int nodes : {25, 500}) {
    DeformationGraph g;
    g.build(m.V, m.F, nodes, 4);
    const int n = g.nodeCount();
    std::vector<Eigen::VectorXd> dist;  // per node, to every vertex
    for (int j = 0; j < n; ++j) dist.push_back(dijkstra_distances(m.V, adj, {g.nodeVertices()[std::size_t(j)]}));
    std::set<std::pair<int, int>> expected;
    for (Eigen::Index v = 0; v < m.V.rows(); ++v) {
      std::vector<std::pair<double, int>> c;
      for (int j = 0; j < n; ++j) c.push_back({dist[std::size_t(j)](v), j});
      std::sort(c.begin(), c.end());
      const double dk = c[4].first;  // the (k+1)-th
      for (int a = 0; a < 4; ++a)
        for (int b = a + 1; b < 4; ++b)
          if (c[std::size_t(a)].first < dk && c[std::size_t(b)].first < dk)
            expected.insert({std::min(c[std::size_t(a)].second, c[std::size_t(b)].second),
                             std::max(c[std::size_t(a)].second, c[std::size_t(b)].second)});
    }
    const std::set<std::pair<int, int>> got(g.edges().begin(), g.edges().end());
    EXPECT_EQ(got, expected) << nodes << " nodes";
  }
}
