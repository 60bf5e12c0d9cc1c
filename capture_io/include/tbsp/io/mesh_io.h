#pragma once
/// \file mesh_io.h
/// \brief Triangle-mesh files: PLY (ASCII, binary little/big endian; faces as lists or
/// `tristrips`; unknown elements such as `range_grid` skipped), OBJ (v/vn, polygon faces with
/// v, v/vt, v//vn, v/vt/vn and negative indices), OFF (OFF/COFF/NOFF/CNOFF, ASCII) and VTK
/// legacy POLYDATA (ASCII or BINARY; POLYGONS and TRIANGLE_STRIPS, point NORMALS).
/// Polygons are fan-triangulated.
///
/// Written by hand rather than through pcl::io::loadPolygonFile (VTK-based): that path gives no
/// line/item in its errors, accepts truncated files silently and cannot read PLY tristrips.
///
/// Every reader rejects malformed input with tbsp::FileError naming the file, the line (ASCII)
/// or element (binary), the item and the fix: truncated data, counts that exceed the file,
/// NaN/Inf coordinates, out-of-range or negative face indices, unknown formats.

#include <string>

#include "tbsp/mesh/tri_mesh.h"

namespace tbsp {

enum class MeshFormat { Auto, PLY, OBJ, OFF, VTK };

/// Format from the file extension (case-insensitive); throws FileError if unknown.
MeshFormat mesh_format_from_path(const std::string& path);

/// \brief Reads a triangle mesh. Normals (PLY nx/ny/nz, OBJ vn matched per vertex, VTK NORMALS)
/// and colours (PLY red/green/blue, OBJ `v x y z r g b`) fill TriMesh::N / TriMesh::C.
/// \throws FileError (see file doc).
TriMesh read_mesh(const std::string& path, MeshFormat format = MeshFormat::Auto);

struct MeshWriteOptions {
  bool binary = true;  ///< PLY: binary_little_endian (default) or ascii; VTK: always ASCII
  int precision = 17;  ///< significant digits for ASCII formats (17 = lossless double)
};

/// \brief Writes a mesh atomically (temp file + rename). Normals/colours are written where
/// the format supports them. \throws FileError.
void write_mesh(const std::string& path, const TriMesh& mesh, const MeshWriteOptions& options = {},
                MeshFormat format = MeshFormat::Auto);

/// \brief Writes a textured OBJ and its MTL (both atomically): `uv` holds one OBJ texture
/// coordinate per vertex (u right, v up, in [0,1]); rows with NaN have none, and faces touching
/// such a vertex are written untextured. The MTL names `texture_file` (relative to the MTL).
/// \throws FileError, InvalidInput when uv does not have one row per vertex.
void write_textured_obj(const std::string& path, const TriMesh& mesh, const Eigen::MatrixX2d& uv, const std::string& mtl_file,
                        const std::string& material, const std::string& texture_file);

}  // namespace tbsp
