#pragma once
/// \file template_fitter.h
/// \brief Template fitting to point clouds (thesis ch. 5 + §5.5): the non-template kernel behind
/// tbsp::TemplateFitting<PointT>. Works on Eigen points; see template_fitting.h for the PCL API.
///
/// Pipeline (all automatic after the markers; without markers a similarity alignment by trimmed
/// ICP comes first and steps 1-2 are skipped):
///  1. initial deformation with the rotation field (eq. 3.12) from the markers;
///  2. global scale λ from ratios of Dijkstra geodesics between markers (§5.2), iterated to a
///     fixed point (the thesis does one step; data ×3 out of scale needs a few) and re-solve;
///  3. iterative matching (§5.3): per template vertex the cloud points within r_max whose normals
///     deviate ≤ θ_max, averaged with the quadratic B-spline kernel, projected on the vertex
///     normal; weighted constraints; re-solve until the largest vertex move < tolerance;
///     r_max shrinks from `initial` to `final` over the first iterations (coarse-to-fine);
///     (optionally refreshing the rotation field from the fit, see refine_rotations); then the
///     constrained set is frozen: each further iteration is one back-substitution;
///  4. displacement propagation (§5.3 end): normal displacements of matched vertices relative to
///     the initial deformation, harmonically interpolated to unmatched vertices, weight ½ (with
///     a frozen set these constraints join it and follow each iteration: no extra solve);
///  5. options (§5.5): Laplacian updating per iteration, adaptive 1-to-4 subdivision where the
///     per-triangle error exceeds ε (+ T-junction repair and valence flips), tangential
///     area-weighted fairing along the cloud normals (eq. 5.1-5.2).

#include <Eigen/Core>
#include <limits>
#include <optional>
#include <string>
#include <vector>

#include "tbsp/core/progress.h"
#include "tbsp/mesh/tri_mesh.h"

