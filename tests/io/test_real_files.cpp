// Readers on real public files from ../shared/data (counts from their MANIFEST).
#include <gtest/gtest.h>

#include <pcl/conversions.h>

#include "test_util.h"
#include "tbsp/io/cloud_io.h"
#include "tbsp/io/mesh_io.h"
#include "tbsp/io/range_scan_conf.h"
#include "tbsp/mesh/mesh_validation.h"
#include "tbsp/mesh/point_mesh_distance.h"

using namespace tbsp;
using test::shared;

namespace {
TriMesh load(const std::string& rel) { return read_mesh(shared(rel)); }
}  // namespace

TEST(RealFiles, AsciiPlyReconstructionWithHolesAndUnreferencedVertices) {
  const std::string p = shared("meshes/dengnantianjie__3dcoursework/bunny/reconstruction/bun_zipper.ply");
  TBSP_REQUIRE_FILE(p);
  const TriMesh m = read_mesh(p);
  EXPECT_EQ(m.V.rows(), 35947);
  EXPECT_EQ(m.F.rows(), 69451);
  const MeshReport r = validate_mesh(m);
  EXPECT_EQ(r.boundary_loops, 5);  // holes in the bottom
  EXPECT_EQ(r.isolated_vertices.size(), 1113u);
}

TEST(RealFiles, AsciiPlyRangeScanSkipsRangeGrid) {
  const std::string p = shared("meshes/dengnantianjie__3dcoursework/bunny/data/bun000.ply");
  TBSP_REQUIRE_FILE(p);
  const TriMesh m = read_mesh(p);
  EXPECT_EQ(m.V.rows(), 40256);
  EXPECT_EQ(m.F.rows(), 0);
  EXPECT_EQ(read_cloud(p).width * read_cloud(p).height, 40256u);
}

// bun.conf (Stanford .conf, tbsp/io/range_scan_conf.h) places the real scans on the bun_zipper
// reconstruction: measured 97-99 % of each scan's points within 1 mm (median ~0.5 mm).
TEST(RealFiles, StanfordConfPlacesBunnyScansOnTheReconstruction) {
  const std::string dir = shared("meshes/dengnantianjie__3dcoursework/bunny/");
  TBSP_REQUIRE_FILE(dir + "data/bun.conf");
  const TriMesh zipper = read_mesh(dir + "reconstruction/bun_zipper.ply");
  for (const char* scan : {"bun000.ply", "bun045.ply", "bun090.ply", "bun270.ply"}) {
    const Eigen::MatrixX3d P = read_registered_range_scans(dir + "data/bun.conf", {scan});
    ASSERT_GT(P.rows(), 30000) << scan;
    const Eigen::VectorXd d = point_mesh_distances(zipper.V, zipper.F, P);
    const double within = double((d.array() < 1e-3).count()) / double(d.size());
    EXPECT_GT(within, 0.95) << scan;
  }
}

TEST(RealFiles, BinaryPlyWithNormalsAndTristrips) {
  const std::string horse = shared("meshes/alecjacobson__common-3d-test-models/data/horse.ply");
  TBSP_REQUIRE_FILE(horse);
  const TriMesh h = read_mesh(horse);
  EXPECT_EQ(h.V.rows(), 48485);
  EXPECT_EQ(h.F.rows(), 96966);
  ASSERT_EQ(h.N.rows(), 48485);
  // the file stores unnormalised normals; we read them as stored (raw bytes of vertex 100)
  EXPECT_NEAR(h.N(100, 0), 5.244577884674072, 1e-6);
  EXPECT_NEAR(h.N(100, 2), -0.26155948638916016, 1e-6);
  const TriMesh igea = load("meshes/alecjacobson__common-3d-test-models/data/igea.ply");
  EXPECT_EQ(igea.V.rows(), 134345);
  EXPECT_GT(igea.F.rows(), 260000);  // strips unrolled into triangles
  const MeshReport r = validate_mesh(igea);
  EXPECT_TRUE(r.bad_index_faces.empty());
  EXPECT_LT(r.inconsistent_edges.size(), std::size_t(igea.F.rows() / 1000)) << "strip orientation alternates correctly";
}

TEST(RealFiles, OffMeshesAndTheirTopology) {
  const std::string p = shared("meshes/libigl__libigl-tutorial-data/bunny.off");
  TBSP_REQUIRE_FILE(p);
  const TriMesh b = read_mesh(p);
  EXPECT_EQ(b.V.rows(), 3485);
  EXPECT_EQ(b.F.rows(), 6966);
  const MeshReport rb = validate_mesh(b);
  EXPECT_EQ(rb.genus, 0);
  EXPECT_EQ(validate_mesh(load("meshes/cfwen__geometry-processing-package/data/eight.off")).genus, 2);
  EXPECT_EQ(validate_mesh(load("meshes/cfwen__geometry-processing-package/data/kitten.nf20k.off")).genus, 1);
  EXPECT_FALSE(validate_mesh(load("meshes/dengnantianjie__3dcoursework/bunny/reconstruction/bun_zipper_res4.ply"))
                   .nonmanifold_edges.empty());
}

TEST(RealFiles, ObjAndVtk) {
  const std::string e = shared("meshes/libigl__libigl-tutorial-data/elephant.obj");
  TBSP_REQUIRE_FILE(e);
  const TriMesh el = read_mesh(e);
  EXPECT_GT(el.V.rows(), 6000);
  EXPECT_TRUE(validate_mesh(el).bad_index_faces.empty());
  const TriMesh human = load("meshes/dengnantianjie__3dcoursework/bunny/data/FinalBaseMesh.obj");
  EXPECT_EQ(human.V.rows(), 24461);
  const TriMesh rabbit = load("capture/PointCloudLibrary__pcl/test/tum_rabbit.vtk");
  EXPECT_EQ(rabbit.V.rows(), 10429);
  EXPECT_EQ(rabbit.F.rows(), 20715);
  ASSERT_EQ(rabbit.N.rows(), 10429);
}

TEST(RealFiles, PcdAllEncodings) {
  const std::string chef = shared("capture/PointCloudLibrary__pcl/doc/tutorials/content/sources/alignment_prerejective/chef.pcd");
  TBSP_REQUIRE_FILE(chef);
  bool normals = false;
  const auto c = read_cloud_normals(chef, &normals);  // binary_compressed (LZF)
  EXPECT_EQ(c->size(), 5092u);
  EXPECT_TRUE(normals);
  const auto b = read_cloud_normals(shared("capture/PointCloudLibrary__pcl/test/bun0.pcd"), &normals);  // ascii
  EXPECT_EQ(b->size(), 397u);
  EXPECT_TRUE(normals);
  const auto m = read_cloud_normals(shared("meshes/PointCloudLibrary__data/biwi_face_database/model.pcd"), &normals);  // binary
  EXPECT_EQ(m->size(), 100000u);
  EXPECT_FALSE(normals);
  const auto person = read_cloud(shared("meshes/PointCloudLibrary__data/tutorials/template_alignment/person.pcd"));
  EXPECT_EQ(person.width * person.height, 307200u);
}
