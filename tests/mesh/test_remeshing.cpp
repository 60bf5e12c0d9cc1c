// Remeshing utilities of the template fitter (§5.5.2 subdivision, fold detection and repair).
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <map>

#include "tbsp/core/error.h"
#include "tbsp/mesh/mesh_validation.h"
#include "tbsp/mesh/primitives.h"
#include "tbsp/mesh/remeshing.h"
#include "tbsp/mesh/topology.h"
#include "tbsp/mesh/tri_mesh.h"

using namespace tbsp;

namespace {
// index of the grid vertex nearest to (x, y)
Eigen::Index nearest_vertex(const TriMesh& m, double x, double y) {
  Eigen::Index best = 0;
  (m.V.rowwise() - Eigen::RowVector3d(x, y, 0)).rowwise().squaredNorm().minCoeff(&best);
  return best;
}
double total_area(const TriMesh& m) {
  double a = 0;
  for (Eigen::Index f = 0; f < m.F.rows(); ++f)
    a += 0.5 * (m.V.row(m.F(f, 1)) - m.V.row(m.F(f, 0))).cross(m.V.row(m.F(f, 2)) - m.V.row(m.F(f, 0))).norm();
  return a;
}
}  // namespace

TEST(LocalFolds, SmoothSurfacesHaveNone) {
  EXPECT_EQ(count_local_folds(make_icosphere(4).V, make_icosphere(4).F), 0);
  const TriMesh grid = make_grid(20, 20, 1, 1, 0.1);  // jittered but every face positive
  EXPECT_EQ(count_local_folds(grid.V, grid.F), 0);
  const TriMesh tube = make_tube(12, 16);
  EXPECT_EQ(count_local_folds(tube.V, tube.F), 0);
  const TriMesh box = make_box(4, 4, 4);  // 90° edges: folds need more than 90° within two rings
  EXPECT_EQ(count_local_folds(box.V, box.F), 0);
}

// A vertex dragged across its neighbours in a regular grid inverts the faces around it; the
// membrane of its one-ring puts it back exactly (an interior vertex of the regular grid is the
// mean of its six neighbours) and nothing else moves.
TEST(LocalFolds, UntangleRemovesAGridCrumpleExactly) {
  TriMesh m = make_grid(16, 16);
  const Eigen::MatrixX3d V0 = m.V;
  const Eigen::Index v = nearest_vertex(m, 0.5, 0.5);
  m.V(v, 0) += 2.5 / 16;  // beyond its +x neighbour
  std::vector<char> mark;
  const int folds = count_local_folds(m.V, m.F, &mark);
  EXPECT_GT(folds, 0);
  EXPECT_EQ(count_flipped_faces(m.V, m.F, face_normals(V0, m.F)), folds);  // exactly the inverted faces
  const UntangleResult r = untangle_local_folds(m.V, m.F);
  EXPECT_EQ(r.folds_before, folds);
  EXPECT_EQ(r.folds_after, 0);
  EXPECT_EQ(count_local_folds(m.V, m.F), 0);
  EXPECT_LT((m.V - V0).rowwise().norm().maxCoeff(), 1e-12);
  EXPECT_GE(r.vertices_moved, 1);
  EXPECT_LE(r.vertices_moved, 8);  // the folded faces' corners, not the whole grid
}