namespace tbsp {

/// \brief A user correspondence: template vertex ↔ cloud point (cloud_index >= 0) or a free 3D
/// position (cloud_index < 0; for markers placed where the scan has no data).
struct FitMarker {
  FitMarker() = default;
  FitMarker(int vertex, Eigen::Index cloud_point) : template_vertex(vertex), cloud_index(cloud_point) {}
  int template_vertex = -1;
  Eigen::Index cloud_index = -1;
  Eigen::Vector3d position = Eigen::Vector3d::Constant(std::numeric_limits<double>::quiet_NaN());
  std::optional<Eigen::Matrix3d> rotation;  ///< optional local frame rotation (template → data)
  double weight = 1.0;                      ///< relative to FitParameters::marker_weight
};

struct Sphere { Eigen::Vector3d center = Eigen::Vector3d::Zero(); double radius = 0; };
struct Box { Eigen::Vector3d min = Eigen::Vector3d::Zero(), max = Eigen::Vector3d::Zero(); };

/// \brief What is excluded from matching. Excluded template vertices get no data constraints
/// (they follow the template smoothly through the Laplacian); excluded cloud points are never
/// matched and not counted in the error metrics.
struct RegionOfInterest {
  std::vector<int> exclude_template_vertices;
  std::vector<Sphere> exclude_template_spheres;  ///< in template (rest) coordinates
  std::vector<Box> exclude_template_boxes;
  std::vector<Eigen::Index> exclude_cloud_points;
  std::vector<Sphere> exclude_cloud_spheres;     ///< in cloud coordinates
  std::vector<Box> exclude_cloud_boxes;
};

/// \brief Parameters. Lengths of 0 mean "derive from the data" (d = cloud bbox diagonal,
/// s = median point spacing); the values used are reported back.
struct FitParameters {
  double max_match_distance = 0;        ///< r_max (final); 0: max(3 s, 0.5 % d)
  double initial_match_distance = 0;    ///< r_max of iteration 1; 0: max(r_max, 3 % d)
  double max_normal_angle_deg = 60;     ///< θ_max
  /// A match is rejected when the weighted mean of its points lies more than this × r_max away
  /// from the vertex's normal line (one-sided neighbourhood at the rim of the data: the normal
  /// projection would be biased). 1 disables the test.
  double rim_rejection = 0.5;
  /// Beyond the thesis: project along the vertex normal onto the weighted least-squares plane
  /// of the matched points instead of onto their weighted mean (same on symmetric
  /// neighbourhoods; unbiased at the rim of the data and on one-sided neighbourhoods).
  bool plane_fit = true;
  /// Beyond the thesis: at large radii (the first coarse-to-fine steps) match against the cloud
  /// summarised in bins of r/3 (per voxel and normal octant: count, Σp, Σppᵀ, mean normal)
  /// instead of every point, when that has under half as many entries. The kernel-weighted
  /// mean and plane are then sums over bins (kernel at the bin centroid); the final radius
  /// always matches every point. 43k vertices / 100k points: iteration 1 matching 0.45 → 0.09 s,
  /// same accuracy (docs/fitting.md). Not used with Laplacian updating / remeshing: there a
  /// robustness sweep stayed within 0.5 % with exact matching and not always with bins.
  bool binned_matching = true;
  int max_iterations = 15;
  /// r_max shrinks geometrically from initial_match_distance to max_match_distance over this
  /// many iterations (coarse-to-fine; 0: r_max from the start). Two steps are faster (one
  /// factorization less) but let misregistered fragments pull a fold into the fit.
  int radius_steps = 3;
  double tolerance = 0;                 ///< stop when the 99th percentile of matched-vertex moves < tol; 0: 2e-4 d
  double marker_weight = 10;            ///< w of marker constraints
  double match_weight = 1;              ///< w of data constraints (§5.3)
  /// Beyond the thesis: inverse-variance weighting of sparse matches. A match whose kernel
  /// weights w_k give an effective number of points n_eff = (Σw)² / Σw² below this has its
  /// least-squares weight (the square of the constraint weight) scaled by n_eff / support_points:
  /// its target is a mean of fewer noisy points, with variance σ² / n_eff. Acts at the rim of
  /// holes and in sparse patches, where one or two noisy points otherwise set a vertex and,
  /// through displacement propagation, the hole next to it. 0: off (the thesis). Bunny ground truth, seeds 1-6: per-vertex hole error lower on
  /// every seed (e.g. 0.977 → 0.895 %, 1.064 → 0.917 %; docs/fitting.md). Not applied with
  /// laplacian_updating: a sphere template far from the data needs every match at full weight
  /// (sphere → Igea 0.44 → 0.49-0.53 % with it).
  double support_points = 3;
  double propagation_weight = 0.5;      ///< w of propagated constraints (§5.3: ½)
  bool rotation_field = true;           ///< eq. 3.12 from the markers
  bool estimate_scale = true;           ///< §5.2
  bool propagate_displacements = true;  ///< §5.3 final step
  /// Beyond the thesis: from iteration 2 on, re-estimate the rotation field from the current fit
  /// (per matched vertex the closest rotation of its cotangent-weighted one-ring map, eq. 3.15)
  /// and interpolate it harmonically into unmatched regions (eq. 3.11), so holes inherit the
  /// local rotations of their rims instead of those extrapolated from a few markers.
  bool refine_rotations = false;
  /// Once r has reached r_max, keep the constrained vertex set and weights fixed and only move the
  /// targets: iterations cost a back-substitution instead of a factorization.
  bool freeze_constraints = true;
  /// Iteration at which the set is frozen; 0: the iteration before r reaches r_max
  /// (= radius_steps, at least 1): three factorizations in all with the defaults. Vertices that
  /// only find data at the final radius are then filled by displacement propagation.
  int freeze_iteration = 0;
  /// Over-relaxation ω of the frozen iterations (x ← x + ω (solve − x); 1: none). The targets
  /// of the matching creep towards the data by a roughly constant fraction per iteration;
  /// ω = 1.5 reaches the tolerance in about two thirds of the iterations. Never applied to
  /// the last step.
  double relaxation = 1.5;
  /// Beyond the thesis: rounds of §5.5.1's Laplacian updating *after* the §5.3 fit, with every
  /// vertex the data does not support (propagated, masked, unmatched) held where the fit put it:
  /// the regularizer becomes the current fit's own Laplacian, so protrusions (ears, tips) are no
  /// longer held back by the template's detail, while the semantic hole filling stays. Each
  /// round is one factorization + up to `detail_iterations` matching / back-substitution steps
  /// (stopping at `detail_tolerance`). Keeps the template's connectivity. 0: off. Bunny ground
  /// truth, 30 markers (docs/fitting.md): clean Hausdorff 0.86 → 0.27 % with 4 rounds (seeds
  /// 1-24: 0.23-0.38 %, 17 within 0.3 %), hole error unchanged; armadillo 43k / 100k points:
  /// 4.78 → 2.75 %, ~4.5 s per round (detail_iterations 8 and detail_tolerance = tolerance:
  /// 3.46 %, 1.5-2 s per round). Cost per iteration: O(#points) closest-point updates +
  /// O(#vertices) kernel sums.
  /// Ignored with laplacian_updating / remeshing (they already regularize with the current shape).
  int detail_rounds = 0;
  int detail_iterations = 20;           ///< per detail round (at most; see detail_tolerance)
  /// A detail round stops when the 99th percentile of the supported vertices' moves drops below
  /// this; 0: tolerance / 2. The residual targets move vertices sideways only slowly (a few
  /// 0.01 % d per iteration at creases), so the rounds need a tighter stop than stage 2: bunny
  /// ground truth, seeds 1-24, 4 rounds: at tolerance and ≤ 8 iterations 16 of 24 within 0.3 %,
  /// worst 0.445 %; at tolerance / 2 and ≤ 20 iterations 18 of 24, worst 0.377 %.
  double detail_tolerance = 0;
  double detail_weight = 2;             ///< weight of the §5.3 vertex targets in detail rounds (held vertices: match_weight)
  /// Weight of the markers in the detail rounds. A marker tied to a cloud point is one noisy
  /// sample; at marker_weight it pins the surface to that point's noise. 1: like one data
  /// constraint (bunny ground truth, 4 rounds, clean Hausdorff averaged over seeds 1-6:
  /// 0.372 % at weight 10 → 0.356 %).
  double detail_marker_weight = 1;
  /// How the detail rounds set the targets of the data-supported vertices.
  /// true (default): residual matching — every ROI cloud point p_k within r_max of the fit is
  /// projected onto it (closest point c_k, which then moves with its face), and a vertex v goes
  /// to v + Σ w_k (p_k − c_k) / Σ w_k, w_k the quadratic B-spline kernel of |c_k − v| over
  /// `detail_radius_factor` × r_max (`detail_normal_angle_deg`). The mean residual is zero where the
  /// fit passes through the data, whatever the curvature, so unlike the §5.3 kernel mean
  /// (which lies inside a convex surface) it needs no correction terms and can average over a
  /// wider kernel; it also moves vertices sideways where the data reach beyond the fit (tips).
  /// false: the §5.3 kernel targets of stage 2, along the vertex normal, plus the face
  /// constraints of `detail_surface_weight`.
  bool detail_residual_matching = true;
  /// Kernel radius of the residual matching as a multiple of r_max (0.5..10).
  double detail_radius_factor = 2;
  /// Residual matching: a point counts only if its normal is within this angle of the normal of
  /// the fit's face it projects onto (stage 2's θ_max compares with the vertex normal instead,
  /// which at a crease or groove is an average of both sides). Bunny ground truth, seeds 1-24,
  /// 4 rounds (≤ 8 iterations each): 40° against the vertex normal at 60°: mean clean
  /// Hausdorff 0.316 → 0.298 %, worst 0.522 → 0.445 % (chosen on seeds 1-12, checked on 13-24;
  /// docs/fitting.md).
  double detail_normal_angle_deg = 40;
  /// Weight of the data → surface constraints of the detail rounds: every face onto which 3 or
  /// more cloud points project (within r_max) pulls its centroid by their mean residual — also
  /// sideways, where the data reach beyond the mesh. 0: off (the default: with residual matching
  /// these few-point means only add noise). With `detail_residual_matching` false use 4.
  double detail_surface_weight = 0;
  bool laplacian_updating = false;      ///< §5.5.1
  double updating_match_weight = 0.5;   ///< data weight with Laplacian updating
  bool remeshing = false;               ///< §5.5.2 (needs laplacian_updating; changes connectivity)
  double subdivision_error = 0;         ///< ε; 0: 0.15 % d
  int max_vertices = 60000;             ///< remeshing stops growing the mesh beyond this
  /// Without markers (and without remeshing): after the aligned fit, this many of its matched
  /// vertices (farthest-point sampled over the template) become free markers at their fitted
  /// positions, and the fit runs again from the template with them — the rotation field and the
  /// geodesic scale of §5.2 then apply as with user markers. 0: one pass (the aligned fit).
  /// Range 0..1000; default 30.
  int auto_markers = 30;
  /// Without markers: first align the template to the cloud by a similarity (trimmed ICP with
  /// scale). false: the template is used where it is — for refining a mesh that is already
  /// posed (ModelGuidedStereo), where a partial cloud would pull a global alignment off.
  bool align_without_markers = true;
  bool fairing = false;                 ///< §5.5.3
  double fairing_lambda = 0.5;          ///< λ of eq. 5.2
  int fairing_steps = 2;                ///< per iteration
  /// With remeshing and fairing, after the fold repair: pleats — strips of faces pointing against
  /// the cloud normal near them because their vertices lie out of order along the surface — are
  /// removed by edge collapses (collapse_pleats, mesh/remeshing.h), then the crumples left are
  /// untangled. Sphere → Igea: faces against the scan's true normals 215 → 70 of 110k,
  /// Hausdorff 0.443 → 0.447 % (docs/fitting.md). Ignored without remeshing (the template's
  /// connectivity is kept then).
  bool pleat_collapse = true;
  /// Count the result's self-intersections (FitReport::self_intersections, exact predicates,
  /// ~0.15 s per 100k faces). Always done with fairing, which also repairs them
  /// (repair_self_intersections, mesh/remeshing.h); without fairing only when this is set
  /// (otherwise the count is -1), which keeps the default path's metrics cheap.
  bool check_self_intersections = false;
  int normal_neighbours = 16;           ///< k for normal estimation / cloud normal averaging
  /// Estimated normals (see fit_template) are oriented by the posed template; where its normal
  /// points the other way (a sphere over a concave ledge) whole patches come out inwards. With
  /// this switch they are then made consistent between neighbours, per connected part the way
  /// the template agrees with more (orient_normals_consistently, mesh/point_normals.h). Sphere →
  /// Igea: 94 of 134k points corrected, but the fit then also matches the concave ledge and the
  /// updating-weight sweep gives 0.41–0.59 % instead of 0.43–0.48 % (docs/fitting.md), so it is
  /// off by default. (The report's flipped_faces uses consistent normals either way.) Given
  /// normals are left alone.
  bool consistent_normals = false;

