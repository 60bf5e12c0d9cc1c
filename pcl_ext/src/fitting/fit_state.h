#pragma once
// Internal: the state the stages of fit_template share (template_fitter.cpp runs them in order).
// One stage per file:
//   fit_setup.cpp        finite points, ROI, normals, derived parameters, markers, template mask
//   fit_alignment.cpp    without markers: similarity alignment (trimmed ICP with scale)
//   fit_initial.cpp      stage 1: initial deformation from the markers, global scale (§5.2);
//                        orientation of estimated normals by the posed template
//   fit_coarse.cpp       coarse stage: stiffness-annealed non-rigid ICP of a deformation graph
//   fit_matching.cpp     the §5.3 kernel: matching every vertex against the cloud
//   fit_iterate.cpp      stage 2: the iterative fit (matching, constraints, solve, convergence)
//   fit_surface_steps.cpp  §5.5 inside the iterations: adaptive subdivision, tangential fairing
//   fit_propagation.cpp  stage 3: displacement propagation (§5.3 end)
//   fit_detail.cpp       detail rounds (Laplacian updating after the fit)
//   fit_repair.cpp       fold repair, pleat collapse, self-intersection repair (§5.5.3)
//   fit_metrics.cpp      distances, fold and intersection counts for the report
// Not installed; nothing here is public API.

#include <Eigen/Core>
#include <Eigen/SparseCore>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "tbsp/core/progress.h"
#include "tbsp/deform/laplacian_deformer.h"
#include "tbsp/fitting/template_fitter.h"
#include "tbsp/mesh/harmonic.h"
#include "tbsp/mesh/point_search.h"
#include "tbsp/mesh/similarity_icp.h"
#include "tbsp/mesh/tri_mesh.h"

namespace tbsp {
namespace fit_impl {

/// Prefix of the fit's error messages.
inline constexpr const char* kWho = "[tbsp::TemplateFitting::reconstruct] ";

/// The input cloud as the stages use it (prepare_cloud): finite points, ROI, search tree, spacing
/// and normals (given, or PCA). It depends only on the cloud, the ROI and normal_neighbours, so
/// the passes and hypotheses of one fit without markers share one (fit_template).
struct PreparedCloud {
  Eigen::Index np = 0;        ///< finite points
  Eigen::MatrixX3d P, N;      ///< np rows; N unit, not yet oriented by the template
  std::vector<char> roi_ok;   ///< per point: inside the region of interest
  Eigen::Vector3d lo, hi;     ///< bounding box of the ROI points
  double diag = 0;            ///< its diagonal
  PointSearch search;         ///< over P
  double spacing = 0;         ///< median nearest-neighbour spacing
  bool normals_estimated = false;
  Eigen::Index points_total = 0, points_skipped_nonfinite = 0, points_excluded = 0;
  double t_search = 0, t_normals = 0;  ///< seconds the preparation took
};

/// Distances and closest faces of the ROI points to the shape V, F they were measured on
/// (roi_distances keeps them current).
struct RoiDistances {
  Eigen::MatrixX3d Q;  ///< the ROI points, in order (roi_points)
  Eigen::MatrixX3d V;  ///< the shape measured (no rows: none yet)
  Eigen::MatrixX3i F;
  Eigen::VectorXd d;   ///< per row of Q
  Eigen::VectorXi f;   ///< per row of Q: its closest face (the lowest index of equally close ones)
};

struct FitState {
  FitState(const TriMesh& t, const std::vector<FitMarker>& m, const ProgressCallback& p, FitReport& r,
           std::vector<VertexStatus>& st, const PreparedCloud& c)
      : markers(m), progress(p), rep(r), status(st), u(r.used), cloud(c), N(c.N), templ_(&t) {}
  /// A second fit continuing from `o`'s state (the same template, markers and cloud), reporting
  /// to `r` / `st` (copies of o's report and status) and `p`. Everything is copied except the
  /// deformer: D starts empty, so the next stage must set it up (coarse_stage does: its mesh,
  /// scale and rotations; iterate_fit its constraints); it takes o's solver analysis, which its
  /// systems on the same connectivity reuse (~0.15 s on 43k vertices, same factors).
  FitState(const FitState& o, const ProgressCallback& p, FitReport& r, std::vector<VertexStatus>& st)
      : markers(o.markers), progress(p), rep(r), status(st), u(r.used), cloud(o.cloud), N(o.N), orient(o.orient),
        cos_max(o.cos_max), mtarget(o.mtarget), mverts(o.mverts), masked(o.masked), V(o.V), V0(o.V0), F(o.F),
        matched(o.matched), target(o.target), prop_ids(o.prop_ids), propagation_handled(o.propagation_handled),
        coarse(o.coarse), roi_dist(o.roi_dist), coarse_prepass(o.coarse_prepass), markers_from_fit(o.markers_from_fit),
        alignment_cache(o.alignment_cache), templ_(o.templ_), NC_(o.NC_), nc_ready_(o.nc_ready_) {
    D.copySolverAnalysis(o.D);
  }

