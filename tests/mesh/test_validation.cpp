#include <gtest/gtest.h>

#include <cmath>
#include <limits>

#include "tbsp/core/error.h"
#include "tbsp/mesh/mesh_validation.h"
#include "tbsp/mesh/pcl_conversions.h"
#include "tbsp/mesh/primitives.h"

using namespace tbsp;

TEST(MeshValidation, CleanClosedMeshes) {
  const MeshReport s = validate_mesh(make_icosphere(2));
  EXPECT_TRUE(s.isClean()) << s.summary();
  EXPECT_EQ(s.genus, 0);
  EXPECT_EQ(s.boundary_edges, 0);
  const MeshReport t = validate_mesh(make_tube(5, 6));
  EXPECT_TRUE(t.isClean()) << t.summary();
  EXPECT_EQ(t.genus, 0);
}

TEST(MeshValidation, OpenGridHasOneBoundaryLoop) {
  const MeshReport r = validate_mesh(make_grid(4, 3));
  EXPECT_EQ(r.boundary_loops, 1);
  EXPECT_EQ(r.boundary_edges, 2 * (4 + 3));
  EXPECT_EQ(r.genus, -1);
  EXPECT_EQ(r.euler_characteristic, 1);
}

TEST(MeshValidation, FindsEveryProblem) {
  TriMesh m = make_grid(2, 2);  // 9 vertices, 8 faces
  m.V.conservativeResize(12, 3);
  m.V.row(9) << std::numeric_limits<double>::quiet_NaN(), 0, 0;  // non-finite + isolated
  m.V.row(10) << 5, 5, 5;                                         // isolated
  m.V.row(11) << 6, 6, 6;
  const Eigen::Index f0 = m.F.rows();
  m.F.conservativeResize(f0 + 4, 3);
  m.F.row(f0) = m.F.row(0);                     // duplicate
  m.F.row(f0 + 1) << 0, 0, 1;                   // degenerate (repeated index)
  m.F.row(f0 + 2) << 0, 1, 99;                  // bad index
  m.F.row(f0 + 3) << m.F(1, 0), m.F(1, 1), 11;  // third face on an interior edge -> non-manifold
  const MeshReport r = validate_mesh(m);
  EXPECT_EQ(r.nonfinite_vertices, std::vector<Eigen::Index>{9});
  EXPECT_EQ(r.bad_index_faces, std::vector<Eigen::Index>{f0 + 2});
  EXPECT_EQ(r.duplicate_faces, std::vector<Eigen::Index>{f0});
  EXPECT_EQ(r.degenerate_faces, std::vector<Eigen::Index>{f0 + 1});
  EXPECT_EQ(r.isolated_vertices, (std::vector<Eigen::Index>{9, 10}));
  EXPECT_FALSE(r.nonmanifold_edges.empty());
  EXPECT_FALSE(r.isClean());
  EXPECT_NE(r.summary().find("duplicate faces: 1"), std::string::npos) << r.summary();
}

TEST(MeshValidation, SeveralComponentsAndOrientation) {
  TriMesh a = make_icosphere(0), b = make_icosphere(0);
  TriMesh m;
  m.V.resize(24, 3);
  m.V << a.V, (b.V.rowwise() + Eigen::RowVector3d(5, 0, 0));
  m.F.resize(40, 3);
  m.F << a.F, (b.F.array() + 12).matrix();
  m.F.row(39) = Eigen::RowVector3i(m.F(39, 0), m.F(39, 2), m.F(39, 1));  // flip one face
  const MeshReport r = validate_mesh(m);
  EXPECT_EQ(r.components, 2);
  EXPECT_EQ(r.inconsistent_edges.size(), 3u);
  MeshRequirements req;
  req.allow_multiple_components = false;
  try {
    require_valid_mesh(m, req, "tbsp::Test");
    FAIL() << "expected InvalidInput";
  } catch (const InvalidInput& e) {
    EXPECT_NE(std::string(e.what()).find("[tbsp::Test]"), std::string::npos);
    EXPECT_NE(std::string(e.what()).find("2 components"), std::string::npos);
  }
}

