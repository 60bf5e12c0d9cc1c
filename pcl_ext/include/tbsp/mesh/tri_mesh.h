#pragma once
/// \file tri_mesh.h
/// \brief tbsp::TriMesh, the triangle-mesh data model, and basic per-element geometry.

#include <Eigen/Core>

namespace tbsp {

/// \brief A triangle mesh: vertex positions and triangles as Eigen matrices (libigl layout).
///
/// - `V`  #V by 3 vertex positions (double, any unit; tbsp never assumes metres).
/// - `F`  #F by 3 vertex indices into V, 0-based, counter-clockwise = outward normal.
/// - `N`  optional #V by 3 per-vertex normals (empty when absent).
/// - `C`  optional #V by 3 per-vertex colours in [0,1] (empty when absent).
/// Plain data: no invariant is enforced on assignment; use validate_mesh() before trusting
/// a mesh from outside, and each algorithm states what it accepts.
struct TriMesh {
  Eigen::MatrixX3d V;
  Eigen::MatrixX3i F;
  Eigen::MatrixX3d N;
  Eigen::MatrixX3d C;

  Eigen::Index numVertices() const { return V.rows(); }
  Eigen::Index numFaces() const { return F.rows(); }
};

/// Length of the diagonal of the axis-aligned bounding box of V (0 for fewer than 2 vertices).
double bbox_diagonal(const Eigen::MatrixX3d& V);

/// #F by 3 unit face normals; zero rows for degenerate faces. O(#F).
Eigen::MatrixX3d face_normals(const Eigen::MatrixX3d& V, const Eigen::MatrixX3i& F);

/// #F triangle areas. O(#F).
Eigen::VectorXd face_areas(const Eigen::MatrixX3d& V, const Eigen::MatrixX3i& F);

/// #V by 3 unit vertex normals, angle-weighted average of incident face normals
/// (zero rows for isolated vertices or vertices with only degenerate faces). O(#F).
Eigen::MatrixX3d vertex_normals(const Eigen::MatrixX3d& V, const Eigen::MatrixX3i& F);

}  // namespace tbsp