  const std::vector<FitMarker>& markers;
  const ProgressCallback& progress;
  FitReport& rep;
  std::vector<VertexStatus>& status;
  FitParameters& u;  ///< the parameters used (rep.used: automatic values filled in)

  // the cloud (finite points only: cloud.P and N have cloud.np rows), cloud.roi_ok per point;
  // shared, read-only, except N: this fit's copy of cloud.N, oriented by its posed template
  // (orient_cloud_normals)
  const PreparedCloud& cloud;
  Eigen::MatrixX3d N;
  bool orient = false;  ///< orient N by the posed template (estimated or unreliable normals)
  double cos_max = 0;   ///< cos θ_max

  // markers (template vertex -> target) and the template mask
  std::vector<Eigen::Vector3d> mtarget;
  std::vector<int> mverts;
  std::vector<char> masked;

  // the fit
  LaplacianDeformer D;
  Eigen::MatrixX3d V;   ///< current shape
  Eigen::MatrixX3d V0;  ///< initial deformation (stage 1), extended by subdivision
  Eigen::MatrixX3i F;
  std::vector<char> matched;
  Eigen::MatrixX3d target;
  std::vector<int> prop_ids;         ///< per vertex: id of its propagated constraint (-1: none)
  bool propagation_handled = false;  ///< propagation decided in the loop (done or skipped for good)
  TriMesh coarse;                    ///< the coarse stage's result: the rest shape of the later stages
  RoiDistances roi_dist;             ///< the last ROI point distances measured (roi_distances)
  /// nodes of a coarser graph the coarse stage fits first (the later hypotheses of a fit
  /// without markers, FitParameters::coarse_prepass_nodes); 0: the coarse_nodes graph alone
  int coarse_prepass = 0;
  /// the markers are the matched vertices of an aligned first pass (the second pass of a fit
  /// without markers), not the user's
  bool markers_from_fit = false;
  /// The similarity alignment of a fit without markers, shared by the passes and hypotheses of
  /// one fit_template call (they align the same template to the same cloud): empty until the
  /// first computes it; nullptr: not shared.
  std::optional<SimilarityIcpResult>* alignment_cache = nullptr;

  /// The template the stages fit: the user's, or its similarity alignment when there are no
  /// markers (align_without_markers).
  const TriMesh& templ() const { return *templ_; }
  void useTemplate(const TriMesh& t) { templ_ = &t; }
  /// The markers as constraints of d (weight × each marker's own weight).
  void addMarkers(LaplacianDeformer& d, double weight) const;
  /// Cloud normals for the fold-over checks: estimated normals made consistent (once, on first
  /// use) unless the fit already did.
  const Eigen::MatrixX3d& consistentNormals();

