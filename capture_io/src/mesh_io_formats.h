#pragma once
// Internal: what the mesh readers and writers of each format (mesh_io_FORMAT.cpp) share, and
// their entry points, dispatched by read_mesh / write_mesh (mesh_io.cpp).
#include <algorithm>
#include <array>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <sstream>
#include <string>
#include <string_view>
#include <vector>

#include "tbsp/core/error.h"
#include "tbsp/io/atomic_file.h"
#include "tbsp/io/mesh_io.h"
#include "text_buffer.h"

namespace tbsp::detail {

inline std::string lower(std::string s) {
  std::transform(s.begin(), s.end(), s.begin(), [](unsigned char c) { return char(std::tolower(c)); });
  return s;
}

inline std::vector<std::string> split(std::string_view line) {
  std::vector<std::string> out;
  std::size_t i = 0;
  while (i < line.size()) {
    while (i < line.size() && std::isspace(static_cast<unsigned char>(line[i]))) ++i;
    std::size_t b = i;
    while (i < line.size() && !std::isspace(static_cast<unsigned char>(line[i]))) ++i;
    if (i > b) out.emplace_back(line.substr(b, i - b));
  }
  return out;
}

// Collects vertices and triangles, validating as it goes.
struct MeshBuilder {
  std::vector<std::array<double, 3>> v, n, c;
  std::vector<std::array<int, 3>> f;

  void addVertex(const TextBuffer& buf, bool binary, double x, double y, double z) {
    if (!std::isfinite(x) || !std::isfinite(y) || !std::isfinite(z)) {
      const std::string msg = "vertex " + std::to_string(v.size()) + " has a non-finite coordinate (" +
                              std::to_string(x) + ", " + std::to_string(y) + ", " + std::to_string(z) +
                              "); fix or remove it in the source";
      binary ? buf.failBinary(msg) : buf.fail(msg);
    }
    v.push_back({x, y, z});
  }
  // polygon with 0-based indices, fan-triangulated; `nv` = number of vertices declared
  void addPolygon(const TextBuffer& buf, bool binary, const std::vector<long long>& idx, long long nv, std::size_t face_no) {
    auto bad = [&](const std::string& m) { binary ? buf.failBinary(m) : buf.fail(m); };
    if (idx.size() < 3) bad("face " + std::to_string(face_no) + " has " + std::to_string(idx.size()) + " vertices; at least 3 are needed");
    for (long long i : idx)
      if (i < 0 || i >= nv)
        bad("face " + std::to_string(face_no) + " references vertex " + std::to_string(i) + " but there are " +
            std::to_string(nv) + " vertices (valid: 0.." + std::to_string(nv - 1) + "); the face list does not match the vertex list");
    for (std::size_t k = 1; k + 1 < idx.size(); ++k) f.push_back({int(idx[0]), int(idx[k]), int(idx[k + 1])});
  }
  TriMesh build() const {
    TriMesh m;
    m.V.resize(Eigen::Index(v.size()), 3);
    for (std::size_t i = 0; i < v.size(); ++i) m.V.row(Eigen::Index(i)) << v[i][0], v[i][1], v[i][2];
    m.F.resize(Eigen::Index(f.size()), 3);
    for (std::size_t i = 0; i < f.size(); ++i) m.F.row(Eigen::Index(i)) << f[i][0], f[i][1], f[i][2];
    if (!n.empty() && n.size() == v.size()) {
      m.N.resize(m.V.rows(), 3);
      for (std::size_t i = 0; i < n.size(); ++i) m.N.row(Eigen::Index(i)) << n[i][0], n[i][1], n[i][2];
    }
    if (!c.empty() && c.size() == v.size()) {
      m.C.resize(m.V.rows(), 3);
      for (std::size_t i = 0; i < c.size(); ++i) m.C.row(Eigen::Index(i)) << c[i][0], c[i][1], c[i][2];
    }
    return m;
  }
};

TriMesh read_ply(TextBuffer& buf);
TriMesh read_obj(TextBuffer& buf);
TriMesh read_off(TextBuffer& buf);
TriMesh read_vtk(TextBuffer& buf);
void write_ply(AtomicFile& f, const TriMesh& m, const MeshWriteOptions& o);
void write_obj(AtomicFile& f, const TriMesh& m, const MeshWriteOptions& o);
void write_off(AtomicFile& f, const TriMesh& m, const MeshWriteOptions& o);
void write_vtk(AtomicFile& f, const TriMesh& m, const MeshWriteOptions& o);

}  // namespace tbsp::detail
