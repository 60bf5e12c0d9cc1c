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
#include "mesh_io_formats.h"
#include "text_buffer.h"

namespace tbsp {

using detail::TextBuffer;
using namespace detail;  // the per-format readers and writers (mesh_io_FORMAT.cpp)

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