TEST(MeshValidation, RequireRejectsAlwaysInvalid) {
  TriMesh empty;
  EXPECT_THROW(require_valid_mesh(empty, {}, "t"), InvalidInput);
  TriMesh m = make_icosphere(0);
  m.F(3, 1) = 40;
  try {
    require_valid_mesh(m, {}, "t");
    FAIL();
  } catch (const InvalidInput& e) {
    EXPECT_NE(std::string(e.what()).find("missing vertices"), std::string::npos) << e.what();
  }
  TriMesh open = make_grid(3, 3);
  MeshRequirements closed;
  closed.allow_boundary = false;
  EXPECT_THROW(require_valid_mesh(open, closed, "t"), InvalidInput);
}

// Found by hand (2026-12-06): a mesh in units 1e100 times too large ended in "not positive
// definite: add constraints", one 1e-100 times too small in "every face has zero area" (the
// squared norms under- and overflow). Coordinates within [1e-50, 1e50] pass, with any offset.
TEST(MeshValidation, CoordinatesOutsideTheSafeRangeAreRefusedByName) {
  for (double s : {1e-60, 1e60, 1e100, 1e-100}) {
    TriMesh m = make_icosphere(1);
    m.V *= s;
    try {
      require_valid_mesh(m, {}, "t");
      ADD_FAILURE() << s;
    } catch (const InvalidInput& e) {
      EXPECT_NE(std::string(e.what()).find("outside [1e-50, 1e50]"), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find("scale the mesh"), std::string::npos) << e.what();
    }
    // the report (tbsp validate) names the scale; it no longer calls every face degenerate
    // (their areas overflow or underflow there: 320 of 320 were listed before)
    const MeshReport r = validate_mesh(m);
    EXPECT_TRUE(r.scale_out_of_range) << s;
    EXPECT_FALSE(r.isClean()) << s;
    EXPECT_TRUE(r.degenerate_faces.empty()) << s;
    EXPECT_NE(r.summary().find("scale out of range"), std::string::npos) << r.summary();
  }
  for (double s : {1e-40, 1e40}) {
    TriMesh m = make_icosphere(1);
    m.V *= s;
    EXPECT_NO_THROW(require_valid_mesh(m, {}, "t")) << s;
    const MeshReport r = validate_mesh(m);
    EXPECT_TRUE(r.degenerate_faces.empty()) << s;
    EXPECT_FALSE(r.scale_out_of_range) << s;
    EXPECT_TRUE(r.isClean()) << s;
  }
}

TEST(PclConversions, RoundTripAndPolygons) {
  TriMesh m = make_icosphere(1);
  m.N = m.V;
  const pcl::PolygonMesh p = to_pcl(m);
  EXPECT_EQ(p.polygons.size(), std::size_t(m.F.rows()));
  const TriMesh back = from_pcl(p);
  EXPECT_EQ(back.F, m.F);
  EXPECT_LT((back.V - m.V).cwiseAbs().maxCoeff(), 1e-6);  // PCL stores float
  EXPECT_LT((back.N - m.N).cwiseAbs().maxCoeff(), 1e-6);
  pcl::PolygonMesh quad = to_pcl(make_grid(1, 1));
  quad.polygons.resize(1);
  quad.polygons[0].vertices = {0, 1, 3, 2};
  EXPECT_EQ(from_pcl(quad).F.rows(), 2);
  quad.polygons[0].vertices = {0, 1};
  EXPECT_THROW(from_pcl(quad), InvalidInput);
  quad.polygons[0].vertices = {0, 1, 17};
  EXPECT_THROW(from_pcl(quad), InvalidInput);
}

// ---- count_self_intersections

namespace {
TriMesh two_spheres(double offset) {  // two unit icospheres in one mesh, the second shifted along x
  const TriMesh s = make_icosphere(2);
  TriMesh m;
  m.V.resize(2 * s.V.rows(), 3);
  m.F.resize(2 * s.F.rows(), 3);
  m.V.topRows(s.V.rows()) = s.V;
  m.V.bottomRows(s.V.rows()) = s.V;
  m.V.bottomRows(s.V.rows()).col(0).array() += offset;
  m.F.topRows(s.F.rows()) = s.F;
  m.F.bottomRows(s.F.rows()) = s.F.array() + int(s.V.rows());
  return m;
}
}  // namespace

