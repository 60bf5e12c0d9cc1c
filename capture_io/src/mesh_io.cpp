#include "tbsp/io/mesh_io.h"

#include <algorithm>
#include <array>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <sstream>
#include <vector>

#include "tbsp/core/error.h"
#include "tbsp/io/atomic_file.h"
#include "text_buffer.h"

namespace tbsp {

using detail::TextBuffer;

namespace {

std::string lower(std::string s) {
  std::transform(s.begin(), s.end(), s.begin(), [](unsigned char c) { return char(std::tolower(c)); });
  return s;
}

std::vector<std::string> split(std::string_view line) {
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

// ------------------------------------------------------------------------------------- PLY
struct PlyProperty {
  std::string name, type;
  bool list = false;
  std::string count_type;
};
struct PlyElement {
  std::string name;
  long long count = 0;
  std::vector<PlyProperty> props;
};

TriMesh read_ply(TextBuffer& buf) {
  std::string_view line;
  if (!buf.nextLine(line) || line != "ply") buf.fail("not a PLY file: the first line must be 'ply' (wrong extension?)");
  std::string format;
  std::vector<PlyElement> elems;
  bool header_done = false;
  while (buf.nextLine(line)) {
    const auto t = split(line);
    if (t.empty()) continue;
    if (t[0] == "comment" || t[0] == "obj_info") continue;
    if (t[0] == "end_header") { header_done = true; break; }
    if (t[0] == "format") {
      if (t.size() < 2) buf.fail("'format' line without a format");
      format = t[1];
      if (format != "ascii" && format != "binary_little_endian" && format != "binary_big_endian")
        buf.fail("unknown PLY format '" + format + "' (expected ascii, binary_little_endian or binary_big_endian)");
    } else if (t[0] == "element") {
      long long cnt = 0;
      if (t.size() != 3 || !detail::parse_int(t[2], cnt) || cnt < 0)
        buf.fail("malformed element line '" + std::string(line) + "' (expected: element NAME COUNT)");
      elems.push_back({t[1], cnt, {}});
    } else if (t[0] == "property") {
      if (elems.empty()) buf.fail("property before any element");
      PlyProperty p;
      if (t.size() == 5 && t[1] == "list") {
        p.list = true; p.count_type = t[2]; p.type = t[3]; p.name = t[4];
        if (!TextBuffer::binarySize(p.count_type) || !TextBuffer::binarySize(p.type))
          buf.fail("unknown type in '" + std::string(line) + "'");
      } else if (t.size() == 3) {
        p.type = t[1]; p.name = t[2];
        if (!TextBuffer::binarySize(p.type)) buf.fail("unknown property type '" + p.type + "'");
      } else {
        buf.fail("malformed property line '" + std::string(line) + "'");
      }
      elems.back().props.push_back(p);
    } else {
      buf.fail("unexpected header line '" + std::string(line.substr(0, 60)) + "'");
    }
  }
  if (!header_done) buf.fail("the PLY header has no 'end_header' (truncated file?)");
  if (format.empty()) buf.fail("the PLY header has no 'format' line");
  const bool ascii = format == "ascii";
  const bool be = format == "binary_big_endian";
  // sanity: declared counts must fit in the data
  {
    std::size_t min_bytes = 0;
    for (const auto& e : elems) {
      std::size_t item = 0;
      for (const auto& p : e.props) item += ascii ? 2 : std::size_t(TextBuffer::binarySize(p.list ? p.count_type : p.type));
      if (item && e.count > 0 && (std::size_t(e.count) > buf.remaining() / item || min_bytes + std::size_t(e.count) * item > buf.remaining()))
        buf.fail("element '" + e.name + "' declares " + std::to_string(e.count) + " items but only " +
                 std::to_string(buf.remaining()) + " bytes of data follow the header (wrong count or truncated file)");
      min_bytes += std::size_t(e.count) * item;
    }
  }
  MeshBuilder mb;
  long long nv = -1;
  std::size_t face_no = 0;
  for (const auto& e : elems) {
    const bool is_vertex = e.name == "vertex";
    const bool is_face = e.name == "face";
    const bool is_strip = e.name == "tristrips";
    int ix = -1, iy = -1, iz = -1, inx = -1, iny = -1, inz = -1, ir = -1, ig = -1, ib = -1, iface = -1;
    for (int k = 0; k < int(e.props.size()); ++k) {
      const auto& n = e.props[std::size_t(k)].name;
      if (n == "x") ix = k; else if (n == "y") iy = k; else if (n == "z") iz = k;
      else if (n == "nx") inx = k; else if (n == "ny") iny = k; else if (n == "nz") inz = k;
      else if (n == "red") ir = k; else if (n == "green") ig = k; else if (n == "blue") ib = k;
      else if ((n == "vertex_indices" || n == "vertex_index") && e.props[std::size_t(k)].list) iface = k;
    }
    if (is_vertex) {
      if (ix < 0 || iy < 0 || iz < 0) buf.fail("the vertex element has no x/y/z properties");
      nv = e.count;
      mb.v.reserve(std::size_t(e.count));
    }
    if ((is_face || is_strip) && iface < 0) buf.fail("the " + e.name + " element has no vertex_indices list");
    if ((is_face || is_strip) && nv < 0) buf.fail("faces come before the vertex element");
    std::vector<double> scal(e.props.size());
    std::vector<long long> list;
    for (long long item = 0; item < e.count; ++item) {
      const std::string what = e.name + " " + std::to_string(item);
      for (std::size_t k = 0; k < e.props.size(); ++k) {
        const auto& p = e.props[k];
        if (!p.list) {
          scal[k] = ascii ? buf.readDouble(what + " property '" + p.name + "'") : buf.readBinary(p.type, be, what);
          continue;
        }
        long long cnt = 0;
        if (ascii) {
          cnt = buf.readInt(what + " list count");
        } else {
          const double c = buf.readBinary(p.count_type, be, what);
          if (!(std::isfinite(c) && c == std::floor(c) && std::abs(c) < 9e18))
            buf.failBinary(what + ": list count " + std::to_string(c) + " is not an integer (corrupt file)");
          cnt = (long long)c;
        }
        if (cnt < 0 || std::size_t(cnt) > buf.remaining())
          ascii ? buf.fail(what + ": list count " + std::to_string(cnt) + " is impossible (corrupt file)")
                : buf.failBinary(what + ": list count " + std::to_string(cnt) + " is impossible (corrupt file)");
        const bool keep = int(k) == iface && (is_face || is_strip);
        if (keep) list.clear();
        for (long long j = 0; j < cnt; ++j) {
          double v = ascii ? buf.readDouble(what + " list entry") : buf.readBinary(p.type, be, what);
          if (keep) {
            // a vertex index: an integer in range of long long (a cast of inf or 1e300 is UB)
            if (!(std::isfinite(v) && v == std::floor(v) && std::abs(v) < 9e18))
              ascii ? buf.fail(what + ": vertex index " + std::to_string(v) + " is not an integer (corrupt file)")
                    : buf.failBinary(what + ": vertex index " + std::to_string(v) + " is not an integer (corrupt file)");
            list.push_back((long long)v);
          }
        }
      }
      if (is_vertex) {
        mb.addVertex(buf, !ascii, scal[std::size_t(ix)], scal[std::size_t(iy)], scal[std::size_t(iz)]);
        if (inx >= 0 && iny >= 0 && inz >= 0) mb.n.push_back({scal[std::size_t(inx)], scal[std::size_t(iny)], scal[std::size_t(inz)]});
        if (ir >= 0 && ig >= 0 && ib >= 0) {
          const double s = e.props[std::size_t(ir)].type.find("float") != std::string::npos || e.props[std::size_t(ir)].type == "double" ? 1.0 : 255.0;
          mb.c.push_back({scal[std::size_t(ir)] / s, scal[std::size_t(ig)] / s, scal[std::size_t(ib)] / s});
        }
      } else if (is_face) {
        mb.addPolygon(buf, !ascii, list, nv, face_no++);
      } else if (is_strip) {
        // triangle strips, -1 restarts; orientation alternates
        std::size_t start = 0;
        for (std::size_t j = 0; j <= list.size(); ++j) {
          if (j < list.size() && list[j] >= 0) continue;
          for (std::size_t a = start; a + 2 < j; ++a) {
            std::vector<long long> tri = (a - start) % 2 == 0 ? std::vector<long long>{list[a], list[a + 1], list[a + 2]}
                                                              : std::vector<long long>{list[a + 1], list[a], list[a + 2]};
            if (tri[0] == tri[1] || tri[1] == tri[2] || tri[0] == tri[2]) continue;  // strip padding
            mb.addPolygon(buf, !ascii, tri, nv, face_no++);
          }
          start = j + 1;
        }
      }
    }
  }
  if (nv < 0) buf.fail("the PLY file has no vertex element");
  return mb.build();
}

// ------------------------------------------------------------------------------------- OBJ
TriMesh read_obj(TextBuffer& buf) {
  MeshBuilder mb;
  std::vector<std::array<double, 3>> vn;
  std::vector<std::array<double, 3>> colors;
  std::vector<std::array<double, 3>> vnormal;  // per vertex, from faces
  std::vector<char> has_normal;
  bool all_colored = true;
  std::vector<std::vector<std::string>> faces;  // deferred: indices may refer to later vertices
  std::vector<int> face_lines;
  std::string_view line;
  while (true) {
    const int lineno = buf.line();
    if (!buf.nextLine(line)) break;
    const auto t = split(line);
    if (t.empty() || t[0][0] == '#') continue;
    if (t[0] == "v") {
      if (t.size() < 4) buf.fail("vertex line needs x y z: '" + std::string(line.substr(0, 60)) + "'");
      double x, y, z;
      if (!detail::parse_double(t[1], x) || !detail::parse_double(t[2], y) || !detail::parse_double(t[3], z))
        throw FileError(buf.path() + ":" + std::to_string(lineno) + ": malformed vertex '" + std::string(line.substr(0, 60)) + "'");
      if (!std::isfinite(x) || !std::isfinite(y) || !std::isfinite(z))
        throw FileError(buf.path() + ":" + std::to_string(lineno) + ": vertex " + std::to_string(mb.v.size() + 1) +
                        " has a non-finite coordinate; fix or remove it in the source");
      mb.v.push_back({x, y, z});
      double r, g, b;
      if (t.size() >= 7 && detail::parse_double(t[4], r) && detail::parse_double(t[5], g) && detail::parse_double(t[6], b))
        colors.push_back({r, g, b});
      else
        all_colored = false;
    } else if (t[0] == "vn") {
      double x = 0, y = 0, z = 0;
      if (t.size() < 4 || !detail::parse_double(t[1], x) || !detail::parse_double(t[2], y) || !detail::parse_double(t[3], z))
        throw FileError(buf.path() + ":" + std::to_string(lineno) + ": malformed normal '" + std::string(line.substr(0, 60)) + "'");
      vn.push_back({x, y, z});
    } else if (t[0] == "f") {
      faces.push_back(t);
      face_lines.push_back(lineno);
    }
    // vt, g, o, s, usemtl, mtllib, l, p: not needed for the triangle mesh
  }
  const long long nv = (long long)mb.v.size();
  vnormal.assign(mb.v.size(), {0, 0, 0});
  has_normal.assign(mb.v.size(), 0);
  for (std::size_t fi = 0; fi < faces.size(); ++fi) {
    const auto& t = faces[fi];
    auto fail = [&](const std::string& m) { throw FileError(buf.path() + ":" + std::to_string(face_lines[fi]) + ": " + m); };
    std::vector<long long> idx;
    for (std::size_t k = 1; k < t.size(); ++k) {
      const std::string& s = t[k];
      const std::size_t sl = s.find('/');
      long long vi;
      if (!detail::parse_int(std::string_view(s).substr(0, sl), vi) || vi == 0)
        fail("malformed face index '" + s + "' (OBJ indices are 1-based: v, v/vt, v//vn or v/vt/vn)");
      const long long v0 = vi > 0 ? vi - 1 : nv + vi;
      if (v0 < 0 || v0 >= nv)
        fail("face " + std::to_string(fi) + " references vertex " + std::to_string(vi) + " but the file has " +
             std::to_string(nv) + " vertices");
      idx.push_back(v0);
      if (sl != std::string::npos) {
        const std::size_t sl2 = s.find('/', sl + 1);
        if (sl2 != std::string::npos && sl2 + 1 < s.size()) {
          long long ni;
          if (!detail::parse_int(std::string_view(s).substr(sl2 + 1), ni) || ni == 0) fail("malformed normal index in '" + s + "'");
          const long long n0 = ni > 0 ? ni - 1 : (long long)vn.size() + ni;
          if (n0 < 0 || n0 >= (long long)vn.size())
            fail("face " + std::to_string(fi) + " references normal " + std::to_string(ni) + " but the file has " +
                 std::to_string(vn.size()) + " normals");
          vnormal[std::size_t(v0)] = vn[std::size_t(n0)];
          has_normal[std::size_t(v0)] = 1;
        }
      }
    }
    mb.addPolygon(buf, false, idx, nv, fi);
  }
  if (mb.v.empty()) buf.fail("no vertices ('v' lines) found; is this an OBJ file?");
  if (!vn.empty() && std::all_of(has_normal.begin(), has_normal.end(), [](char c) { return c != 0; })) mb.n = vnormal;
  if (all_colored && !colors.empty()) mb.c = colors;
  return mb.build();
}

// ------------------------------------------------------------------------------------- OFF
TriMesh read_off(TextBuffer& buf) {
  std::string_view line;
  auto next_content = [&](std::vector<std::string>& t) {
    while (buf.nextLine(line)) {
      const std::size_t h = line.find('#');
      t = split(h == std::string_view::npos ? line : line.substr(0, h));
      if (!t.empty()) return true;
    }
    return false;
  };
  std::vector<std::string> t;
  if (!next_content(t)) buf.fail("empty file");
  std::string kw = t[0];
  if (kw.size() < 3 || kw.substr(kw.size() - 3) != "OFF")
    buf.fail("not an OFF file: the header must be OFF, COFF, NOFF or CNOFF (found '" + kw.substr(0, 20) + "')");
  const bool has_color = kw.find('C') != std::string::npos;
  const bool has_normal = kw.find('N') != std::string::npos && kw.find("NOFF") != std::string::npos;
  if (kw.find('4') != std::string::npos || kw.find('n') != std::string::npos)
    buf.fail("4D/nD OFF variants are not supported; convert to 3D OFF");
  t.erase(t.begin());
  if (!t.empty() && t[0] == "BINARY") buf.fail("binary OFF is not supported; save as ASCII OFF, PLY or OBJ");
  if (t.empty() && !next_content(t)) buf.fail("missing the 'vertices faces edges' count line");
  long long nv, nf;
  if (t.size() < 2 || !detail::parse_int(t[0], nv) || !detail::parse_int(t[1], nf) || nv < 0 || nf < 0)
    buf.fail("malformed count line (expected: NUM_VERTICES NUM_FACES NUM_EDGES)");
  if (std::size_t(nv) > buf.remaining() / 6 + 1 || std::size_t(nf) > buf.remaining() / 6 + 1)
    buf.fail("declares " + std::to_string(nv) + " vertices and " + std::to_string(nf) + " faces but only " +
             std::to_string(buf.remaining()) + " bytes follow (wrong counts or truncated file)");
  MeshBuilder mb;
  mb.v.reserve(std::size_t(nv));
  for (long long i = 0; i < nv; ++i) {
    if (!next_content(t))
      buf.fail("unexpected end of file: read " + std::to_string(i) + " of " + std::to_string(nv) +
               " vertices (the file is truncated or the count is wrong)");
    double x, y, z;
    if (t.size() < 3 || !detail::parse_double(t[0], x) || !detail::parse_double(t[1], y) || !detail::parse_double(t[2], z))
      buf.fail("vertex " + std::to_string(i) + ": expected x y z, found '" + std::string(line.substr(0, 60)) + "'");
    mb.addVertex(buf, false, x, y, z);
    std::size_t at = 3;
    if (has_normal && t.size() >= 6) {
      double a, b, c;
      if (detail::parse_double(t[3], a) && detail::parse_double(t[4], b) && detail::parse_double(t[5], c)) mb.n.push_back({a, b, c});
      at = 6;
    }
    if (has_color && t.size() >= at + 3) {
      double r, g, b;
      if (detail::parse_double(t[at], r) && detail::parse_double(t[at + 1], g) && detail::parse_double(t[at + 2], b)) {
        const double s = (r > 1 || g > 1 || b > 1) ? 255.0 : 1.0;
        mb.c.push_back({r / s, g / s, b / s});
      }
    }
  }
  for (long long i = 0; i < nf; ++i) {
    if (!next_content(t))
      buf.fail("unexpected end of file: read " + std::to_string(i) + " of " + std::to_string(nf) +
               " faces (the file is truncated or the count is wrong)");
    long long k;
    if (!detail::parse_int(t[0], k) || k < 0 || std::size_t(k) + 1 > t.size())
      buf.fail("face " + std::to_string(i) + ": malformed line '" + std::string(line.substr(0, 60)) + "' (expected: K i1 .. iK)");
    std::vector<long long> idx(static_cast<std::size_t>(k));
    for (long long j = 0; j < k; ++j)
      if (!detail::parse_int(t[std::size_t(j + 1)], idx[std::size_t(j)]))
        buf.fail("face " + std::to_string(i) + ": index '" + t[std::size_t(j + 1)] + "' is not an integer");
    mb.addPolygon(buf, false, idx, nv, std::size_t(i));
  }
  return mb.build();
}

// ------------------------------------------------------------------------------------- VTK
TriMesh read_vtk(TextBuffer& buf) {
  std::string_view line;
  if (!buf.nextLine(line) || line.rfind("# vtk DataFile", 0) != 0)
    buf.fail("not a VTK legacy file: the first line must start with '# vtk DataFile'");
  if (!buf.nextLine(line)) buf.fail("truncated header (missing title line)");
  if (!buf.nextLine(line)) buf.fail("truncated header (missing ASCII/BINARY line)");
  const std::string enc = split(line).empty() ? "" : split(line)[0];
  if (enc != "ASCII" && enc != "BINARY") buf.fail("third line must be ASCII or BINARY (found '" + std::string(line.substr(0, 20)) + "')");
  const bool binary = enc == "BINARY";
  std::string_view tok;
  if (!buf.token(tok) || tok != "DATASET" || !buf.token(tok) || tok != "POLYDATA")
    buf.fail("only 'DATASET POLYDATA' is supported (unstructured grids etc. are not surface meshes)");
  MeshBuilder mb;
  long long nv = -1;
  std::size_t face_no = 0;
  while (buf.token(tok)) {
    const std::string kw(tok);
    if (kw == "POINTS") {
      nv = buf.readInt("POINTS count");
      std::string_view type;
      if (!buf.token(type)) buf.fail("POINTS without a data type");
      const std::string ty(type);
      if (nv < 0 || std::size_t(nv) > buf.remaining() / (binary ? std::size_t(std::max(TextBuffer::binarySize(ty), 1)) * 3 : 2))
        buf.fail("POINTS declares " + std::to_string(nv) + " points but the file is too short (wrong count or truncated)");
      if (binary) buf.skipToNextLine();
      for (long long i = 0; i < nv; ++i) {
        double x, y, z;
        if (binary) {
          x = buf.readBinary(ty, true, "point " + std::to_string(i));
          y = buf.readBinary(ty, true, "point " + std::to_string(i));
          z = buf.readBinary(ty, true, "point " + std::to_string(i));
        } else {
          x = buf.readDouble("point " + std::to_string(i));
          y = buf.readDouble("point " + std::to_string(i));
          z = buf.readDouble("point " + std::to_string(i));
        }
        mb.addVertex(buf, binary, x, y, z);
      }
    } else if (kw == "VERTICES" || kw == "LINES" || kw == "POLYGONS" || kw == "TRIANGLE_STRIPS") {
      const long long ncell = buf.readInt(kw + " cell count");
      const long long size = buf.readInt(kw + " size");
      if (ncell < 0 || size < 0 || std::size_t(size) > buf.remaining() / (binary ? 4 : 2) + 1)
        buf.fail(kw + " declares " + std::to_string(size) + " values but the file is too short (wrong count or truncated)");
      if (binary) buf.skipToNextLine();
      if (nv < 0) buf.fail(kw + " before POINTS");
      long long consumed = 0;
      std::vector<long long> idx;
      for (long long c = 0; c < ncell; ++c) {
        const std::string what = kw + " cell " + std::to_string(c);
        const long long k = binary ? (long long)buf.readBinary("int", true, what) : buf.readInt(what);
        if (k < 0 || consumed + k + 1 > size) buf.fail(what + ": vertex count " + std::to_string(k) + " exceeds the declared size");
        idx.resize(std::size_t(k));
        for (long long j = 0; j < k; ++j) idx[std::size_t(j)] = binary ? (long long)buf.readBinary("int", true, what) : buf.readInt(what);
        consumed += k + 1;
        if (kw == "POLYGONS") mb.addPolygon(buf, binary, idx, nv, face_no++);
        else if (kw == "TRIANGLE_STRIPS")
          for (std::size_t a = 0; a + 2 < idx.size(); ++a) {
            std::vector<long long> tri = a % 2 == 0 ? std::vector<long long>{idx[a], idx[a + 1], idx[a + 2]}
                                                    : std::vector<long long>{idx[a + 1], idx[a], idx[a + 2]};
            mb.addPolygon(buf, binary, tri, nv, face_no++);
          }
      }
      if (consumed != size) buf.fail(kw + ": cells hold " + std::to_string(consumed) + " values but " + std::to_string(size) + " were declared");
    } else if (kw == "OFFSETS" || kw == "CONNECTIVITY") {
      buf.fail("the VTK 5.1 OFFSETS/CONNECTIVITY cell layout is not supported; save as legacy format 4.2");
    } else if (kw == "POINT_DATA") {
      const long long n = buf.readInt("POINT_DATA count");
      std::string_view at;
      if (buf.token(at) && at == "NORMALS") {
        std::string_view name, type;
        if (!buf.token(name) || !buf.token(type)) buf.fail("malformed NORMALS line");
        if (binary) buf.skipToNextLine();
        for (long long i = 0; i < n; ++i) {
          std::array<double, 3> v{};
          for (int d = 0; d < 3; ++d)
            v[std::size_t(d)] = binary ? buf.readBinary(std::string(type), true, "normal " + std::to_string(i))
                                       : buf.readDouble("normal " + std::to_string(i));
          mb.n.push_back(v);
        }
      }
      break;  // other attributes are not needed for the mesh
    } else if (kw == "CELL_DATA" || kw == "FIELD" || kw == "METADATA") {
      break;
    } else {
      buf.fail("unexpected keyword '" + kw.substr(0, 30) + "' in POLYDATA");
    }
  }
  if (nv < 0) buf.fail("no POINTS section");
  return mb.build();
}

// ----------------------------------------------------------------------------------- writers
void write_ply(AtomicFile& f, const TriMesh& m, const MeshWriteOptions& o) {
  auto& s = f.stream();
  const bool nrm = m.N.rows() == m.V.rows() && m.V.rows() > 0;
  const bool col = m.C.rows() == m.V.rows() && m.V.rows() > 0;
  s << "ply\nformat " << (o.binary ? "binary_little_endian" : "ascii") << " 1.0\ncomment written by tbsp\n";
  s << "element vertex " << m.V.rows() << "\nproperty double x\nproperty double y\nproperty double z\n";
  if (nrm) s << "property float nx\nproperty float ny\nproperty float nz\n";
  if (col) s << "property uchar red\nproperty uchar green\nproperty uchar blue\n";
  s << "element face " << m.F.rows() << "\nproperty list uchar int vertex_indices\nend_header\n";
  auto c8 = [](double v) { return std::uint8_t(std::lround(std::clamp(v, 0.0, 1.0) * 255.0)); };
  if (o.binary) {
    for (Eigen::Index i = 0; i < m.V.rows(); ++i) {
      const double p[3] = {m.V(i, 0), m.V(i, 1), m.V(i, 2)};
      s.write(reinterpret_cast<const char*>(p), sizeof p);
      if (nrm) { const float n[3] = {float(m.N(i, 0)), float(m.N(i, 1)), float(m.N(i, 2))}; s.write(reinterpret_cast<const char*>(n), sizeof n); }
      if (col) { const std::uint8_t c[3] = {c8(m.C(i, 0)), c8(m.C(i, 1)), c8(m.C(i, 2))}; s.write(reinterpret_cast<const char*>(c), 3); }
    }
    for (Eigen::Index i = 0; i < m.F.rows(); ++i) {
      const std::uint8_t k = 3;
      const std::int32_t idx[3] = {m.F(i, 0), m.F(i, 1), m.F(i, 2)};
      s.write(reinterpret_cast<const char*>(&k), 1);
      s.write(reinterpret_cast<const char*>(idx), sizeof idx);
    }
  } else {
    s.precision(o.precision);
    for (Eigen::Index i = 0; i < m.V.rows(); ++i) {
      s << m.V(i, 0) << ' ' << m.V(i, 1) << ' ' << m.V(i, 2);
      if (nrm) s << ' ' << float(m.N(i, 0)) << ' ' << float(m.N(i, 1)) << ' ' << float(m.N(i, 2));
      if (col) s << ' ' << int(c8(m.C(i, 0))) << ' ' << int(c8(m.C(i, 1))) << ' ' << int(c8(m.C(i, 2)));
      s << '\n';
    }
    for (Eigen::Index i = 0; i < m.F.rows(); ++i) s << "3 " << m.F(i, 0) << ' ' << m.F(i, 1) << ' ' << m.F(i, 2) << '\n';
  }
}

void write_obj(AtomicFile& f, const TriMesh& m, const MeshWriteOptions& o) {
  auto& s = f.stream();
  s.precision(o.precision);
  const bool nrm = m.N.rows() == m.V.rows() && m.V.rows() > 0;
  const bool col = m.C.rows() == m.V.rows() && m.V.rows() > 0;
  s << "# written by tbsp\n";
  for (Eigen::Index i = 0; i < m.V.rows(); ++i) {
    s << "v " << m.V(i, 0) << ' ' << m.V(i, 1) << ' ' << m.V(i, 2);
    if (col) s << ' ' << m.C(i, 0) << ' ' << m.C(i, 1) << ' ' << m.C(i, 2);
    s << '\n';
  }
  if (nrm)
    for (Eigen::Index i = 0; i < m.N.rows(); ++i) s << "vn " << m.N(i, 0) << ' ' << m.N(i, 1) << ' ' << m.N(i, 2) << '\n';
  for (Eigen::Index i = 0; i < m.F.rows(); ++i) {
    s << 'f';
    for (int k = 0; k < 3; ++k) {
      s << ' ' << m.F(i, k) + 1;
      if (nrm) s << "//" << m.F(i, k) + 1;
    }
    s << '\n';
  }
}

void write_off(AtomicFile& f, const TriMesh& m, const MeshWriteOptions& o) {
  auto& s = f.stream();
  s.precision(o.precision);
  s << "OFF\n" << m.V.rows() << ' ' << m.F.rows() << " 0\n";
  for (Eigen::Index i = 0; i < m.V.rows(); ++i) s << m.V(i, 0) << ' ' << m.V(i, 1) << ' ' << m.V(i, 2) << '\n';
  for (Eigen::Index i = 0; i < m.F.rows(); ++i) s << "3 " << m.F(i, 0) << ' ' << m.F(i, 1) << ' ' << m.F(i, 2) << '\n';
}

void write_vtk(AtomicFile& f, const TriMesh& m, const MeshWriteOptions& o) {
  auto& s = f.stream();
  s.precision(o.precision);
  s << "# vtk DataFile Version 3.0\ntbsp mesh\nASCII\nDATASET POLYDATA\nPOINTS " << m.V.rows() << " double\n";
  for (Eigen::Index i = 0; i < m.V.rows(); ++i) s << m.V(i, 0) << ' ' << m.V(i, 1) << ' ' << m.V(i, 2) << '\n';
  s << "POLYGONS " << m.F.rows() << ' ' << 4 * m.F.rows() << '\n';
  for (Eigen::Index i = 0; i < m.F.rows(); ++i) s << "3 " << m.F(i, 0) << ' ' << m.F(i, 1) << ' ' << m.F(i, 2) << '\n';
  if (m.N.rows() == m.V.rows() && m.V.rows() > 0) {
    s << "POINT_DATA " << m.V.rows() << "\nNORMALS normals double\n";
    for (Eigen::Index i = 0; i < m.N.rows(); ++i) s << m.N(i, 0) << ' ' << m.N(i, 1) << ' ' << m.N(i, 2) << '\n';
  }
}

}  // namespace

MeshFormat mesh_format_from_path(const std::string& path) {
  const auto dot = path.find_last_of('.');
  const std::string ext = dot == std::string::npos ? "" : lower(path.substr(dot + 1));
  if (ext == "ply") return MeshFormat::PLY;
  if (ext == "obj") return MeshFormat::OBJ;
  if (ext == "off") return MeshFormat::OFF;
  if (ext == "vtk") return MeshFormat::VTK;
  throw FileError("'" + path + "': unknown mesh format '." + ext + "'; use .ply, .obj, .off or .vtk");
}

TriMesh read_mesh(const std::string& path, MeshFormat format) {
  if (format == MeshFormat::Auto) format = mesh_format_from_path(path);
  TextBuffer buf = TextBuffer::load(path);
  if (buf.remaining() == 0) throw FileError("'" + path + "': the file is empty");
  switch (format) {
    case MeshFormat::PLY: return read_ply(buf);
    case MeshFormat::OBJ: return read_obj(buf);
    case MeshFormat::OFF: return read_off(buf);
    case MeshFormat::VTK: return read_vtk(buf);
    default: break;
  }
  throw FileError("'" + path + "': unknown mesh format");
}

void write_mesh(const std::string& path, const TriMesh& mesh, const MeshWriteOptions& options, MeshFormat format) {
  if (format == MeshFormat::Auto) format = mesh_format_from_path(path);
  if (mesh.F.rows() > 0 && (mesh.F.minCoeff() < 0 || mesh.F.maxCoeff() >= mesh.V.rows()))
    throw FileError("cannot write '" + path + "': the mesh has face indices outside 0.." + std::to_string(mesh.V.rows() - 1));
  AtomicFile f(path, format == MeshFormat::PLY && options.binary);
  switch (format) {
    case MeshFormat::PLY: write_ply(f, mesh, options); break;
    case MeshFormat::OBJ: write_obj(f, mesh, options); break;
    case MeshFormat::OFF: write_off(f, mesh, options); break;
    case MeshFormat::VTK: write_vtk(f, mesh, options); break;
    default: throw FileError("cannot write '" + path + "': unknown format");
  }
  f.commit();
}

void write_textured_obj(const std::string& path, const TriMesh& mesh, const Eigen::MatrixX2d& uv, const std::string& mtl_file,
                        const std::string& material, const std::string& texture_file) {
  if (uv.rows() != mesh.V.rows())
    throw InvalidInput("write_textured_obj('" + path + "'): " + std::to_string(uv.rows()) + " texture coordinates for " +
                       std::to_string(mesh.V.rows()) + " vertices");
  {
    AtomicFile mtl(mtl_file);
    mtl.stream() << "# tbsp inverse texture mapping\nnewmtl " << material << "\nKa 1 1 1\nKd 1 1 1\nKs 0 0 0\nillum 1\nmap_Kd "
                 << texture_file << "\n";
    mtl.commit();
  }
  AtomicFile out(path);
  std::ostream& os = out.stream();
  char buf[128];
  std::string mtl_name = mtl_file;
  const auto slash = mtl_name.find_last_of("/\\");
  if (slash != std::string::npos) mtl_name = mtl_name.substr(slash + 1);
  os << "# tbsp inverse texture mapping: " << mesh.V.rows() << " vertices, " << mesh.F.rows() << " faces\nmtllib " << mtl_name
     << "\nusemtl " << material << "\n";
  for (Eigen::Index i = 0; i < mesh.V.rows(); ++i) {
    std::snprintf(buf, sizeof buf, "v %.9g %.9g %.9g\n", mesh.V(i, 0), mesh.V(i, 1), mesh.V(i, 2));
    os << buf;
  }
  std::vector<long> vt(static_cast<std::size_t>(uv.rows()), 0);
  long next = 1;
  for (Eigen::Index i = 0; i < uv.rows(); ++i) {
    if (!uv.row(i).allFinite()) continue;
    std::snprintf(buf, sizeof buf, "vt %.9g %.9g\n", uv(i, 0), uv(i, 1));
    os << buf;
    vt[static_cast<std::size_t>(i)] = next++;
  }
  for (Eigen::Index f = 0; f < mesh.F.rows(); ++f) {
    const long a = vt[mesh.F(f, 0)], b = vt[mesh.F(f, 1)], c = vt[mesh.F(f, 2)];
    if (a && b && c)
      os << "f " << mesh.F(f, 0) + 1 << '/' << a << ' ' << mesh.F(f, 1) + 1 << '/' << b << ' ' << mesh.F(f, 2) + 1 << '/' << c << '\n';
    else
      os << "f " << mesh.F(f, 0) + 1 << ' ' << mesh.F(f, 1) + 1 << ' ' << mesh.F(f, 2) + 1 << '\n';
  }
  out.commit();
}

}  // namespace tbsp