// On a sphere a vertex dragged along the surface past its neighbours folds the faces around it;
// the repair brings it back between them, on the surface within the sagitta of its one-ring,
// and leaves the rest of the sphere alone.
TEST(LocalFolds, UntangleRepairsADraggedSphereVertex) {
  TriMesh m = make_icosphere(3);  // edges ~0.19
  const Eigen::MatrixX3d V0 = m.V;
  const Eigen::Index v = 17;
  const Eigen::Vector3d p = m.V.row(v).transpose();
  const Eigen::Vector3d t = p.unitOrthogonal();
  m.V.row(v) = (p + 0.3 * t).normalized().transpose();  // 1.5 edge lengths along the surface
  ASSERT_GT(count_local_folds(m.V, m.F), 0);
  const UntangleResult r = untangle_local_folds(m.V, m.F);
  EXPECT_EQ(r.folds_after, 0);
  EXPECT_EQ(count_flipped_faces(m.V, m.F, face_normals(V0, m.F)), 0);
  // back between its neighbours, at their mean: inside the sphere by the one-ring's sagitta (~0.02)
  EXPECT_NEAR(m.V.row(v).norm(), 1.0, 0.03);
  EXPECT_LT((m.V.row(v) - V0.row(v)).norm(), 0.03);
  Eigen::Index changed = 0;
  for (Eigen::Index i = 0; i < m.V.rows(); ++i) changed += (m.V.row(i) - V0.row(i)).norm() > 1e-12;
  EXPECT_LE(changed, 7);  // the vertex (and at most its one-ring, if the region had to grow)
}

TEST(LocalFolds, MeshBoundaryVerticesStayFixed) {
  TriMesh m = make_grid(8, 8);
  const Eigen::Index corner = nearest_vertex(m, 0, 0);
  m.V.row(corner) = Eigen::RowVector3d(0.3, 0.3, 0);  // boundary vertex dragged inside: folds
  ASSERT_GT(count_local_folds(m.V, m.F), 0);
  const UntangleResult r = untangle_local_folds(m.V, m.F);
  EXPECT_EQ((m.V.row(corner) - Eigen::RowVector3d(0.3, 0.3, 0)).norm(), 0.0);  // never moved
  // the interior vertices may move to resolve what they can; the result is finite and reported
  EXPECT_TRUE(m.V.allFinite());
  EXPECT_EQ(r.folds_after, count_local_folds(m.V, m.F));
  EXPECT_LE(r.folds_after, r.folds_before);
}

TEST(AdaptiveSubdivision, OneMarkedFaceGetsRedAndItsNeighboursGreen) {
  const TriMesh m = make_grid(4, 4);
  std::vector<char> marked(std::size_t(m.F.rows()), 0);
  // an interior face: none of its vertices on the grid border
  Eigen::Index f0 = -1;
  for (Eigen::Index f = 0; f < m.F.rows() && f0 < 0; ++f) {
    bool interior = true;
    for (int q = 0; q < 3; ++q) {
      const Eigen::RowVector3d x = m.V.row(m.F(f, q));
      interior = interior && x(0) > 0.1 && x(0) < 0.9 && x(1) > 0.1 && x(1) < 0.9;
    }
    if (interior) f0 = f;
  }
  ASSERT_GE(f0, 0);
  marked[std::size_t(f0)] = 1;
  const SubdivisionResult s = adaptive_subdivide(m.V, m.F, marked);
  EXPECT_EQ(s.red_faces, 1);
  EXPECT_EQ(s.green_faces, 3);
  EXPECT_EQ(s.V.rows(), m.V.rows() + 3);
  EXPECT_EQ(s.F.rows(), m.F.rows() + 3 + 3);  // 1 -> 4 and three 1 -> 2
  EXPECT_EQ(s.V.topRows(m.V.rows()), m.V);    // old vertices keep their indices
  for (std::size_t k = 0; k < s.parents.size(); ++k) {
    const auto [a, b] = s.parents[k];
    EXPECT_LT((s.V.row(m.V.rows() + Eigen::Index(k)) - 0.5 * (m.V.row(a) + m.V.row(b))).norm(), 1e-15);
  }
  TriMesh out;
  out.V = s.V;
  out.F = s.F;
  EXPECT_NEAR(total_area(out), 1.0, 1e-12);  // no overlap, no gap
  Eigen::MatrixX3d up(s.F.rows(), 3);
  up.rowwise() = Eigen::RowVector3d(0, 0, 1);
  EXPECT_EQ(count_flipped_faces(s.V, s.F, up), 0);
}

