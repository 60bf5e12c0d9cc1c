#pragma once
/// \file remeshing.h
/// \brief Adaptive refinement for template fitting (thesis §5.5.2, Fig. 5.7): 1-to-4 splits of
/// marked triangles with T-junction repair (red-green closure), and valence-optimising edge flips.
/// Written by hand: CGAL's refinement/isotropic remeshing do not split by a per-face error flag
/// and would renumber the vertices, while here old vertices keep their indices (new ones are
/// appended), so markers and per-vertex state survive.

#include <Eigen/Core>
#include <functional>
#include <vector>

namespace tbsp {

struct SubdivisionResult {
  Eigen::MatrixX3d V;
  Eigen::MatrixX3i F;
  /// per new vertex (index >= old #V): the two old vertices whose edge midpoint it is
  std::vector<std::pair<int, int>> parents;
  int red_faces = 0;    ///< faces split 1-to-4
  int green_faces = 0;  ///< faces split 1-to-2 to repair a T-junction
};

/// \brief Splits every face with `marked[f]` into 4 and repairs T-junctions: a face with two or
/// three split edges is split 1-to-4 as well (repeated until closed), a face with one split edge
/// is bisected. Midpoints are placed at the edge midpoints of V. Old vertex indices are kept.
/// \pre F is a manifold triangle mesh (boundary allowed), marked.size() == #F.
SubdivisionResult adaptive_subdivide(const Eigen::MatrixX3d& V, const Eigen::MatrixX3i& F, const std::vector<char>& marked);

/// \brief Flips interior edges where that reduces Σ (valence − 6)² of the four vertices involved
/// (boundary vertices target 4), Botsch & Kobbelt 2004, skipping flips that would fold the surface
/// (new face normals deviating more than `max_normal_change_deg` from the old ones) or duplicate
/// an edge. Up to `sweeps` passes. \returns the number of flips.
int valence_edge_flips(const Eigen::MatrixX3d& V, Eigen::MatrixX3i& F, int sweeps = 3, double max_normal_change_deg = 30);

/// \brief Number of faces whose normal points against the given reference normals
/// (n_f · ref_f < 0), i.e. fold-overs; rows of ref with zero length are ignored.
int count_flipped_faces(const Eigen::MatrixX3d& V, const Eigen::MatrixX3i& F, const Eigen::MatrixX3d& reference_face_normals);

/// \brief Local fold-overs ("pleats"): faces whose normal points against the area-weighted mean
/// normal of the faces around them (the faces at the vertices within two rings of the face's
/// corners, each counted once, weighted by its area). A surface that doubles back on itself in a small crumple
/// has such faces even when no single edge is bent back sharply; a smooth surface has none unless
/// it turns by more than 90° within those rings. O(#F · two-ring size), parallel.
/// \param V, F the mesh (#V by 3, #F by 3).
/// \param face_mark if given, resized to #F and set to 1 for each folded face.
/// \returns the number of folded faces.
int count_local_folds(const Eigen::MatrixX3d& V, const Eigen::MatrixX3i& F, std::vector<char>* face_mark = nullptr);

struct UntangleResult {
  int folds_before = 0;    ///< count_local_folds before
  int folds_after = 0;     ///< ... and after
  int rounds = 0;          ///< rounds run
  int vertices_moved = 0;  ///< distinct vertices re-placed
};

/// \brief Removes local fold-overs (count_local_folds) by re-placing the vertices of the folded
/// faces and `rings` rings around them: they are set to the harmonic (uniform-weight)
/// interpolation of the fixed vertices around them — a discrete membrane. Projected on any plane
/// that is Tutte's embedding of the projected region boundary, so a disc-shaped region whose
/// boundary projects to a convex polygon comes out fold-free. Rounds repeat on the folds left;
/// the region grows by one ring only after a round without progress (up to `max_rings`), so the
/// surface changes as little as possible: with rings = 0 the folded faces' own vertices move,
/// about the size of the crumple. Vertices on a mesh boundary stay fixed. Each round is one
/// sparse solve over the region vertices. \returns counts before/after.
UntangleResult untangle_local_folds(Eigen::MatrixX3d& V, const Eigen::MatrixX3i& F, int rings = 0, int max_rounds = 20,
                                    int max_rings = 3);

struct PleatCollapseResult {
  int faces_before = 0;  ///< faces against their reference normal before
  int faces_after = 0;   ///< ... and after
  int collapses = 0;     ///< edges collapsed
  int passes = 0;        ///< passes run
};

/// \brief Removes pleats — strips of faces whose vertices lie out of order along the surface, so
/// that the faces point against the surface's normal there — by edge collapses. A face is
/// *against* when its normal n_f has n_f · reference_normal(centroid) < 0; a zero reference
/// (no data near the face) never counts. Per pass, the edges of those faces are taken shortest
/// first; an edge (a, b) is collapsed when (1) the link condition holds (a and b share exactly
/// the two opposite vertices, so the mesh stays manifold), (2) at the best of five positions on
/// the segment ab (midpoint, ends, quarter points) none of the remaining faces around it
/// degenerates (area below 1e-3 × the squared median edge length), and none of those the
/// reference accepts points against their area-weighted mean normal (no new crumple) or is
/// bent back by more than 120° against a neighbour (no new folded edge), and (3) fewer faces
/// around it are against their reference than before. A collapse locks its neighbourhood until the next pass;
/// passes repeat (at most `max_passes`) until none is possible. More than 5 % of the faces
/// against the reference means it is oriented the other way, not pleats: then nothing changes.
/// `min_cosine` > 0 also counts faces nearly perpendicular to the reference (n_f · r < min_cosine). Pleats whose vertices are out of
/// order cannot be fixed by edge flips or by smoothing without flattening detail; merging the
/// out-of-order vertices removes them with sub-edge-length moves.
/// Changes connectivity: the merged-away vertices and the removed faces are compacted (order
/// otherwise kept).
/// O(passes · (#F + Σ candidate neighbourhoods)), the reference is evaluated ~ 5 × per face
/// of a neighbourhood tried. Written by hand: CGAL's edge-collapse simplification takes a cost
/// and placement policy but no "against a reference normal" stop and renumbers the mesh.
/// \param V, F the mesh (#V by 3, #F by 3), changed in place.
/// \param reference_normal the expected outward normal at a point (zero: no reference there).
/// \param max_passes at most this many passes (default 30).
/// \param min_cosine faces with n_f · r < min_cosine count as against the reference (default 0).
/// \param old_to_new if given, set to the new index of every old vertex (-1: removed).
/// \pre F is a manifold triangle mesh (boundary allowed).
PleatCollapseResult collapse_pleats(Eigen::MatrixX3d& V, Eigen::MatrixX3i& F,
                                    const std::function<Eigen::Vector3d(const Eigen::Vector3d&)>& reference_normal,
                                    std::vector<int>* old_to_new = nullptr, int max_passes = 30, double min_cosine = 0);

struct IntersectionRepairResult {
  int pairs_before = 0;    ///< intersecting face pairs (count_self_intersections) before
  int pairs_after = 0;     ///< ... and after
  int rounds = 0;          ///< smoothing rounds run
  int vertices_moved = 0;  ///< distinct vertices moved
};

/// \brief Removes self-intersections — faces passing through each other, e.g. a pleat pushed
/// through the surface next to it — by umbrella smoothing. Per round, the vertices of the
/// intersecting faces (grown by one ring per 10 rounds while crossings persist) move half-way
/// to the centroid of their neighbours, and the mesh is checked again (count_self_intersections,
/// exact predicates); at most `max_rounds` rounds. Connectivity is unchanged; only vertices near
/// crossings move, so detail elsewhere is kept. A crossing between two distant parts of the
/// surface that touch over a large area (e.g. two interpenetrating components) needs more
/// rounds than that and is left (pairs_after > 0).
/// Cost: rounds × (O(#F log #F) check + O(region) smoothing).
/// \throws InvalidInput as count_self_intersections (not a manifold, consistently oriented mesh).
IntersectionRepairResult repair_self_intersections(Eigen::MatrixX3d& V, const Eigen::MatrixX3i& F, int max_rounds = 50);

}  // namespace tbsp
