#include <gtest/gtest.h>

#include <fstream>

#include "test_util.h"
#include "tbsp/core/error.h"
#include "tbsp/io/tet_mesh_io.h"

using namespace tbsp;

namespace {
const char* kGood =
    "MeshVersionFormatted 1\n"
    "Dimension 3\n"
    "# a comment\n"
    "Vertices\n5\n"
    "0 0 0 1\n1 0 0 1\n0 1 0 1\n0 0 1 1\n1 1 1 2\n"
    "Edges\n1\n1 2 0\n"
    "Triangles\n2\n1 2 3 0\n1 2 4 0\n"
    "Tetrahedra\n2\n1 2 3 4 7\n2 3 4 5 7\n"
    "Corners\n1\n1\n"
    "End\n";

std::string write(const std::filesystem::path& dir, const std::string& name, const std::string& text) {
  const auto p = dir / name;
  std::ofstream(p) << text;
  return p.string();
}
}  // namespace

TEST(TetMeshIo, ReadsWritesAndRoundTrips) {
  const auto dir = test::temp_dir("tetio");
  const TetMesh m = read_tet_mesh(write(dir, "good.mesh", kGood));
  ASSERT_EQ(m.V.rows(), 5);
  ASSERT_EQ(m.T.rows(), 2);
  EXPECT_EQ(m.T(1, 0), 1);
  EXPECT_EQ(m.T(1, 3), 4);
  EXPECT_EQ(m.V(4, 2), 1.0);
  const std::string out = (dir / "out.mesh").string();
  TetMesh w = m;
  w.V(0, 0) = 1.0 / 3.0;
  write_tet_mesh(out, w);
  const TetMesh r = read_tet_mesh(out);
  EXPECT_EQ(r.V, w.V);  // 17 digits: lossless
  EXPECT_EQ(r.T, w.T);
  std::filesystem::remove_all(dir);
}

TEST(TetMeshIo, MalformedFilesGiveClearErrors) {
  const auto dir = test::temp_dir("tetio_bad");
  const std::string good(kGood);
  auto expect_error = [&](const std::string& name, const std::string& text, const std::string& needle) {
    const std::string p = write(dir, name, text);
    try {
      read_tet_mesh(p);
      ADD_FAILURE() << name << ": no error";
    } catch (const FileError& e) {
      const std::string msg = e.what();
      EXPECT_NE(msg.find(name), std::string::npos) << msg;
      EXPECT_NE(msg.find(needle), std::string::npos) << name << ": " << msg;
    }
  };
  expect_error("truncated.mesh", good.substr(0, good.find("2 3 4 5")), "tetrahedron 2");
  expect_error("bad_index.mesh", std::string(kGood).replace(good.find("2 3 4 5 7"), 9, "2 3 4 9 7"), "refers to vertex 9");
  expect_error("zero_index.mesh", std::string(kGood).replace(good.find("1 2 3 4 7"), 9, "0 2 3 4 7"), "refers to vertex 0");
  expect_error("nan.mesh", std::string(kGood).replace(good.find("1 1 1 2"), 7, "1 nan 1 2"), "vertex 5");
  expect_error("dim2.mesh", std::string(kGood).replace(good.find("Dimension 3"), 11, "Dimension 2"), "Dimension 2");
  expect_error("huge.mesh", "MeshVersionFormatted 1\nDimension 3\nVertices\n999999999\n0 0 0 0\n", "more than the file can hold");
  expect_error("negative.mesh", "MeshVersionFormatted 1\nDimension 3\nVertices\n-4\n", "-4");
  expect_error("unknown.mesh", std::string(kGood).replace(good.find("Corners"), 7, "Bananas"), "unknown section 'Bananas'");
  expect_error("surface_only.mesh", good.substr(0, good.find("Tetrahedra")) + "End\n", "no Tetrahedra");
  expect_error("no_vertices.mesh", "MeshVersionFormatted 1\nDimension 3\nEnd\n", "no Vertices");
  expect_error("garbage.mesh", "\x01\x02 binary junk", "");
  expect_error("tets_first.mesh", "MeshVersionFormatted 1\nDimension 3\nTetrahedra\n1\n1 2 3 4 0\nEnd\n", "no Vertices section precedes");
  try {
    read_tet_mesh((dir / "missing.mesh").string());
    ADD_FAILURE();
  } catch (const FileError& e) {
    EXPECT_NE(std::string(e.what()).find("missing.mesh"), std::string::npos);
  }
  std::filesystem::remove_all(dir);
}