namespace {
// interior edges shared by exactly two faces, boundary edges by one, none by more (manifold)
bool edges_manifold(const Eigen::MatrixX3i& F) {
  std::map<std::pair<int, int>, int> count;
  for (Eigen::Index f = 0; f < F.rows(); ++f)
    for (int k = 0; k < 3; ++k) {
      const int a = F(f, k), b = F(f, (k + 1) % 3);
      ++count[{std::min(a, b), std::max(a, b)}];
    }
  for (const auto& e : count)
    if (e.second > 2) return false;
  return true;
}
}  // namespace

// A column of a planar grid pushed 1.5 spacings along +x lies beyond the next column: the strip
// between them is a pleat (faces inverted, vertices out of order along the plane). Collapsing
// the pleat's short edges merges the out-of-order pairs; the result lies in the plane, points
// along the reference normal everywhere and covers the unit square exactly once (its unsigned
// area is the square's: no overlap left).
TEST(PleatCollapse, RemovesAPleatInAPlane) {
  TriMesh m = make_grid(16, 16);
  const Eigen::Vector3d up = face_normals(m.V, m.F).row(0).transpose();
  ASSERT_NEAR(std::abs(up.z()), 1.0, 1e-12);
  std::vector<Eigen::Index> column;
  for (double y = 0.25; y <= 0.75 + 1e-9; y += 1.0 / 16) column.push_back(nearest_vertex(m, 0.5, y));
  for (Eigen::Index v : column) m.V(v, 0) += 1.5 / 16;
  const Eigen::MatrixX3d ref_normals = face_normals(make_grid(16, 16).V, m.F);  // the plane's
  const int inverted = count_flipped_faces(m.V, m.F, ref_normals);
  ASSERT_GE(inverted, 2 * int(column.size()) - 2);
  const Eigen::Index nv = m.V.rows();
  const Eigen::MatrixX3d V0 = m.V;
  std::vector<int> old_to_new;
  const PleatCollapseResult r = collapse_pleats(m.V, m.F, [&](const Eigen::Vector3d&) { return up; }, &old_to_new);
  EXPECT_EQ(r.faces_before, inverted);
  EXPECT_EQ(r.faces_after, 0);
  EXPECT_GE(r.collapses, int(column.size()) - 2);
  EXPECT_LE(r.collapses, 2 * int(column.size()));  // about one per out-of-order pair
  const Eigen::MatrixX3d FN = face_normals(m.V, m.F);
  for (Eigen::Index f = 0; f < m.F.rows(); ++f) EXPECT_GT(FN.row(f).dot(up), 0.99) << "face " << f;
  EXPECT_LT(m.V.col(2).cwiseAbs().maxCoeff(), 1e-12);  // still in the plane
  EXPECT_NEAR(total_area(m), 1.0, 1e-9);                // covers the square once
  EXPECT_TRUE(edges_manifold(m.F));
  // the map: one entry per old vertex, removed ones -1, the others keep their place
  ASSERT_EQ(old_to_new.size(), std::size_t(nv));
  int removed = 0;
  for (Eigen::Index i = 0; i < nv; ++i) {
    const int j = old_to_new[std::size_t(i)];
    if (j < 0) {
      ++removed;
      continue;
    }
    ASSERT_LT(j, m.V.rows());
    if (std::find(column.begin(), column.end(), i) == column.end()) {  // merged partners move within the pleat
      EXPECT_LT((m.V.row(j) - V0.row(i)).norm(), 1.5 / 16 + 1e-12);
    }
  }
  EXPECT_EQ(removed, r.collapses);
  EXPECT_EQ(m.V.rows(), nv - r.collapses);
  // Euler characteristic of the disc is kept: one collapse removes 1 vertex, 3 edges, 2 faces
  EXPECT_EQ(m.V.rows() - unique_edges(m.F).rows() + m.F.rows(), 1);
}

