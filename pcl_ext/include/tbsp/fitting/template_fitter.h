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
///  2b. coarse stage (coarse_nodes > 0; by default without markers, and with markers as the second
///     of two fits compared on the data): a deformation graph fitted to the cloud by
///     stiffness-annealed non-rigid ICP (DeformationGraph), for parts turned about joints; its
///     result is the rest shape of the steps below;
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

/// \brief Parameters of fit_template / TemplateFitting, grouped by stage.
///
/// Lengths of 0 mean "derive from the data" (d = bounding-box diagonal of the cloud's region of
/// interest, s = its median point spacing); the values used are reported back in FitReport.
/// Each entry: default, range, meaning. isValid() checks the ranges. The user page with the
/// measured effect of the main switches is docs/fitting.md; how each was chosen is in
/// docs/dev/fitting_experiments.md.
struct FitParameters {
  // ---- matching (§5.3) ----
  /// Final match radius r_max (length). Default 0 → max(3 s, 0.5 % d). ≥ 0.
  double max_match_distance = 0;
  /// Match radius of the first iteration (length). Default 0 → max(r_max, 3 % d). ≥ 0.
  double initial_match_distance = 0;
  /// θ_max (degrees): largest angle between a point's and the vertex's normal. Default 60. (0, 180].
  double max_normal_angle_deg = 60;
  /// A match is rejected when the weighted mean of its points lies farther than this × r_max
  /// from the vertex's normal line (a one-sided neighbourhood at the rim of the data, whose
  /// normal projection would be biased). Default 0.5. (0, 1]; 1 disables the test.
  double rim_rejection = 0.5;
  /// Project onto the weighted least-squares plane of the matched points (true) or onto their
  /// weighted mean (false, the thesis). Default true: unbiased at rims and on one-sided
  /// neighbourhoods, identical on symmetric ones.
  bool plane_fit = true;
  /// At the large radii of the first iterations, match against the cloud summarised in bins of
  /// r/3 per normal octant (count, Σp, Σppᵀ, mean normal) when that has under half as many
  /// entries; the final radius always matches every point. Default true (≈ 5 × faster first
  /// iteration on 100k points, same accuracy). Not used with laplacian_updating.
  bool binned_matching = true;
  /// Inverse-variance weighting of sparse matches: a match whose effective number of points
  /// n_eff = (Σw)² / Σw² is below this gets its least-squares weight × n_eff / support_points.
  /// Default 3; ≥ 0; 0 = off (the thesis). Not applied with laplacian_updating.
  double support_points = 3;
  /// Neighbours k for normal estimation and cloud normal averaging. Default 16. ≥ 3.
  int normal_neighbours = 16;
  /// Make estimated normals consistent between neighbours after orienting them by the posed
  /// template (orient_normals_consistently). Default false. Given normals are never changed.
  bool consistent_normals = false;

  // ---- iterations and weights ----
  /// Matching iterations at most. Default 15. 0..1000.
  int max_iterations = 15;
  /// Iterations over which r shrinks geometrically from initial_match_distance to r_max.
  /// Default 3. 0..100 (0: r_max from the start).
  int radius_steps = 3;
  /// Stop when the 99th percentile of matched-vertex moves is below this (length). Default
  /// 0 → 2e-4 d. ≥ 0.
  double tolerance = 0;
  /// Weight of marker constraints. Default 10. > 0.
  double marker_weight = 10;
  /// Weight of data constraints. Default 1. > 0.
  double match_weight = 1;
  /// Weight of propagated constraints (holes). Default 0.5 (the thesis's ½). > 0.
  double propagation_weight = 0.5;
  /// Once r reaches r_max, keep the constrained set and weights fixed and move only targets:
  /// each later iteration is one back-substitution. Default true.
  bool freeze_constraints = true;
  /// Iteration at which the set is frozen. Default 0 → the iteration before r reaches r_max. ≥ 0.
  int freeze_iteration = 0;
  /// Over-relaxation ω of frozen iterations, x ← x + ω (solve − x); never on the last step.
  /// Default 1.5. [1, 2); 1 = none.
  double relaxation = 1.5;