  /// Checks ranges; fills `why` with the first problem.
  bool isValid(std::string* why = nullptr) const;
};

enum class VertexStatus : unsigned char { Matched = 0, Propagated = 1, Masked = 2, Unmatched = 3 };

struct FitIteration {
  int iteration = 0;
  double match_radius = 0;
  Eigen::Index matched = 0;
  double max_move = 0;
  double seconds = 0;
  double matching_seconds = 0;  ///< of `seconds`: the neighbour search and targets
  double solve_seconds = 0;     ///< of `seconds`: system update, factorization (if any), solve
  bool binned = false;          ///< matched against the binned cloud (FitParameters::binned_matching)
};

/// \brief Everything reconstruct() reports (also written as the JSON report of `tbsp fit`).
struct FitReport {
  enum class Status { Success, NotConverged } status = Status::Success;
  std::string message;
  int iterations = 0;
  std::vector<FitIteration> history;
  double scale = 1.0;                    ///< global scale λ (§5.2; without markers: the alignment's scale)
  /// without markers: the similarity (rotation, uniform scale, translation; template → cloud)
  /// found by trimmed ICP before the fit, its rotation angle, scale, iterations and the RMS
  /// distance of the kept pairs (cloud point → nearest template vertex) at the end
  bool aligned_without_markers = false;
  Eigen::Matrix4d alignment = Eigen::Matrix4d::Identity();
  double alignment_rotation_deg = 0, alignment_scale = 1, alignment_rms = 0;
  int alignment_iterations = 0;
  int auto_markers = 0;  ///< markers taken from the aligned fit for the second pass (FitParameters::auto_markers)
  FitParameters used;                    ///< parameters with the derived values filled in
  Eigen::Index points_total = 0, points_skipped_nonfinite = 0, points_excluded = 0;
  bool normals_estimated = false;
  Eigen::Index normals_flipped_for_consistency = 0;  ///< with FitParameters::consistent_normals
  Eigen::Index vertices = 0, faces = 0, matched = 0, propagated = 0, masked = 0;
  double bbox_diagonal = 0, point_spacing = 0;
  // metrics over ROI points (cloud → mesh)
  double hausdorff = 0, hausdorff_rel = 0, rms = 0, mean = 0, p99 = 0;
  double coverage_vertices = 0;          ///< fraction of (non-masked) template vertices matched
  double coverage_points = 0;            ///< fraction of ROI points within r_max of the result
  /// faces more than 120° against the cloud normal nearest to their centre (within r_max);
  /// estimated normals are made consistent for this count (orient_normals_consistently)
  int flipped_faces = 0;
  int folded_edges = 0;                  ///< edges whose two faces are bent back by more than 120°
  int local_folds = 0;                   ///< faces against their surroundings' normal (count_local_folds); -1: not computed (fairing off)
  int untangled_vertices = 0;            ///< vertices the fold repair re-placed (with fairing)
  /// pairs of faces of the result that intersect other than at a shared edge or vertex
  /// (count_self_intersections: a surface folded through itself, §5.5.3); -1: not checked
  /// (fairing off and FitParameters::check_self_intersections not set, or a template that is
  /// not a consistently oriented manifold mesh)
  int self_intersections = -1;
  int self_intersections_before = -1;    ///< ... before the self-intersection repair (with fairing)
  /// with FitParameters::pleat_collapse: faces against the (consistent) cloud normal near them
  /// before / after, and the edges collapsed
  int pleat_faces_before = 0, pleat_faces_after = 0, pleat_collapses = 0;
  // timings (s)
  double t_normals = 0, t_search = 0, t_alignment = 0, t_initial = 0, t_scale = 0, t_iterations = 0, t_matching = 0,
         t_solve = 0, t_propagation = 0, t_detail = 0, t_remeshing = 0, t_fairing = 0, t_metrics = 0, t_total = 0;
  int detail_iterations_run = 0;         ///< matching / solve steps of the detail rounds, all rounds
  Eigen::Index detail_surface_constraints = 0;  ///< data -> surface constraints, all detail rounds
  Eigen::Index detail_points_tracked = 0;  ///< cloud points of the residual matching, last detail round
};

/// \brief Fits `templ` to the cloud P (#P by 3) with normals N (#P by 3, or 0 rows: then they
/// are estimated by PCA over `normal_neighbours`). Estimated normals (and given ones when
/// `orient_normals` is true, e.g. from PCL's estimator) are oriented by the posed template
/// (and then made consistent with FitParameters::consistent_normals).
/// Non-finite points are skipped and counted.
/// \param templ the template (a valid triangle mesh).
/// \param P, N the cloud's points and normals (see above).
/// \param markers template vertex ↔ cloud point / position correspondences; empty: the template
/// is roughly in place and is first aligned to the cloud (rotation, uniform scale, translation;
/// trimmed ICP, FitReport::alignment), then fitted with the matches alone.
/// \param roi what is excluded from matching (template vertices, cloud points).
/// \param params the parameters (validated: FitParameters::isValid); the values used are in the report.
/// \param progress called with (fraction, stage); returning false cancels (tbsp::Cancelled).
/// \param orient_normals orient given normals by the posed template too.
/// \param[out] result fitted mesh (template connectivity unless remeshing)
/// \param[out] status per result vertex
/// \throws InvalidInput for an empty cloud, markers on missing vertices/points, marker sets that
/// leave the system singular, invalid parameters or an unsuitable template; Cancelled.
FitReport fit_template(const TriMesh& templ, const Eigen::MatrixX3d& P, const Eigen::MatrixX3d& N,
                       const std::vector<FitMarker>& markers, const RegionOfInterest& roi, const FitParameters& params,
                       TriMesh& result, std::vector<VertexStatus>& status, const ProgressCallback& progress = {},
                       bool orient_normals = false);

/// Quadratic B-spline fall-off of §5.3: 1 at t=0, 0 at t>=1, C1 (t = distance / r_max).
inline double bspline_weight(double t) {
  if (t >= 1) return 0;
  if (t < 0.5) return 1 - 2 * t * t;
  return 2 * (1 - t) * (1 - t);
}

}  // namespace tbsp
