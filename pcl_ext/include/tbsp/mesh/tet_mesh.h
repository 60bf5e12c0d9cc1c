#pragma once
/// \file tet_mesh.h
/// \brief Tetrahedral meshes (thesis §2.1.1.3, ch. 7): storage, signed volumes, boundary
/// surface, validation, and the surface-to-tet construction of §10.8.
///
/// Orientation convention: a tetrahedron (a, b, c, d) is positive when
/// ((b − a) × (c − a)) · (d − a) > 0, i.e. d lies on the side that the face (a, b, c) (counter-
/// clockwise) faces. Boundary faces are returned counter-clockwise seen from outside.

#include <Eigen/Core>
#include <string>
#include <vector>

#include "tbsp/mesh/tri_mesh.h"

namespace tbsp {

/// \brief A tetrahedral mesh: #V by 3 vertex positions (any length unit) and #T by 4 vertex
/// indices. Plain data, like TriMesh.
struct TetMesh {
  Eigen::MatrixX3d V;
  Eigen::Matrix<int, Eigen::Dynamic, 4> T;

  Eigen::Index numVertices() const { return V.rows(); }
  Eigen::Index numTets() const { return T.rows(); }
};

/// Signed volume of each tetrahedron (positive when oriented as in the file doc). O(#T).
Eigen::VectorXd tet_signed_volumes(const Eigen::MatrixX3d& V, const Eigen::Matrix<int, Eigen::Dynamic, 4>& T);

/// Sum of the absolute tetrahedron volumes.
double tet_mesh_volume(const TetMesh& mesh);

/// \brief Swaps two vertices of every negatively oriented tetrahedron. \returns how many were flipped.
Eigen::Index orient_tets(TetMesh& mesh);

/// \brief Faces used by exactly one tetrahedron, oriented outward (for positively oriented
/// tets). O(#T log #T). \param T the tetrahedra (#T by 4). \param[out] face_tet optional: the tetrahedron owning each face.
Eigen::MatrixX3i tet_boundary_faces(const Eigen::Matrix<int, Eigen::Dynamic, 4>& T,
                                    std::vector<int>* face_tet = nullptr);

/// \brief The boundary surface as a TriMesh over the *same* vertex array (interior vertices
/// stay in V, unreferenced), so vertex i of the surface is vertex i of the tet mesh.
TriMesh tet_boundary_mesh(const TetMesh& mesh);

/// \brief The boundary surface with only the vertices it uses, positions taken from X (#V by 3,
/// e.g. deformed positions of the tet mesh). \param[out] vertex_map optional: for each tet-mesh
/// vertex its index in the surface, or −1 (interior).
/// \param X, T vertex positions (#V by 3) and tetrahedra (#T by 4).
TriMesh tet_boundary_surface(const Eigen::MatrixX3d& X, const Eigen::Matrix<int, Eigen::Dynamic, 4>& T,
                             std::vector<int>* vertex_map = nullptr);

/// \brief Tetrahedra sharing a face with each tetrahedron: #T by 4, entry k is the neighbour
/// across the face opposite vertex k, or −1 on the boundary. O(#T log #T).
Eigen::Matrix<int, Eigen::Dynamic, 4> tet_face_neighbours(const Eigen::Matrix<int, Eigen::Dynamic, 4>& T);

/// \brief Vertex-connected components of the tet mesh (label per vertex; unreferenced
/// vertices get their own label). \returns the number of components.
int tet_connected_components(const TetMesh& mesh, Eigen::VectorXi& labels);

/// \brief Checks a tet mesh for use by TetDeformer / DeformationTransfer and throws
/// InvalidInput naming the first offending items: empty mesh, non-finite coordinates,
/// indices out of range, repeated vertices in a tetrahedron, degenerate tetrahedra (|volume|
/// ≤ 1e-12 · mean |volume|). Negatively oriented tets are not an error (see orient_tets).
/// `who` prefixes the message.
void require_valid_tet_mesh(const TetMesh& mesh, const std::string& who);

/// \brief §10.8: turns a triangle surface (open or closed) into one tetrahedron per
/// triangle by adding a point offset from the triangle's centroid along its normal by
/// `offset` (length units; ≤ 0 means 0.5 × the mean edge length). The surface vertices keep
/// their indices (0..#V−1); the apex of face f is vertex #V + f. The tets are positively
/// oriented. Lets DeformationTransfer and TetDeformer run on surfaces that cannot be
/// tetrahedralized (open, non-manifold, self-intersecting). Degenerate (zero-area) faces get no
/// tetrahedron (their apex stays, unreferenced). \throws InvalidInput for an empty mesh or bad indices.
TetMesh surface_to_tets(const TriMesh& surface, double offset = 0.0);

}  // namespace tbsp