TEST(SelfIntersections, CleanSurfacesHaveNone) {
  for (const TriMesh& m : {make_icosphere(3), make_tube(6, 12), make_box(3, 3, 3), make_grid(5, 4, 1, 1, 0.2, 3), two_spheres(2.5)}) {
    std::vector<std::pair<int, int>> pairs;
    int degenerate = -1;
    EXPECT_EQ(count_self_intersections(m.V, m.F, &pairs, &degenerate), 0);
    EXPECT_TRUE(pairs.empty());
    EXPECT_EQ(degenerate, 0);
  }
}

TEST(SelfIntersections, InterpenetratingSpheres) {
  const TriMesh m = two_spheres(1.0);  // the spheres cross along a circle of radius sqrt(3)/2
  std::vector<std::pair<int, int>> pairs;
  const int n = count_self_intersections(m.V, m.F, &pairs);
  EXPECT_GT(n, 20);  // the circle crosses dozens of faces of each sphere
  ASSERT_EQ(int(pairs.size()), n);
  const int nf = int(m.F.rows()) / 2;
  for (const auto& [a, b] : pairs) {
    EXPECT_LT(a, b);
    EXPECT_TRUE(a < nf && b >= nf) << a << " " << b;  // one face of each sphere
    // both faces reach the plane x = 0.5 where the spheres meet
    for (int f : {a, b}) {
      double lo = 1e9, hi = -1e9;
      for (int k = 0; k < 3; ++k) {
        lo = std::min(lo, m.V(m.F(f, k), 0));
        hi = std::max(hi, m.V(m.F(f, k), 0));
      }
      EXPECT_LE(lo, 0.5 + 1e-12);
      EXPECT_GE(hi, 0.5 - 1e-12);
    }
  }
}

TEST(SelfIntersections, VertexPulledThroughTheSurface) {
  TriMesh m = make_icosphere(3);
  const int v = 0;
  m.V.row(v) *= -1.5;  // its fan now crosses the far side of the sphere
  std::vector<std::pair<int, int>> pairs;
  ASSERT_GT(count_self_intersections(m.V, m.F, &pairs), 0);
  for (const auto& [a, b] : pairs) {  // every crossing involves a face of the moved vertex
    const bool fa = m.F(a, 0) == v || m.F(a, 1) == v || m.F(a, 2) == v;
    const bool fb = m.F(b, 0) == v || m.F(b, 1) == v || m.F(b, 2) == v;
    EXPECT_TRUE(fa || fb) << a << " " << b;
  }
}

TEST(SelfIntersections, FoldedFlatOntoItselfAndTouchingOnly) {
  Eigen::MatrixX3d V(4, 3);
  V << 0, 0, 0, 1, 0, 0, 0.3, 1, 0, 0.6, 1, 0;
  Eigen::MatrixX3i F(2, 3);
  F << 0, 1, 2, 1, 0, 3;  // shares edge 0-1, third corners on the same side: folded flat, overlapping
  EXPECT_EQ(count_self_intersections(V, F), 1);
  V(3, 1) = -1;  // unfolded: a flat quad
  EXPECT_EQ(count_self_intersections(V, F), 0);
  V(3, 2) = 1e-9;  // bent by a hair: still only the shared edge in common
  EXPECT_EQ(count_self_intersections(V, F), 0);
  // two triangles touching at one shared vertex only
  Eigen::MatrixX3d W(5, 3);
  W << 0, 0, 0, 1, 0, 0, 0, 1, 0, -1, 0, 0, 0, -1, 0;
  Eigen::MatrixX3i G(2, 3);
  G << 0, 1, 2, 0, 3, 4;
  EXPECT_EQ(count_self_intersections(W, G), 0);
}

