#pragma once
/// \file tetrahedralize.h
/// \brief Surface → tetrahedral mesh: quadric-error decimation (CGAL
/// Surface_mesh_simplification, Garland–Heckbert plane quadrics) and face-constrained
/// Delaunay tetrahedralization with quality bounds (TetGen), thesis §7.3 / §8.1.
///
/// Debian ships TetGen 1.5 as the `tetgen` program, not a library, so tetrahedralize() writes
/// the surface as a .smesh file into a fresh temporary directory, runs the program, reads the
/// .node/.ele result and removes the directory. TetGen's own error lines are quoted in the
/// exception when it fails (e.g. self-intersecting facets).

#include <string>

#include "tbsp/core/progress.h"
#include "tbsp/mesh/tet_mesh.h"
#include "tbsp/mesh/tri_mesh.h"

namespace tbsp {

/// \brief Garland–Heckbert edge-collapse decimation of a manifold triangle mesh to at most
/// `target_faces` faces (CGAL, bounded-normal-change placement so no face flips). Returns
/// the input unchanged when it already has ≤ target_faces faces.
/// O(#F log #F). \throws InvalidInput for non-manifold, empty or degenerate input, or
/// target_faces < 4.
/// \param mesh the closed or open manifold triangle mesh to simplify.
/// \param target_faces the largest face count of the result (≥ 4).
/// \param progress called with the fraction of the collapses done (stage "decimate"); returning
/// false cancels (tbsp::Cancelled; the input is untouched, nothing is returned).
TriMesh decimate_mesh(const TriMesh& mesh, Eigen::Index target_faces, const ProgressCallback& progress = {});

struct TetgenOptions {
  /// Radius-edge ratio bound (TetGen -q); ≤ 0 disables quality refinement.
  double max_radius_edge_ratio = 1.5;
  /// Minimum dihedral angle in degrees (TetGen -q ratio/angle); 0 keeps TetGen's default.
  double min_dihedral_deg = 10.0;
  /// Maximum tetrahedron volume (TetGen -a), ≤ 0 for none. Smaller → more tets.
  double max_volume = 0.0;
  /// Keep the surface triangulation (TetGen -Y): no Steiner points on the boundary, so the
  /// first #V vertices of the result are the input vertices and the boundary faces are the
  /// input faces. Default on.
  bool preserve_surface = true;
  /// Program to run ("tetgen" from $PATH by default).
  std::string tetgen_program = "tetgen";
  /// Progress (stages "decimate", "tetgen": before and after the program runs; TetGen itself
  /// reports nothing); returning false cancels (tbsp::Cancelled).
  ProgressCallback progress;
};

/// \brief Face-constrained Delaunay tetrahedralization of a closed, manifold, consistently
/// oriented triangle surface (any number of components). The result's tets are positively
/// oriented; with preserve_surface its first #V vertices equal the input vertices.
/// \throws InvalidInput naming the problem when the surface is open (boundary edges),
/// non-manifold, inconsistently oriented or has degenerate faces — checked before TetGen runs —
/// and Error with TetGen's own message when TetGen rejects it (self-intersections) or cannot be run.
TetMesh tetrahedralize(const TriMesh& surface, const TetgenOptions& options = {});

/// \brief Decimate to about `target_tets` tetrahedra and tetrahedralize: the surface is
/// decimated to target_tets / 2.2 faces (the tets-per-surface-face ratio TetGen gives with the
/// default quality bounds); when the result misses the target by more than 30 % the face
/// target is corrected once and the surface re-decimated. Non-positive target: no decimation.
TetMesh tetrahedralize_to_size(const TriMesh& surface, Eigen::Index target_tets, const TetgenOptions& options = {},
                               TriMesh* decimated_surface = nullptr);

/// \brief tetrahedralize_to_size on each connected component of the surface on its own, the
/// results concatenated (vertex indices offset, components in the order of their first face).
/// For templates modelled as overlapping closed parts (limbs pushed into a torso), which TetGen
/// refuses as a whole because the parts intersect; each part becomes a volume of its own. The
/// target is shared by the components' face counts (at least 20 tets each). Zero-volume slivers
/// (|volume| <= 1e-9 of the mean, which TetGen can leave on a small decimated part) are dropped. Throws like
/// tetrahedralize when a component itself is open, non-manifold or self-intersecting.
TetMesh tetrahedralize_components(const TriMesh& surface, Eigen::Index target_tets, const TetgenOptions& options = {},
                                  TriMesh* decimated_surface = nullptr);

}  // namespace tbsp
