#include "mesh_io_formats.h"

namespace tbsp::detail {

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

}  // namespace tbsp::detail