TEST(SelfIntersections, DegenerateFacesAreCountedApart) {
  Eigen::MatrixX3d V(4, 3);
  V << 0, 0, 0, 1, 0, 0, 2, 0, 0, 0, 1, 0;  // 0, 1, 2 collinear
  Eigen::MatrixX3i F(2, 3);
  F << 0, 1, 2, 1, 0, 3;
  int degenerate = 0;
  EXPECT_EQ(count_self_intersections(V, F, nullptr, &degenerate), 0);
  EXPECT_EQ(degenerate, 1);
}

TEST(SelfIntersections, BadInputIsRejected) {
  TriMesh m = make_icosphere(1);
  Eigen::MatrixX3i F = m.F;
  F(3, 1) = int(m.V.rows());
  try {
    count_self_intersections(m.V, F);
    FAIL() << "an index out of range was accepted";
  } catch (const InvalidInput& e) {
    EXPECT_NE(std::string(e.what()).find("face 3"), std::string::npos) << e.what();
  }
  Eigen::MatrixX3d V = m.V;
  V(2, 0) = std::numeric_limits<double>::quiet_NaN();
  EXPECT_THROW(count_self_intersections(V, m.F), InvalidInput);
  Eigen::MatrixX3i G(m.F.rows() + 1, 3);  // a third face on an edge: not manifold
  G << m.F, m.F.row(0);
  try {
    count_self_intersections(m.V, G);
    FAIL() << "a non-manifold mesh was accepted";
  } catch (const InvalidInput& e) {
    EXPECT_NE(std::string(e.what()).find("manifold"), std::string::npos) << e.what();
  }
}

// --- check_orientation_against: faces probed against a reference surface -----------------------

TEST(OrientationAgainstReference, SphereAgainstAFinerSphere) {
  const TriMesh ref = make_icosphere(4), coarse = make_icosphere(3);  // centroids up to ~0.01 inside
  ReferenceOrientation r = check_orientation_against(coarse.V, coarse.F, ref.V, ref.F, 0.05);
  EXPECT_EQ(r.consistent, coarse.F.rows());
  EXPECT_EQ(r.flipped, 0);
  EXPECT_EQ(r.unmatched, 0);
  EXPECT_DOUBLE_EQ(r.distance, 0.05);
  TriMesh inverted = coarse;  // every face turned inside out
  inverted.F.col(1).swap(inverted.F.col(2));
  r = check_orientation_against(inverted.V, inverted.F, ref.V, ref.F, 0.05);
  EXPECT_EQ(r.flipped, inverted.F.rows());
  ASSERT_EQ(int(r.flipped_faces.size()), r.flipped);
  EXPECT_EQ(r.flipped_faces.front(), 0);
  EXPECT_EQ(r.flipped_faces.back(), inverted.F.rows() - 1);
  TriMesh far = coarse;  // 1.5 x: 0.5 off the reference, beyond the probe
  far.V *= 1.5;
  r = check_orientation_against(far.V, far.F, ref.V, ref.F, 0.05);
  EXPECT_EQ(r.unmatched, far.F.rows());
  r = check_orientation_against(far.V, far.F, ref.V, ref.F, 0.6);  // a longer probe reaches it
  EXPECT_EQ(r.consistent, far.F.rows());
}

namespace {
// A strip along y extruded from a polyline profile in the x-z plane (faces oriented so that a
// profile running in +x has its normal along +z).
TriMesh extruded_profile(const std::vector<Eigen::Vector2d>& xz, int ny) {
  TriMesh m;
  const int nx = int(xz.size());
  m.V.resize(nx * (ny + 1), 3);
  for (int j = 0; j <= ny; ++j)
    for (int i = 0; i < nx; ++i) m.V.row(j * nx + i) << xz[std::size_t(i)](0), double(j) / ny, xz[std::size_t(i)](1);
  m.F.resize(2 * (nx - 1) * ny, 3);
  int f = 0;
  for (int j = 0; j < ny; ++j)
    for (int i = 0; i + 1 < nx; ++i) {
      const int a = j * nx + i, b = a + 1, c = a + nx, d = c + 1;
      m.F.row(f++) << a, b, d;
      m.F.row(f++) << a, d, c;
    }
  return m;
}
}  // namespace

