#include "mesh_io_formats.h"

namespace tbsp::detail {

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
    // An empty face element without properties (PCL's PLYWriter writes "element face 0") is fine.
    if ((is_face || is_strip) && iface < 0 && e.count > 0) buf.fail("the " + e.name + " element has no vertex_indices list");
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

}  // namespace tbsp::detail
