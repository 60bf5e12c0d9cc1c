#pragma once
/// \file pcl_conversions.h
/// \brief TriMesh <-> pcl::PolygonMesh.

#include <pcl/PolygonMesh.h>

#include "tbsp/mesh/tri_mesh.h"

namespace tbsp {

/// \brief Converts a TriMesh to a pcl::PolygonMesh (cloud fields x,y,z, plus normal_x.. when
/// mesh.N is set and rgb when mesh.C is set). Coordinates are stored as float (PCL's types).
pcl::PolygonMesh to_pcl(const TriMesh& mesh);

/// \brief Converts a pcl::PolygonMesh to a TriMesh. Polygons with more than 3 vertices are
/// fan-triangulated. Normals and colours are carried over when the cloud has them.
/// \throws InvalidInput if the cloud lacks x/y/z, a polygon has fewer than 3 vertices or an
/// index is out of range (the message names the polygon).
TriMesh from_pcl(const pcl::PolygonMesh& mesh);

}  // namespace tbsp
