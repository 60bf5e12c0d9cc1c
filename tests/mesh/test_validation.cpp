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