// Nothing to do on a good surface or where there is no reference (no data near the face).
TEST(PleatCollapse, LeavesGoodSurfacesAndFacesWithoutDataAlone) {
  TriMesh m = make_icosphere(3);
  const TriMesh m0 = m;
  std::vector<int> map;
  PleatCollapseResult r = collapse_pleats(m.V, m.F, [](const Eigen::Vector3d& c) { return Eigen::Vector3d(c.normalized()); }, &map);
  EXPECT_EQ(r.faces_before, 0);
  EXPECT_EQ(r.collapses, 0);
  EXPECT_EQ(m.V, m0.V);
  EXPECT_EQ(m.F, m0.F);
  ASSERT_EQ(map.size(), std::size_t(m0.V.rows()));
  for (std::size_t i = 0; i < map.size(); ++i) EXPECT_EQ(map[i], int(i));
  // no reference (no data near any face): nothing counts
  r = collapse_pleats(m.V, m.F, [](const Eigen::Vector3d&) { return Eigen::Vector3d::Zero(); });
  EXPECT_EQ(r.faces_before, 0);
  EXPECT_EQ(r.collapses, 0);
  EXPECT_EQ(m.V, m0.V);
  // a reference pointing inwards puts every face against it: that is an orientation problem,
  // not pleats, and the mesh is not decimated
  r = collapse_pleats(m.V, m.F, [](const Eigen::Vector3d& c) { return Eigen::Vector3d(-c.normalized()); });
  EXPECT_EQ(r.faces_before, m0.F.rows());
  EXPECT_EQ(r.faces_after, m0.F.rows());
  EXPECT_EQ(r.collapses, 0);
  EXPECT_EQ(m.F, m0.F);
}

// On a curved surface: a vertex dragged along the sphere past its neighbours turns the faces
// around it inside out; collapsing it into the neighbour it passed leaves a closed sphere
// (Euler characteristic 2) with every face outwards and every vertex still on the sphere up to
// the sagitta of an edge.
TEST(PleatCollapse, RepairsADraggedSphereVertex) {
  TriMesh m = make_icosphere(3);  // edges ~0.19
  const Eigen::Index v = 17;
  const Eigen::Vector3d p = m.V.row(v).transpose();
  m.V.row(v) = (p + 0.3 * p.unitOrthogonal()).normalized().transpose();
  const auto outward = [](const Eigen::Vector3d& c) { return Eigen::Vector3d(c.normalized()); };
  const PleatCollapseResult r = collapse_pleats(m.V, m.F, outward);
  ASSERT_GT(r.faces_before, 0);
  EXPECT_EQ(r.faces_after, 0);
  EXPECT_GE(r.collapses, 1);
  EXPECT_LE(r.collapses, 3);
  const Eigen::MatrixX3d FN = face_normals(m.V, m.F);
  for (Eigen::Index f = 0; f < m.F.rows(); ++f) {
    const Eigen::Vector3d c = (m.V.row(m.F(f, 0)) + m.V.row(m.F(f, 1)) + m.V.row(m.F(f, 2))).transpose() / 3.0;
    EXPECT_GT(FN.row(f).dot(c.normalized()), 0.0) << "face " << f;
  }
  EXPECT_LT(m.V.rowwise().norm().maxCoeff(), 1.0 + 1e-12);
  EXPECT_GT(m.V.rowwise().norm().minCoeff(), 0.99);  // midpoints of ~0.2 chords: sagitta < 0.005
  EXPECT_TRUE(edges_manifold(m.F));
  EXPECT_EQ(m.V.rows() - unique_edges(m.F).rows() + m.F.rows(), 2);
}

TEST(SelfIntersectionRepair, VertexPulledThroughASphere) {
  const TriMesh s = make_icosphere(3);
  TriMesh m = s;
  const int v = 0;
  m.V.row(v) *= -1.5;  // its fan now crosses the far side of the sphere
  const IntersectionRepairResult r = repair_self_intersections(m.V, m.F);
  EXPECT_GT(r.pairs_before, 0);
  EXPECT_EQ(r.pairs_after, 0);
  EXPECT_EQ(count_self_intersections(m.V, m.F), 0);
  EXPECT_GT(r.rounds, 0);
  EXPECT_GT(r.vertices_moved, 0);
  // the vertex no longer pokes through the far side (it stops inside, as a pit: the repair
  // removes crossings, not dents), and only the neighbourhoods of the crossings moved
  EXPECT_LT(m.V.row(v).norm(), 1.0);
  int far = 0;
  for (Eigen::Index i = 0; i < m.V.rows(); ++i) far += (m.V.row(i) - s.V.row(i)).norm() > 1e-12;
  EXPECT_EQ(far, r.vertices_moved);
  EXPECT_LT(r.vertices_moved, int(m.V.rows()) / 4);
  EXPECT_EQ(count_local_folds(m.V, m.F), 0);
}