  // ---- coarse stage: pose and scale ----
  /// Rotation field from the markers (eq. 3.12) for the initial deformation. Default true.
  bool rotation_field = true;
  /// Global scale from geodesic distance ratios between markers (§5.2). Default true.
  bool estimate_scale = true;
  /// Re-estimate the rotation field from the current fit from iteration 2 on (eq. 3.15) and
  /// interpolate it into unmatched regions. Default false.
  bool refine_rotations = false;
  /// Without markers: align the template to the cloud by a similarity first (trimmed ICP with
  /// scale). Default true; false uses the template where it is (a mesh already posed).
  bool align_without_markers = true;
  /// Without markers: after the aligned fit, this many of its matched vertices (farthest-point
  /// sampled) become markers and the fit runs again with them. Default 30. 0..1000 (0: one pass).
  int auto_markers = 30;
  /// Nodes of the embedded deformation graph of the coarse stage (a stiffness-annealed
  /// non-rigid ICP between the initial deformation and the §5.3 iterations; follows parts turned
  /// about joints; fit_coarse.cpp). Default −1 (automatic): without markers (a fit that aligns the
  /// template itself: align_without_markers, auto_markers > 0), 400, since nothing else can follow
  /// a turned part; with markers (no remeshing) the fit runs twice, without the coarse stage and
  /// with 400 nodes, side by side on two threads when OpenMP allows, and keeps the fit from which
  /// fewer ROI points lie farther than r_max after the pull rounds (the one without unless the
  /// other has more than 10 and 1 % fewer: where the data cannot tell, the template's own shape
  /// in holes is kept; FitReport::coarse_compared). With detail_rounds the choice is made before
  /// them and only the kept fit runs them. Where the fit without the coarse stage leaves 10 points
  /// or fewer beyond r_max that are not isolated (at least 4 other points within 3 × the cloud's
  /// median spacing: stray outliers do not count) the other is stopped; otherwise the comparison
  /// costs the slower fit's time (measured 1.6-3.6 × one fit without the coarse stage on two
  /// cores, docs/fitting.md) and about twice one fit's peak memory.
  /// 400 is the measured setting. −1, 0 (off) or 4..20000.
  int coarse_nodes = -1;
  /// Without markers (the auto_markers flow) and with the coarse stage on: one more hypothesis
  /// per entry. The whole fit runs once with the coarse_nodes graph alone and once per entry with
  /// a graph of that many nodes fitted first (regions the size of a head or a limb turn as wholes
  /// towards the data), then the coarse_nodes graph from there; the fit closest to the cloud is
  /// kept: the lowest mean of the largest 1 % of the cloud → fit distances (FitReport::tail_mean;
  /// ties keep the earlier hypothesis). Each hypothesis costs one fit without markers; with more
  /// than one OpenMP thread allowed they run side by side, one thread each (the same result as one
  /// after the other; about one fit's memory each); unused with markers (they pose the parts). Default {100, 200} (three hypotheses). Each entry in
  /// 4..20000; entries not below coarse_nodes and repeated entries are skipped; empty: one hypothesis.
  std::vector<int> coarse_prepass_nodes = {100, 200};
  /// Rounds of the coarse stage: stiffness and radius fall geometrically over them. Default 5. 1..100.
  int coarse_rounds = 5;
  /// Gauss-Newton steps (each with new correspondences) per round at most. Default 6. 1..100.
  int coarse_steps = 6;
  /// Correspondence radius of the first round, × d (the last round: max(2 r_max, 1 % d)).
  /// Default 0.1. (0, 1].
  double coarse_radius = 0.1;
  /// Stiffness α of the first / last round (relative: α = 1 weighs the regulariser as much as
  /// the data in total). Defaults 10 / 0.01. > 0.
  double coarse_stiffness = 10, coarse_final_stiffness = 0.01;
  /// Largest angle between a cloud normal and the deformed template's normal in a coarse
  /// correspondence (degrees). Default 60. (0, 180].
  double coarse_normal_angle_deg = 60;
  /// Weight of the point-to-point part of a coarse correspondence (the point-to-plane part has
  /// weight 1). Default 0.1. ≥ 0.
  double coarse_point_weight = 0.1;