 private:
  const TriMesh* templ_;
  Eigen::MatrixX3d NC_;
  bool nc_ready_ = false;
};

// ---- fit_setup.cpp
/// Finite points, ROI, search tree, spacing, normals (given, or PCA with `normal_neighbours`).
/// Throws InvalidInput naming the problem (no finite point, ROI excludes all, one point).
PreparedCloud prepare_cloud(const Eigen::MatrixX3d& P_in, const Eigen::MatrixX3d& N_in, const RegionOfInterest& roi,
                            int normal_neighbours);
/// The report's cloud fields, whether to orient the normals, and the derived parameters.
void use_cloud(FitState& s, const FitParameters& params, bool orient_normals);
/// Marker targets and the template mask; throws InvalidInput naming the marker / vertex.
void prepare_markers(FitState& s, const Eigen::MatrixX3d& P_in, const RegionOfInterest& roi);

// ---- fit_alignment.cpp
/// Without markers: similarity alignment of s.templ() to the cloud by trimmed ICP (cloud ->
/// template, Umeyama); writes the aligned template and the report's alignment fields.
void align_without_markers(FitState& s, TriMesh& aligned);
/// The similarity alignment of the template vertices V to the cloud's ROI points that
/// align_without_markers applies (FitState::alignment_cache holds it once computed).
SimilarityIcpResult similarity_alignment(const PreparedCloud& c, const Eigen::MatrixX3d& V);
/// A warning (text ending in a space) when the alignment turned the template by more than 30° or
/// scaled it outside [2/3, 1.5]: beyond a template roughly in place; empty otherwise.
std::string alignment_warning(const SimilarityIcpResult& r);

// ---- fit_initial.cpp
/// Stage 1: initial deformation from the markers, global scale; sets V, V0, F; freezes the field.
void initial_pose(FitState& s);
/// Estimated normals point away from the posed template (and are made consistent if asked).
void orient_cloud_normals(FitState& s);

// ---- fit_coarse.cpp
/// Coarse stage (FitParameters::coarse_nodes > 0): embedded deformation graph non-rigid ICP
/// from s.V; sets s.V, s.V0 and the Laplacian's rotations.
void coarse_stage(FitState& s);

// ---- fit_matching.cpp
/// Per-vertex cloud neighbours cached in the frozen phase (see fit_iterate.cpp).
struct NeighbourCache {
  std::vector<std::vector<std::pair<Eigen::Index, double>>> nb;
  Eigen::MatrixX3d at;
  std::vector<double> r;
};
/// The §5.3 kernel targets at radius r for every vertex of s.V (only the frozen set when
/// frozen_phase): s.target, s.matched and match_scale (weight factors) are set. Returns whether
/// the binned cloud was used.
bool match_vertices(FitState& s, double r, bool frozen_phase, const std::vector<int>& frozen_ids, NeighbourCache& cache,
                    Eigen::VectorXd& match_scale);
/// Target of §5.3 from kernel-weighted sums (Σw, Σw p, Σw ppᵀ); see fit_matching.cpp.
Eigen::Vector3d kernel_target(const Eigen::Vector3d& vj, const Eigen::Vector3d& nj, double sw, const Eigen::Vector3d& sp,
                              const Eigen::Matrix3d& spp, bool plane_fit, double in_ball, double* tangential_offset);
/// Kernel sums over the cloud points nb within radius rr of a vertex with normal nj.
void kernel_sums(const std::vector<std::pair<Eigen::Index, double>>& nb, const Eigen::MatrixX3d& P, const Eigen::MatrixX3d& N,
                 const std::vector<char>& roi_ok, const Eigen::Vector3d& nj, double cos_max, double rr, double& sw,
                 Eigen::Vector3d& sp, Eigen::Matrix3d& spp, double* sw2 = nullptr);
/// 99th percentile of |A_j - B_j| over the rows j with use[j] (0 when none).
double percentile99_move(const Eigen::MatrixX3d& A, const Eigen::MatrixX3d& B, const std::vector<char>& use);

// ---- fit_iterate.cpp
/// Stage 2: the iterative fit. Returns whether it converged.
bool iterate_fit(FitState& s);
/// A mesh component without a marker or a matched vertex (a part the scan does not see, e.g. a
/// hand behind the body in one frame of a replay) would be free to translate: the system is
/// singular. It keeps its place instead: one weak constraint (propagation_weight) at its vertex
/// nearest its centroid holds it at X + offset; its shape still follows δ and the rotation field.
/// Adds the constraints to s.D (positions X, faces F); matched vertices hold their component
/// when `use_matches` (s.matched may be empty), markers always.
void anchor_free_components(FitState& s, const Eigen::MatrixX3d& X, const Eigen::MatrixX3i& F, const Eigen::Vector3d& offset,
                            bool use_matches);

// ---- fit_surface_steps.cpp
/// Adaptive 1-to-4 subdivision of faces whose data error exceeds ε (§5.5.2). Returns whether
/// the mesh changed.
bool remesh_step(FitState& s, double r);
/// Tangential area-weighted fairing of matched vertices along the cloud normals (eq. 5.1-5.2).
void fairing_step(FitState& s, double r);

// ---- fit_propagation.cpp
/// Displacement propagation inside the frozen iterations.
struct Propagation {
  HarmonicInterpolator harmonic;
  std::vector<int> sources;  ///< the matched vertices the interpolation starts from
  Eigen::MatrixX3d N0;       ///< normals of the initial deformation
  bool in_loop = false;      ///< propagated constraints are in the frozen system
  /// Normal displacements of the sources relative to V0, harmonically interpolated, as targets.
  Eigen::MatrixX3d targets(const Eigen::MatrixX3d& X, const Eigen::MatrixX3d& V0) const;
};
/// Adds the propagated constraints to the frozen system (s.D) when the set is frozen.
void start_propagation(FitState& s, Propagation& p);
/// Moves the propagated constraints' targets with the current shape.
void update_propagation(FitState& s, const Propagation& p);
/// Stage 3: vertex status, and the separate propagation solve when the loop did not do it.
void propagate_displacements(FitState& s);

// ---- fit_detail.cpp
void detail_rounds(FitState& s);
// Pull rounds (FitParameters::pull_rounds): detail rounds that move only the vertices near the
// regions the fit leaves unexplained, run when no detail rounds are asked for.
void pull_rounds(FitState& s);

// ---- fit_repair.cpp
/// Faces whose normal is more than 120° against the normal NR of the cloud point nearest to
/// their centre (within max_match_distance, ROI).
int flipped_faces(const FitState& s, const Eigen::MatrixX3d& X, const Eigen::MatrixX3d& NR);
/// Edges whose two faces are bent back by more than 120°; marks their vertices when mark.
int folded_edges(const Eigen::MatrixX3i& F, const Eigen::MatrixX3d& X, std::vector<char>* mark);
/// Fold repair, pleat collapse, self-intersection repair. Returns the self-intersection count
/// when it is known without counting again (0), else -1.
int repair_surface(FitState& s);

// ---- fit_metrics.cpp
void compute_metrics(FitState& s, int known_crossings);
/// The cloud's ROI points, in order.
Eigen::MatrixX3d roi_points(const PreparedCloud& c);
/// Whether at least 4 other points of the cloud lie within 3 × its median spacing of the cloud
/// point q: a point of a sampled surface, not an isolated one (a stray outlier, which no fit
/// explains). O(log n).
bool is_surface_point(const PreparedCloud& c, const Eigen::Vector3d& q);
/// Distances and closest faces of the ROI points to the current shape s.V, s.F: exactly what
/// point_mesh_distances gives, measured again only where the shape moved since the last call
/// (update_point_mesh_distances; all of it when F changed or over a quarter of the vertices moved).
const RoiDistances& roi_distances(FitState& s);
/// FitReport::tail_mean of ROI point distances (in any order; reordered here): the mean of the
/// largest 1 % (at least one; 0 for none), summed in ascending order.
double tail_mean(std::vector<double> d);
/// Points in the regions (sum of their counts).
Eigen::Index unexplained_points(const std::vector<FitReport::UnexplainedRegion>& regions);
/// FitReport::unexplained of the ROI points Q and their distances to the result. `member`
/// (optional): per row of Q, the index of the returned region it belongs to, or -1.
std::vector<FitReport::UnexplainedRegion> unexplained_regions(const Eigen::MatrixX3d& Q, const Eigen::VectorXd& dist, double diag,
                                                              double r_max, std::vector<int>* member = nullptr);

}  // namespace fit_impl
}  // namespace tbsp
