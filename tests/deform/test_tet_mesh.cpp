#include <gtest/gtest.h>

#include "tbsp/core/error.h"
#include "tbsp/mesh/mesh_validation.h"
#include "tbsp/mesh/primitives.h"
#include "tbsp/mesh/tet_mesh.h"
#include "tbsp/mesh/tetrahedralize.h"
#include "tet_test_util.h"

using namespace tbsp;

TEST(Tetrahedralize, BoxKeepsItsSurfaceAndVolume) {
  const TriMesh box = make_box(6, 3, 2, 1.5, 0.6, 0.4);
  ASSERT_TRUE(validate_mesh(box).isClean());
  EXPECT_EQ(validate_mesh(box).genus, 0);
  const TetMesh t = tetrahedralize(box);
  EXPECT_NEAR(tet_mesh_volume(t), 1.5 * 0.6 * 0.4, 1e-12);
  EXPECT_GT(tet_signed_volumes(t.V, t.T).minCoeff(), 0.0);
  ASSERT_GE(t.V.rows(), box.V.rows());
  EXPECT_LT((t.V.topRows(box.V.rows()) - box.V).cwiseAbs().maxCoeff(), 1e-15);  // -Y: surface preserved
  const Eigen::MatrixX3i B = tet_boundary_faces(t.T);
  EXPECT_EQ(B.rows(), box.F.rows());
  EXPECT_NEAR(test::enclosed_volume(t.V, B), 1.5 * 0.6 * 0.4, 1e-12);  // outward oriented
  // a volume bound refines the interior
  TetgenOptions fine;
  fine.max_volume = 0.001;
  const TetMesh tf = tetrahedralize(box, fine);
  EXPECT_GT(tf.T.rows(), 2 * t.T.rows());
  EXPECT_NEAR(tet_mesh_volume(tf), 1.5 * 0.6 * 0.4, 1e-12);
}

TEST(Tetrahedralize, BadSurfacesGiveClearErrors) {
  auto expect_error = [](const TriMesh& m, const std::string& needle) {
    try {
      tetrahedralize(m);
      ADD_FAILURE() << "no error, expected '" << needle << "'";
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find(needle), std::string::npos) << e.what();
    }
  };
  TriMesh open = make_box(2, 2, 2);
  open.F.conservativeResize(open.F.rows() - 2, 3);
  expect_error(open, "boundary");
  // two overlapping boxes in one mesh: closed and manifold, but self-intersecting
  TriMesh a = make_box(2, 2, 2), two;
  two.V.resize(2 * a.V.rows(), 3);
  two.V << a.V, (a.V.array() + 0.37).matrix();
  two.F.resize(2 * a.F.rows(), 3);
  two.F << a.F, (a.F.array() + int(a.V.rows())).matrix();
  expect_error(two, "self-intersect");
  // non-manifold: a face repeated with a third copy on one edge
  TriMesh nm = make_box(1, 1, 1);
  nm.V.conservativeResize(nm.V.rows() + 1, 3);
  nm.V.row(nm.V.rows() - 1) << 0.5, 0.5, 3;
  nm.F.conservativeResize(nm.F.rows() + 1, 3);
  nm.F.row(nm.F.rows() - 1) << nm.F(0, 0), nm.F(0, 1), int(nm.V.rows()) - 1;
  expect_error(nm, "manifold");
  TriMesh flipped = make_box(2, 2, 2);
  std::swap(flipped.F(0, 1), flipped.F(0, 2));
  expect_error(flipped, "orient");
  TetgenOptions missing;
  missing.tetgen_program = "/nonexistent/tetgen";
  try {
    tetrahedralize(make_box(1, 1, 1), missing);
    ADD_FAILURE();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("install the Debian package `tetgen`"), std::string::npos) << e.what();
  }
}