  // ---- propagation (§5.3, final step) ----
  /// Interpolate the matched vertices' displacements harmonically into unmatched ones. Default true.
  bool propagate_displacements = true;

  // ---- detail rounds (beyond the thesis) ----
  /// Rounds of Laplacian updating after the fit with every unsupported vertex held: protrusions
  /// sharpen, holes keep their filling, connectivity is kept. Each round: one factorization +
  /// up to detail_iterations matching / back-substitution steps. Default −1 (automatic): 4 when
  /// the template has at most kAutoDetailVertices (20,000) vertices, else 0 (a round costs
  /// ~0.1 s on a 3.5k-vertex template, ~2 s on a 43k one). Compared fits (coarse_nodes) and
  /// the hypotheses of a fit without markers choose before the detail rounds; only the kept fit
  /// runs them. −1..100 (0: off). Ignored with laplacian_updating / remeshing.
  int detail_rounds = -1;
  /// Template size up to which detail_rounds = −1 runs 4 rounds.
  static constexpr int kAutoDetailVertices = 20000;
  /// Iterations per detail round at most. Default 20. 1..1000.
  int detail_iterations = 20;
  /// A detail round stops when the 99th percentile of the supported vertices' moves is below
  /// this (length). Default 0 → tolerance / 2. ≥ 0.
  double detail_tolerance = 0;
  /// Weight of the data targets in detail rounds (held vertices: match_weight). Default 2. > 0.
  double detail_weight = 2;
  /// Weight of the markers in detail rounds (a marker on a cloud point is one noisy sample).
  /// Default 1. > 0.
  double detail_marker_weight = 1;
  /// Targets of the detail rounds: true = residual matching (a vertex moves by the kernel mean
  /// of the cloud → fit residuals, unbiased on curved surfaces and also sideways); false = the
  /// §5.3 kernel targets along the normal (+ detail_surface_weight). Default true.
  bool detail_residual_matching = true;
  /// Residual matching: the points of regions the fit leaves unexplained (FitReport::unexplained,
  /// recomputed each round: a part it has not reached, such as the tip of a thin ear folded
  /// back) pull at any distance, by up to 1.5 × their region's farthest distance, instead of
  /// only within r_max. Scattered far points (outliers) form no region and stay ignored; points
  /// whose normal disagrees with the face they project onto (detail_normal_angle_deg) do not
  /// pull, but a region of clutter facing the surface would pull it: exclude clutter with an
  /// ROI. Default true.
  bool detail_pull_unexplained = true;
  /// Pull rounds: when a fit without detail rounds leaves regions of the cloud unexplained
  /// (FitReport::unexplained: a thin part folded back, a finger left behind), up to this many
  /// detail rounds that move only the vertices within reach of those regions (1.5 × a region's
  /// farthest distance + the residual kernel's radius), every other vertex held where the fit
  /// put it. A region's points keep pulling in the later rounds (also once they fall under the
  /// region threshold); a fit that leaves no region runs none and is unchanged. The regions'
  /// points pull as with detail_pull_unexplained (and so would a region of clutter facing the
  /// surface: exclude it with an ROI). Each round solves on the moving vertices' neighbourhood
  /// only (one small factorization, detail_iterations back-substitutions; ~0.15 s on 43k
  /// vertices). Default 3; 0 (off)..100; ignored with detail rounds (they pull the same regions),
  /// laplacian_updating, remeshing or detail_residual_matching = false.
  int pull_rounds = 3;
  /// Kernel radius of residual matching, × r_max. Default 2. [0.5, 10].
  double detail_radius_factor = 2;
  /// Residual matching: a point counts only if its normal is within this angle (degrees) of the
  /// normal of the face it projects onto. Default 40. (0, 180].
  double detail_normal_angle_deg = 40;
  /// Weight of per-face data constraints in detail rounds (each face with ≥ 3 projecting points
  /// pulls its centroid by their mean residual). Default 0 (off); ≥ 0; 4 with
  /// detail_residual_matching = false.
  double detail_surface_weight = 0;

