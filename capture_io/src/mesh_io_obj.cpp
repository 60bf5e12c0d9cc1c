#include "mesh_io_formats.h"

namespace tbsp::detail {

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

}  // namespace tbsp::detail