TEST(Tetrahedralize, DecimationReachesTheTarget) {
  const TriMesh sphere = make_icosphere(4);  // 5120 faces
  const TriMesh d = decimate_mesh(sphere, 500);
  EXPECT_LE(d.F.rows(), 500);
  EXPECT_GE(d.F.rows(), 480);
  const MeshReport r = validate_mesh(d);
  EXPECT_TRUE(r.isClean()) << r.summary();
  EXPECT_EQ(r.genus, 0);
  const TetMesh t = tetrahedralize_to_size(sphere, 2000);
  EXPECT_GT(t.T.rows(), 1400);
  EXPECT_LT(t.T.rows(), 2600);
  EXPECT_NEAR(tet_mesh_volume(t), 4.0 / 3.0 * M_PI, 0.15);
  EXPECT_THROW(decimate_mesh(sphere, 2), InvalidInput);
}

TEST(TetMesh, SurfaceToTetsAndNeighbours) {
  TriMesh grid = make_grid(4, 3, 1.0, 0.75);  // open surface
  const TetMesh t = surface_to_tets(grid, 0.1);
  EXPECT_EQ(t.T.rows(), grid.F.rows());
  EXPECT_EQ(t.V.rows(), grid.V.rows() + grid.F.rows());
  EXPECT_LT((t.V.topRows(grid.V.rows()) - grid.V).norm(), 1e-15);
  const Eigen::VectorXd vol = tet_signed_volumes(t.V, t.T);
  EXPECT_GT(vol.minCoeff(), 0.0);
  EXPECT_NEAR(vol.sum(), 0.1 * 0.75 / 3.0, 1e-12);  // area * height / 3
  EXPECT_NO_THROW(require_valid_tet_mesh(t, "test"));
  // neighbours of a single split cube
  const TetMesh box = tetrahedralize(make_box(1, 1, 1));
  const auto N = tet_face_neighbours(box.T);
  int interior = 0;
  for (Eigen::Index j = 0; j < N.rows(); ++j)
    for (int k = 0; k < 4; ++k)
      if (N(j, k) >= 0) {
        ++interior;
        EXPECT_TRUE((N.row(N(j, k)).array() == int(j)).any());
      }
  EXPECT_EQ(interior + tet_boundary_faces(box.T).rows(), 4 * box.T.rows());
  TetMesh neg = box;
  std::swap(neg.T(0, 0), neg.T(0, 1));
  EXPECT_EQ(orient_tets(neg), 1);
  EXPECT_GT(tet_signed_volumes(neg.V, neg.T).minCoeff(), 0.0);
}

TEST(Tetrahedralize, OverlappingClosedPartsPerComponent) {
  // Two boxes pushed into each other (a limb into a torso): TetGen refuses the union (the
  // surfaces intersect); per component, each box is a volume of its own.
  TriMesh a = make_box(4, 4, 4, 1.0, 1.0, 1.0), b = make_box(4, 2, 2, 1.0, 0.4, 0.4);
  b.V.rowwise() += Eigen::RowVector3d(0.7, 0.3, 0.3);
  TriMesh both;
  both.V.resize(a.V.rows() + b.V.rows(), 3);
  both.V << a.V, b.V;
  both.F.resize(a.F.rows() + b.F.rows(), 3);
  both.F << a.F, (b.F.array() + int(a.V.rows())).matrix();
  EXPECT_THROW(tetrahedralize(both), Error);
  TriMesh dec;
  const TetMesh t = tetrahedralize_components(both, 0, {}, &dec);
  Eigen::VectorXi labels;
  EXPECT_EQ(tet_connected_components(t, labels), 2);
  EXPECT_NEAR(tet_mesh_volume(t), 1.0 + 0.16, 1e-9);  // the two volumes, the overlap counted twice
  EXPECT_EQ(dec.F.rows(), both.F.rows());             // no decimation asked
  // with a target: shared by the parts' face counts, each part decimated on its own
  const TetMesh small = tetrahedralize_components(both, 200, {}, &dec);
  EXPECT_LT(dec.F.rows(), both.F.rows());
  EXPECT_EQ(tet_connected_components(small, labels), 2);
}