  // ---- remeshing (§5.5.1, §5.5.2) ----
  /// Rebuild the Laplacian from the current shape each iteration (§5.5.1). Default false.
  bool laplacian_updating = false;
  /// Data weight with Laplacian updating. Default 0.5. > 0.
  double updating_match_weight = 0.5;
  /// Adaptive 1-to-4 subdivision (§5.5.2); needs laplacian_updating; changes connectivity.
  /// Default false.
  bool remeshing = false;
  /// Subdivision splits faces whose data lie farther than this on average (length). Default
  /// 0 → 0.15 % d. ≥ 0.
  double subdivision_error = 0;
  /// Remeshing stops growing the mesh beyond this many vertices. Default 60000. ≥ 4.
  int max_vertices = 60000;

  // ---- fairing and repairs (§5.5.3) ----
  /// Tangential area-weighted fairing along the cloud normals (eq. 5.1–5.2), then fold repair
  /// and self-intersection repair after the loop. Default false.
  bool fairing = false;
  /// λ of eq. 5.2. Default 0.5. (0, 1].
  double fairing_lambda = 0.5;
  /// Fairing steps per iteration. Default 2. ≥ 0.
  int fairing_steps = 2;
  /// With remeshing and fairing: collapse pleats (strips of faces against the nearby cloud
  /// normals whose vertices lie out of order along the surface), then untangle what is left.
  /// Default true. Ignored without remeshing.
  bool pleat_collapse = true;
  /// Count the result's self-intersections (exact predicates, ~0.15 s per 100k faces) also
  /// without fairing (with fairing they are counted and repaired). Default false (count -1).
  bool check_self_intersections = false;

