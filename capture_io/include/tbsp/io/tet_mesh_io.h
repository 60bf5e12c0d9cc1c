#pragma once
/// \file tet_mesh_io.h
/// \brief Tetrahedral meshes in the MEDIT .mesh format (ASCII; the format of libigl's and
/// TetGen's -g tet meshes, Gmsh/MMG interchange): `MeshVersionFormatted`, `Dimension 3`,
/// `Vertices`, `Tetrahedra` (1-based indices, a reference number per item). Other sections
/// (Triangles, Edges, Corners, Ridges, Normals, ...) are skipped by their documented item
/// sizes; an unknown keyword is an error (its item size is unknown).
///
/// Malformed input — missing Vertices/Tetrahedra, counts beyond the end of the file,
/// non-finite coordinates, indices outside 1..#V, Dimension other than 3 — gives a
/// tbsp::FileError naming the file, the line and the item.

#include <string>

#include "tbsp/mesh/tet_mesh.h"

namespace tbsp {

/// \brief Reads a MEDIT .mesh tetrahedral mesh. \throws FileError.
TetMesh read_tet_mesh(const std::string& path);

/// \brief Writes `mesh` as MEDIT .mesh (Vertices, Tetrahedra, and the boundary Triangles),
/// atomically. \throws FileError.
void write_tet_mesh(const std::string& path, const TetMesh& mesh);

}  // namespace tbsp
