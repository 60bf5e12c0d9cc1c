// Every reader rejects malformed input with a FileError naming the file and the problem.
#include <gtest/gtest.h>

#include <fstream>

#include "test_util.h"
#include "tbsp/core/error.h"
#include "tbsp/io/cloud_io.h"
#include "tbsp/io/mesh_io.h"

using namespace tbsp;

namespace {
struct Case {
  std::string name, file, content, expect;
};
void PrintTo(const Case& c, std::ostream* os) { *os << c.name; }

std::string ply_header(int nv, int nf, const std::string& fmt = "ascii") {
  return "ply\nformat " + fmt + " 1.0\nelement vertex " + std::to_string(nv) +
         "\nproperty float x\nproperty float y\nproperty float z\nelement face " + std::to_string(nf) +
         "\nproperty list uchar int vertex_indices\nend_header\n";
}

std::vector<Case> cases() {
  std::string bin_trunc = ply_header(3, 1, "binary_little_endian") + std::string(20, '\0');
  return {
      {"ply_magic", "a.ply", "plx\nformat ascii 1.0\n", "not a PLY file"},
      {"ply_no_end_header", "a.ply", "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\n", "end_header"},
      {"ply_truncated", "a.ply", ply_header(3, 1) + "0 0 0\n1 0 0\n", "truncated"},
      {"ply_absurd_count", "a.ply", ply_header(1000000000, 1) + "0 0 0\n", "declares 1000000000"},
      {"ply_nan", "a.ply", ply_header(3, 1) + "0 0 0\nnan 0 0\n0 1 0\n3 0 1 2\n", "non-finite"},
      {"ply_bad_index", "a.ply", ply_header(3, 1) + "0 0 0\n1 0 0\n0 1 0\n3 0 1 7\n", "references vertex 7"},
      {"ply_negative_index", "a.ply", ply_header(3, 1) + "0 0 0\n1 0 0\n0 1 0\n3 0 -1 2\n", "references vertex -1"},
      // fuzz findings (UBSan: inf cast to an integer index)
      {"ply_inf_index", "a.ply", ply_header(3, 1) + "0 0 0\n1 0 0\n0 1 0\n3 0 inf 2\n", "is not an integer"},
      {"ply_huge_index", "a.ply", ply_header(3, 1) + "0 0 0\n1 0 0\n0 1 0\n3 0 1e300 2\n", "is not an integer"},
      {"ply_fractional_index", "a.ply", ply_header(3, 1) + "0 0 0\n1 0 0\n0 1 0\n3 0 1.5 2\n", "is not an integer"},
      {"ply_binary_truncated", "a.ply", bin_trunc, "truncated"},
      {"ply_garbage_number", "a.ply", ply_header(3, 1) + "0 0 0\n1 zero 0\n0 1 0\n3 0 1 2\n", "expected a number"},
      {"ply_unknown_format", "a.ply", "ply\nformat ebcdic 1.0\nend_header\n", "unknown PLY format"},
      {"obj_bad_index", "a.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n", "references vertex 9"},
      {"obj_nan", "a.obj", "v 0 0 0\nv inf 0 0\nv 0 1 0\nf 1 2 3\n", "non-finite"},
      {"obj_short_vertex", "a.obj", "v 0 0\n", "needs x y z"},
      {"obj_zero_index", "a.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n", "1-based"},
      {"obj_no_vertices", "a.obj", "# nothing here\n", "no vertices"},
      {"obj_bad_normal_index", "a.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nvn 0 0 1\nf 1//1 2//2 3//1\n", "normal 2"},
      {"off_magic", "a.off", "OFX\n3 1 0\n", "not an OFF file"},
      {"off_truncated", "a.off", "OFF\n4 1 0\n0 0 0\n1 0 0\n0 1 0\n", "truncated"},
      {"off_absurd_count", "a.off", "OFF\n99999999 1 0\n0 0 0\n", "declares 99999999"},
      {"off_nan", "a.off", "OFF\n3 1 0\n0 0 0\n1 nan 0\n0 1 0\n3 0 1 2\n", "non-finite"},
      {"off_bad_index", "a.off", "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 3\n", "references vertex 3"},
      {"off_missing_faces", "a.off", "OFF\n3 2 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n", "read 1 of 2 faces"},
      {"off_binary", "a.off", "OFF BINARY\n", "binary OFF is not supported"},
      {"off_bad_counts_line", "a.off", "OFF\nthree one zero\n", "count line"},
      {"vtk_magic", "a.vtk", "# not vtk\n", "not a VTK legacy file"},
      {"vtk_grid", "a.vtk", "# vtk DataFile Version 3.0\nt\nASCII\nDATASET UNSTRUCTURED_GRID\n", "POLYDATA"},
      {"vtk_truncated", "a.vtk", "# vtk DataFile Version 3.0\nt\nASCII\nDATASET POLYDATA\nPOINTS 3 float\n0 0 0 1 0 0\n", "truncated"},
      {"vtk_bad_index", "a.vtk", "# vtk DataFile Version 3.0\nt\nASCII\nDATASET POLYDATA\nPOINTS 3 float\n0 0 0 1 0 0 0 1 0\nPOLYGONS 1 4\n3 0 1 5\n", "references vertex 5"},
      {"vtk_nan", "a.vtk", "# vtk DataFile Version 3.0\nt\nASCII\nDATASET POLYDATA\nPOINTS 3 float\n0 0 0 1 0 nan 0 1 0\n", "non-finite"},
      {"vtk_size_mismatch", "a.vtk", "# vtk DataFile Version 3.0\nt\nASCII\nDATASET POLYDATA\nPOINTS 3 float\n0 0 0 1 0 0 0 1 0\nPOLYGONS 1 3\n3 0 1 2\n", "exceeds the declared size"},
      {"empty_file", "a.ply", "", "empty"},
  };
}
}  // namespace