  /// Checks ranges; fills `why` with the first problem.
  bool isValid(std::string* why = nullptr) const;
  /// detail_rounds as a fit of a template with `template_vertices` vertices runs them: −1
  /// resolved (4 up to kAutoDetailVertices, 0 above or with laplacian_updating / remeshing),
  /// any other value as it is.
  int resolvedDetailRounds(Eigen::Index template_vertices) const;
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
  int coarse_nodes = 0, coarse_steps = 0;  ///< coarse stage: graph nodes, Gauss-Newton steps (0: off)
  /// with markers and coarse_nodes −1: the fit ran without and with the coarse stage
  /// (FitParameters::coarse_nodes); coarse_far_points: the ROI points farther than r_max from
  /// each (without, with) where the choice was made (after the pull rounds, or before the detail
  /// rounds). Kept: coarse_nodes is 400 when the coarse stage's fit was. When the fit without it
  /// leaves 10 points or fewer there that are not isolated (stray outliers left out), the other is
  /// stopped (not compared; coarse_far_points holds that one count).
  bool coarse_compared = false;
  std::vector<Eigen::Index> coarse_far_points;
  /// without markers, with the coarse stage: hypotheses fitted (1 + the usable entries of
  /// FitParameters::coarse_prepass_nodes), the kept one's index (0: the coarse_nodes graph alone)
  /// and coarser graph (its nodes; 0: none), and each hypothesis's tail_mean in the order they ran
  /// (with detail rounds: before them; only the kept hypothesis runs them, and tail_mean below is
  /// its value after them)
  int coarse_hypotheses = 0, coarse_kept = 0, coarse_prepass_nodes = 0;
  std::vector<double> coarse_scores;
  int auto_markers = 0;  ///< markers taken from the aligned fit for the second pass (FitParameters::auto_markers)
  FitParameters used;                    ///< parameters with the derived values filled in
  Eigen::Index points_total = 0, points_skipped_nonfinite = 0, points_excluded = 0;
  bool normals_estimated = false;
  Eigen::Index normals_flipped_for_consistency = 0;  ///< with FitParameters::consistent_normals
  Eigen::Index vertices = 0, faces = 0, matched = 0, propagated = 0, masked = 0;
  double bbox_diagonal = 0, point_spacing = 0;
  // metrics over ROI points (cloud → mesh)
  double hausdorff = 0, hausdorff_rel = 0, rms = 0, mean = 0, p99 = 0;
  /// mean of the largest 1 % of the distances (the mean beyond p99): how far the worst-fitted
  /// parts of the cloud are; it ranks the coarse-stage hypotheses of a fit without markers
  double tail_mean = 0;
  /// A region of the cloud the result does not explain (see `unexplained`).
  struct UnexplainedRegion {
    Eigen::Index points = 0;                           ///< ROI points in it
    Eigen::Vector3d centre = Eigen::Vector3d::Zero();  ///< their mean, cloud units
    double max_distance = 0;                           ///< the farthest one's distance to the result
  };
  /// Groups of ROI points farther than max(2 r_max, 1 % of the bounding-box diagonal) from the
  /// result (points within half that of each other joined), each of at least max(30, 0.1 % of
  /// the ROI points), largest first, at most 8. Typically a part of the template that stayed behind (an ear, a
  /// limb or a finger turned beyond the fit's reach: give a marker there) or data that are not
  /// the object (clutter: exclude it with the region of interest). Scattered outliers and noise
  /// do not form regions. A fit that leaves any is reported with a warning in `message`.
  std::vector<UnexplainedRegion> unexplained;
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
  // timings (s); t_normals and t_search: the cloud's preparation, done once per fit_template
  // call (a fit without markers shares it between its passes and hypotheses)
  double t_normals = 0, t_search = 0, t_alignment = 0, t_initial = 0, t_coarse = 0, t_scale = 0, t_iterations = 0, t_matching = 0,
         t_solve = 0, t_propagation = 0, t_detail = 0, t_pull = 0, t_remeshing = 0, t_fairing = 0, t_metrics = 0, t_total = 0;
  int detail_iterations_run = 0;         ///< matching / solve steps of the detail rounds, all rounds
  Eigen::Index detail_surface_constraints = 0;  ///< data -> surface constraints, all detail rounds
  Eigen::Index detail_points_tracked = 0;  ///< cloud points of the residual matching, last detail round
  int detail_rounds_pulling = 0;
  int pull_rounds_run = 0;  ///< pull rounds run (FitParameters::pull_rounds; 0 when no region was left)  ///< detail rounds whose unexplained regions pulled (FitParameters::detail_pull_unexplained)
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
/// \param progress called with (fraction, stage); returning false cancels (tbsp::Cancelled). A fit
/// without markers whose hypotheses run side by side calls it from their threads, one call at a
/// time (serialised), with the mean of their fractions.
/// \param orient_normals orient given normals by the posed template too.
/// \param[out] result fitted mesh (template connectivity unless remeshing)
/// \param[out] status per result vertex
/// \throws InvalidInput for an empty cloud, markers on missing vertices/points, marker sets that
/// leave the system singular, invalid parameters or an unsuitable template, and a fit in which no
/// template vertex matched the cloud (with max_iterations > 0: the template far from the scan,
/// markers off it; the message gives both bounding boxes); Cancelled. On an exception `result`
/// and `status` are left as they were. A markerless alignment that turned the template by more
/// than 30° or scaled it outside [2/3, 1.5] is fitted, with a warning in FitReport::message; so is
/// a result with more than 1 % of its edges (beyond the template's own) folded back by over 120°.
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