TEST(SelfIntersectionRepair, CleanMeshUntouchedAndBadMeshRejected) {
  TriMesh m = make_icosphere(2);
  const Eigen::MatrixX3d V0 = m.V;
  const IntersectionRepairResult r = repair_self_intersections(m.V, m.F);
  EXPECT_EQ(r.pairs_before, 0);
  EXPECT_EQ(r.rounds, 0);
  EXPECT_EQ(m.V, V0);
  Eigen::MatrixX3i G(m.F.rows() + 1, 3);  // a third face on an edge
  G << m.F, m.F.row(0);
  EXPECT_THROW(repair_self_intersections(m.V, G), InvalidInput);
}

TEST(Topology, GrowRegionAndUmbrellaStep) {
  const TriMesh g = make_grid(4, 4);  // 5 x 5 vertices, row-major
  const auto adj = vertex_adjacency(g.F, g.V.rows());
  std::vector<char> region(std::size_t(g.V.rows()), 0);
  region[12] = 1;  // the centre
  grow_region(region, adj, 1);
  int n = 0;
  for (char c : region) n += c;
  EXPECT_EQ(n, 1 + int(adj[12].size()));
  grow_region(region, adj, 5);  // the whole grid
  n = 0;
  for (char c : region) n += c;
  EXPECT_EQ(n, int(g.V.rows()));
  // an umbrella step moves a lifted centre vertex half-way to its neighbours' mean and nothing else
  Eigen::MatrixX3d V = g.V;
  V(12, 2) = 1.0;
  std::vector<char> only(std::size_t(g.V.rows()), 0), moved(std::size_t(g.V.rows()), 0);
  only[12] = 1;
  umbrella_step(V, adj, only, 0.5, &moved);
  EXPECT_NEAR(V(12, 2), 0.5, 1e-12);
  Eigen::RowVector3d mean = Eigen::RowVector3d::Zero();
  for (int j : adj[12]) mean += g.V.row(j);
  mean /= double(adj[12].size());
  EXPECT_NEAR(V(12, 0), 0.5 * g.V(12, 0) + 0.5 * mean(0), 1e-12);
  EXPECT_EQ(moved[12], 1);
  for (Eigen::Index i = 0; i < V.rows(); ++i)
    if (i != 12) {
      EXPECT_EQ(V.row(i), g.V.row(i));
      EXPECT_EQ(moved[std::size_t(i)], 0);
    }
}

// vertex_faces: each vertex's faces, ascending, exactly the faces that list it.
TEST(Topology, VertexFacesListEachVertexsFacesInAscendingOrder) {
  const TriMesh m = make_icosphere(2, 1.0);
  std::vector<int> off, faces;
  vertex_faces(m.F, m.V.rows(), off, faces);
  ASSERT_EQ(off.size(), std::size_t(m.V.rows()) + 1);
  EXPECT_EQ(off.back(), int(3 * m.F.rows()));
  for (Eigen::Index v = 0; v < m.V.rows(); ++v) {
    std::vector<int> expect;
    for (Eigen::Index f = 0; f < m.F.rows(); ++f)
      if ((m.F.row(f).array() == int(v)).any()) expect.push_back(int(f));
    const std::vector<int> got(faces.begin() + off[std::size_t(v)], faces.begin() + off[std::size_t(v) + 1]);
    EXPECT_EQ(got, expect) << "vertex " << v;
  }
}