TEST(OrientationAgainstReference, PleatLyingOnAPlane) {
  const TriMesh plane = make_grid(10, 10, 4.0, 1.0);  // z = 0, normal +z, x in [0, 4]
  ASSERT_GT(face_normals(plane.V, plane.F)(0, 2), 0);
  // an S-pleat hovering 0.01-0.03 over the plane: right at z 0.01, back at z 0.02, right at 0.03
  const std::vector<Eigen::Vector2d> profile = {{0.2, 0.01}, {1.0, 0.01}, {2.0, 0.01}, {2.0, 0.02}, {1.0, 0.02},
                                                {0.5, 0.02}, {0.5, 0.03}, {1.5, 0.03}, {3.0, 0.03}};
  const int ny = 4;
  const TriMesh pleat = extruded_profile(profile, ny);
  const ReferenceOrientation r = check_orientation_against(pleat.V, pleat.F, plane.V, plane.F, 0.1);
  // per row: 2 + 2 + 2 segments on the sheets (normals +z, -z, +z) and 2 upright turns
  EXPECT_EQ(r.consistent, 2 * ny * 4);
  EXPECT_EQ(r.flipped, 2 * ny * 2);  // the middle sheet points into the plane
  EXPECT_EQ(r.unmatched, 2 * ny * 2);  // the turns stand across the plane: the probe runs along it
  EXPECT_EQ(r.degenerate, 0);
  const Eigen::MatrixX3d N = face_normals(pleat.V, pleat.F);
  for (int f : r.flipped_faces) EXPECT_LT(N(f, 2), -0.99) << f;
  // the same pleat beyond the plane's edge (x > 4) cannot be judged
  TriMesh beyond = pleat;
  beyond.V.col(0).array() += 10;
  const ReferenceOrientation o = check_orientation_against(beyond.V, beyond.F, plane.V, plane.F, 0.1);
  EXPECT_EQ(o.unmatched, beyond.F.rows());
}

TEST(OrientationAgainstReference, ThinReferenceCancels) {
  const TriMesh plate = make_box(4, 4, 1, 1.0, 1.0, 0.01);  // a closed plate 0.01 thick
  const TriMesh sheet = extruded_profile({{0.1, 0.02}, {0.5, 0.02}, {0.9, 0.02}}, 2);  // just over its top
  // a short probe meets the top only; one longer than the plate crosses top and bottom: no verdict
  EXPECT_EQ(check_orientation_against(sheet.V, sheet.F, plate.V, plate.F, 0.015).consistent, sheet.F.rows());
  EXPECT_EQ(check_orientation_against(sheet.V, sheet.F, plate.V, plate.F, 0.5).unmatched, sheet.F.rows());
}

TEST(OrientationAgainstReference, BadInputIsRejected) {
  const TriMesh m = make_icosphere(1);
  Eigen::MatrixX3i F = m.F;
  F(3, 1) = -1;
  try {
    check_orientation_against(m.V, m.F, m.V, F, 0.1);
    FAIL() << "an index out of range was accepted";
  } catch (const InvalidInput& e) {
    EXPECT_NE(std::string(e.what()).find("face 3 of the reference"), std::string::npos) << e.what();
  }
  Eigen::MatrixX3d V = m.V;
  V(2, 1) = std::numeric_limits<double>::infinity();
  EXPECT_THROW(check_orientation_against(V, m.F, m.V, m.F, 0.1), InvalidInput);
  EXPECT_THROW(check_orientation_against(m.V, Eigen::MatrixX3i(), m.V, m.F, 0.1), InvalidInput);
  for (double d : {0.0, -1.0, std::numeric_limits<double>::quiet_NaN()})
    EXPECT_THROW(check_orientation_against(m.V, m.F, m.V, m.F, d), InvalidInput) << d;
  // a face of zero area has no normal: counted apart
  Eigen::MatrixX3d W = m.V;
  W.row(m.F(0, 1)) = W.row(m.F(0, 0));
  EXPECT_GE(check_orientation_against(W, m.F, m.V, m.F, 0.1).degenerate, 1);
}