class MalformedMesh : public ::testing::TestWithParam<Case> {};

TEST_P(MalformedMesh, GivesAClearFileError) {
  const Case& c = GetParam();
  const auto dir = test::temp_dir("bad_" + c.name);
  const std::string p = (dir / c.file).string();
  { std::ofstream(p, std::ios::binary) << c.content; }
  try {
    read_mesh(p);
    FAIL() << c.name << ": no error";
  } catch (const FileError& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find(p), std::string::npos) << "message must name the file: " << msg;
    EXPECT_NE(msg.find(c.expect), std::string::npos) << c.name << ": " << msg;
  }
  std::filesystem::remove_all(dir);
}

INSTANTIATE_TEST_SUITE_P(Parsers, MalformedMesh, ::testing::ValuesIn(cases()),
                         [](const ::testing::TestParamInfo<Case>& i) { return i.param.name; });

TEST(MalformedFiles, MissingFilesAndUnknownFormats) {
  EXPECT_THROW(read_mesh("/nonexistent/dir/x.ply"), FileError);
  EXPECT_THROW(read_mesh("/tmp"), FileError);
  try {
    read_mesh("model.stl");
    FAIL();
  } catch (const FileError& e) {
    EXPECT_NE(std::string(e.what()).find("unknown mesh format"), std::string::npos);
  }
}

TEST(MalformedFiles, PcdErrors) {
  const auto dir = test::temp_dir("badpcd");
  const std::string empty = (dir / "e.pcd").string(), garbage = (dir / "g.pcd").string(), trunc = (dir / "t.pcd").string();
  { std::ofstream(empty) << ""; }
  { std::ofstream(garbage) << "this is not a point cloud\n"; }
  {
    std::ofstream(trunc, std::ios::binary) << "# .PCD v0.7\nVERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\n"
                                              "WIDTH 1000\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS 1000\nDATA binary\n"
                                           << std::string(24, '\1');
  }
  for (const auto& p : {empty, garbage, trunc, (dir / "missing.pcd").string()}) {
    try {
      read_cloud(p);
      FAIL() << p;
    } catch (const FileError& e) {
      EXPECT_NE(std::string(e.what()).find(p), std::string::npos) << e.what();
    }
  }
  std::filesystem::remove_all(dir);
}

// Fuzz finding (scripts/fuzz, target pcd): PCL 1.13 keeps parsing header keywords in an ASCII
// body, so a data line starting with "COLUMNS" emptied its field list and the body was written
// out of bounds (segfault). The body is validated first; each case names the line.
TEST(MalformedFiles, PcdAsciiBodyIsValidatedBeforePcl) {
  const auto dir = test::temp_dir("badpcd_ascii");
  const std::string head = "# .PCD v0.7\nVERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 3\nHEIGHT 1\n"
                           "VIEWPOINT 0 0 0 1 0 0 0\nPOINTS 3\nDATA ascii\n";
  const std::vector<std::pair<std::string, std::string>> cases = {
      {"0 0 0\nCOLUMNS9Cloud \n1 1 1\n", ":13: 'COLUMNS9Cloud' is not a number"},
      {"0 0 0\n1 1\n2 2 2\n", ":13: point 1 has 2 values; FIELDS x COUNT need 3"},
      {"0 0 0\n1 1 1\n", "holds 2 of the 3 POINTS"},
      {"0 0 0\n1 1 1\n2 2 2\n3 3 3\n", ":15: more data lines than the 3 POINTS"},
  };
  for (const auto& [body, expect] : cases) {
    const std::string p = (dir / "a.pcd").string();
    std::ofstream(p) << head << body;
    try {
      read_cloud(p);
      FAIL() << body;
    } catch (const FileError& e) {
      EXPECT_NE(std::string(e.what()).find(expect), std::string::npos) << e.what();
    }
  }
  // TYPE must be I, U or F and agree with SIZE (PCL 1.13 crashes on others: fuzz finding)
  for (const auto& [types, expect] : std::vector<std::pair<std::string, std::string>>{
           {"SIZE 2 4 4\nTYPE F N F\n", "TYPE F needs SIZE 4 or 8 (got 2)"},
           {"SIZE 4 4 4\nTYPE F N F\n", "TYPE 'N' of field y is not I, U or F"},
           {"SIZE 4 4 4\nTYPE F F\n", "TYPE has 2 entries for 3 FIELDS"}}) {
    const std::string p = (dir / "t.pcd").string();
    std::ofstream(p) << "# .PCD v0.7\nVERSION 0.7\nFIELDS x y z\n" << types
                     << "COUNT 1 1 1\nWIDTH 1\nHEIGHT 1\nPOINTS 1\nDATA ascii\n0 0 0\n";
    try {
      read_cloud(p);
      FAIL() << types;
    } catch (const FileError& e) {
      EXPECT_NE(std::string(e.what()).find(expect), std::string::npos) << e.what();
    }
  }
  // a valid body with blank lines, nan and exponents still reads
  std::ofstream(dir / "ok.pcd") << head << "0 0 0\n\n1e-3 nan 2\n-1 1.5E2 3\n";
  EXPECT_EQ(read_cloud((dir / "ok.pcd").string()).width, 3u);
  std::filesystem::remove_all(dir);
}
