#include "tbsp/io/tet_mesh_io.h"

#include <cmath>
#include <iomanip>
#include <map>
#include <sstream>

#include "tbsp/core/error.h"
#include "tbsp/io/atomic_file.h"
#include "text_buffer.h"

namespace tbsp {

namespace {
// Numbers per item of the MEDIT sections we skip (3D).
const std::map<std::string, int>& skipped_sections() {
  static const std::map<std::string, int> m = {
      {"Edges", 3},          {"Triangles", 4},         {"Quadrilaterals", 5},  {"Hexahedra", 9},
      {"Prisms", 7},         {"Corners", 1},           {"Ridges", 1},          {"RequiredVertices", 1},
      {"RequiredEdges", 1},  {"RequiredTriangles", 1}, {"Normals", 3},         {"NormalAtVertices", 2},
      {"Tangents", 3},       {"TangentAtVertices", 2}, {"TangentAtEdges", 3},  {"Identifier", 0}};
  return m;
}
}  // namespace

TetMesh read_tet_mesh(const std::string& path) {
  auto tb = detail::TextBuffer::load(path);
  TetMesh out;
  bool have_v = false, have_t = false;
  std::string_view tok;
  while (tb.token(tok, true)) {
    const std::string key(tok);
    if (key == "End") break;
    if (key == "MeshVersionFormatted") {
      tb.readInt("the version after MeshVersionFormatted", true);
      continue;
    }
    if (key == "Dimension") {
      const long long d = tb.readInt("the dimension after Dimension", true);
      if (d != 3) tb.fail("Dimension " + std::to_string(d) + " is not supported; tetrahedral meshes are 3D");
      continue;
    }
    const int line = tb.line();
    const long long n = tb.readInt("the item count of section " + key, true);
    const long long budget = static_cast<long long>(tb.remaining() / 2) + 1;  // every item needs >= 2 bytes
    if (n < 0 || n > budget)
      tb.fail("section " + key + " declares " + std::to_string(n) + " items, more than the file can hold (truncated?)");
    if (key == "Vertices") {
      out.V.resize(n, 3);
      for (long long i = 0; i < n; ++i) {
        for (int k = 0; k < 3; ++k) {
          const double v = tb.readDouble("coordinate " + std::to_string(k) + " of vertex " + std::to_string(i + 1) + " of " +
                                             std::to_string(n) + " (section Vertices at line " + std::to_string(line) + ")",
                                         true);
          if (!std::isfinite(v)) tb.fail("vertex " + std::to_string(i + 1) + " has a non-finite coordinate");
          out.V(i, k) = v;
        }
        tb.readInt("the reference number of vertex " + std::to_string(i + 1), true);
      }
      have_v = true;
    } else if (key == "Tetrahedra") {
      out.T.resize(n, 4);
      for (long long i = 0; i < n; ++i) {
        for (int k = 0; k < 4; ++k) {
          const long long v = tb.readInt("vertex " + std::to_string(k + 1) + " of tetrahedron " + std::to_string(i + 1) + " of " +
                                             std::to_string(n),
                                         true);
          if (!have_v || v < 1 || v > out.V.rows())
            tb.fail("tetrahedron " + std::to_string(i + 1) + " refers to vertex " + std::to_string(v) + ", but " +
                    (have_v ? "the file has " + std::to_string(out.V.rows()) + " vertices (1-based)" : "no Vertices section precedes it"));
          out.T(i, k) = int(v - 1);
        }
        tb.readInt("the reference number of tetrahedron " + std::to_string(i + 1), true);
      }
      have_t = true;
    } else {
      const auto it = skipped_sections().find(key);
      if (it == skipped_sections().end())
        tb.fail("unknown section '" + key + "'; expected Vertices, Tetrahedra or another MEDIT keyword");
      for (long long i = 0; i < n * it->second; ++i) tb.readDouble("item " + std::to_string(i / std::max(1, it->second) + 1) + " of section " + key, true);
    }
  }
  if (!have_v) throw FileError(path + ": no Vertices section; is this a MEDIT .mesh file?");
  if (!have_t || out.T.rows() == 0)
    throw FileError(path + ": no Tetrahedra; this .mesh holds a surface only — read it as a triangle mesh or tetrahedralize it");
  return out;
}

void write_tet_mesh(const std::string& path, const TetMesh& mesh) {
  std::ostringstream os;
  os << std::setprecision(17);
  os << "MeshVersionFormatted 1\nDimension 3\nVertices\n" << mesh.V.rows() << "\n";
  for (Eigen::Index i = 0; i < mesh.V.rows(); ++i) os << mesh.V(i, 0) << ' ' << mesh.V(i, 1) << ' ' << mesh.V(i, 2) << " 0\n";
  const Eigen::MatrixX3i B = tet_boundary_faces(mesh.T);
  os << "Triangles\n" << B.rows() << "\n";
  for (Eigen::Index f = 0; f < B.rows(); ++f) os << B(f, 0) + 1 << ' ' << B(f, 1) + 1 << ' ' << B(f, 2) + 1 << " 0\n";
  os << "Tetrahedra\n" << mesh.T.rows() << "\n";
  for (Eigen::Index t = 0; t < mesh.T.rows(); ++t)
    os << mesh.T(t, 0) + 1 << ' ' << mesh.T(t, 1) + 1 << ' ' << mesh.T(t, 2) + 1 << ' ' << mesh.T(t, 3) + 1 << " 0\n";
  os << "End\n";
  write_text_file_atomic(path, os.str());
}

}  // namespace tbsp
