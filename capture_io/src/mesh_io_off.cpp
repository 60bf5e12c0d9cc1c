#include "mesh_io_formats.h"

namespace tbsp::detail {

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

void write_off(AtomicFile& f, const TriMesh& m, const MeshWriteOptions& o) {
  auto& s = f.stream();
  s.precision(o.precision);
  s << "OFF\n" << m.V.rows() << ' ' << m.F.rows() << " 0\n";
  for (Eigen::Index i = 0; i < m.V.rows(); ++i) s << m.V(i, 0) << ' ' << m.V(i, 1) << ' ' << m.V(i, 2) << '\n';
  for (Eigen::Index i = 0; i < m.F.rows(); ++i) s << "3 " << m.F(i, 0) << ' ' << m.F(i, 1) << ' ' << m.F(i, 2) << '\n';
}

}  // namespace tbsp::detail
