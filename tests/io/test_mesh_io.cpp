#include <gtest/gtest.h>

#include <fstream>

#include "test_util.h"
#include "tbsp/core/error.h"
#include "tbsp/io/atomic_file.h"
#include "tbsp/io/mesh_io.h"
#include "tbsp/mesh/primitives.h"

using namespace tbsp;

class MeshRoundTrip : public ::testing::TestWithParam<std::pair<std::string, bool>> {};

TEST_P(MeshRoundTrip, WritesAndReadsBack) {
  const auto [ext, binary] = GetParam();
  TriMesh m = make_icosphere(2, 1.7);
  m.V.col(0).array() += 1.0 / 3.0;  // not representable in float
  m.N = m.V.rowwise().normalized();
  const auto dir = test::temp_dir("rt");
  const std::string p = (dir / ("m." + ext)).string();
  MeshWriteOptions o;
  o.binary = binary;
  write_mesh(p, m, o);
  const TriMesh r = read_mesh(p);
  EXPECT_EQ(r.F, m.F);
  EXPECT_LT((r.V - m.V).cwiseAbs().maxCoeff(), 1e-15) << "doubles survive a round trip";
  if (ext != "off") {
    ASSERT_EQ(r.N.rows(), m.V.rows());
    EXPECT_LT((r.N - m.N).cwiseAbs().maxCoeff(), 1e-6);
  }
  std::filesystem::remove_all(dir);
}

INSTANTIATE_TEST_SUITE_P(Formats, MeshRoundTrip,
                         ::testing::Values(std::make_pair(std::string("ply"), true), std::make_pair(std::string("ply"), false),
                                           std::make_pair(std::string("obj"), false), std::make_pair(std::string("off"), false),
                                           std::make_pair(std::string("vtk"), false)));

TEST(MeshIo, ColoursAndPolygonsAndNegativeObjIndices) {
  const auto dir = test::temp_dir("poly");
  const std::string obj = (dir / "q.obj").string();
  std::ofstream(obj) << "# quad + colours\nv 0 0 0 1 0 0\nv 1 0 0 0 1 0\nv 1 1 0 0 0 1\nv 0 1 0 1 1 1\nvt 0 0\nf -4/1 -3/1 -2/1 -1/1\n";
  const TriMesh q = read_mesh(obj);
  EXPECT_EQ(q.F.rows(), 2);
  ASSERT_EQ(q.C.rows(), 4);
  EXPECT_DOUBLE_EQ(q.C(1, 1), 1.0);
  const std::string off = (dir / "c.off").string();
  std::ofstream(off) << "COFF\n# comment\n4 1 0\n0 0 0 255 0 0 255\n1 0 0 0 255 0 255\n1 1 0 0 0 255 255\n0 1 0 9 9 9 255\n4 0 1 2 3\n";
  const TriMesh c = read_mesh(off);
  EXPECT_EQ(c.F.rows(), 2);
  ASSERT_EQ(c.C.rows(), 4);
  EXPECT_DOUBLE_EQ(c.C(0, 0), 1.0);
  std::filesystem::remove_all(dir);
}

TEST(MeshIo, PlyTristripsAndSkippedElements) {
  const auto dir = test::temp_dir("strip");
  const std::string p = (dir / "s.ply").string();
  std::ofstream(p) << "ply\nformat ascii 1.0\nobj_info scanner\nelement vertex 5\nproperty float x\nproperty float y\n"
                      "property float z\nelement range_grid 2\nproperty list uchar int vertex_indices\n"
                      "element tristrips 1\nproperty list int int vertex_indices\nend_header\n"
                      "0 0 0\n1 0 0\n0 1 0\n1 1 0\n2 1 0\n1 0\n0\n6 0 1 2 3 -1 4\n";
  const TriMesh m = read_mesh(p);
  EXPECT_EQ(m.V.rows(), 5);
  ASSERT_EQ(m.F.rows(), 2);
  EXPECT_EQ(m.F.row(0), Eigen::RowVector3i(0, 1, 2));
  EXPECT_EQ(m.F.row(1), Eigen::RowVector3i(2, 1, 3));  // odd triangle of a strip flips
  std::filesystem::remove_all(dir);
}

TEST(AtomicWrite, FailedWriteNeverClobbersExistingOutput) {
  const auto dir = test::temp_dir("atomic");
  const std::string p = (dir / "good.ply").string();
  const TriMesh good = make_icosphere(1);
  write_mesh(p, good);
  TriMesh bad = good;
  bad.F(0, 0) = 1000;
  EXPECT_THROW(write_mesh(p, bad), FileError);
  EXPECT_EQ(read_mesh(p).V, good.V);
  {
    AtomicFile f(p);
    f.stream() << "garbage";
    // no commit: destructor drops the temp file
  }
  EXPECT_EQ(read_mesh(p).F, good.F);
  std::size_t n = 0;
  for (auto& e : std::filesystem::directory_iterator(dir)) { (void)e; ++n; }
  EXPECT_EQ(n, 1u) << "no temp files left behind";
  EXPECT_THROW(write_mesh((dir / "no_such_dir" / "x.ply").string(), good), FileError);
  EXPECT_THROW(write_mesh((dir / "x.stl").string(), good), FileError);
  std::filesystem::remove_all(dir);
}
