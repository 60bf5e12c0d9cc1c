// Set-up of a fit: the cloud (finite points, ROI, normals), derived parameters, markers, mask.
#include <algorithm>
#include <cmath>

#include "fit_state.h"
#include "tbsp/core/error.h"
#include "tbsp/core/logging.h"
#include "tbsp/core/timer.h"
#include "tbsp/mesh/point_normals.h"

namespace tbsp {
namespace fit_impl {
namespace {

bool inside(const Eigen::Vector3d& p, const std::vector<Sphere>& s, const std::vector<Box>& b) {
  for (const auto& x : s)
    if ((p - x.center).norm() <= x.radius) return true;
  for (const auto& x : b)
    if ((p.array() >= x.min.array()).all() && (p.array() <= x.max.array()).all()) return true;
  return false;
}

// The automatic values (0 = derive from the data) of the parameters used.
void derive_parameters(FitState& s, const FitParameters& params) {
  FitParameters& u = s.u;
  u = params;
  const double diag = s.cloud.diag;
  if (u.max_match_distance == 0) u.max_match_distance = std::max(3 * s.rep.point_spacing, 0.005 * diag);
  if (u.initial_match_distance == 0) u.initial_match_distance = std::max(u.max_match_distance, 0.03 * diag);
  if (u.tolerance == 0) u.tolerance = 2e-4 * diag;
  if (u.detail_tolerance == 0) u.detail_tolerance = 0.5 * u.tolerance;
  if (u.subdivision_error == 0) u.subdivision_error = 0.0015 * diag;
  if (u.remeshing && !u.laplacian_updating) {
    u.laplacian_updating = true;
    s.rep.message += "remeshing implies Laplacian updating (enabled). ";
  }
  s.cos_max = std::cos(u.max_normal_angle_deg * M_PI / 180.0);
}

}  // namespace

void FitState::addMarkers(LaplacianDeformer& d, double weight) const {
  for (std::size_t k = 0; k < markers.size(); ++k) {
    DeformConstraint c;
    c.at = SurfacePoint::atVertex(mverts[k]);
    c.target = mtarget[k];
    c.weight = weight * markers[k].weight;
    c.rotation = markers[k].rotation;
    d.addConstraint(c);
  }
}

const Eigen::MatrixX3d& FitState::consistentNormals() {
  if (!rep.normals_estimated || u.consistent_normals) return N;
  if (!nc_ready_) {
    NC_ = N;
    orient_normals_consistently(cloud.search, NC_, Eigen::VectorXd::Ones(cloud.np), u.normal_neighbours);
    nc_ready_ = true;
  }
  return NC_;
}

PreparedCloud prepare_cloud(const Eigen::MatrixX3d& P_in, const Eigen::MatrixX3d& N_in, const RegionOfInterest& roi,
                            int normal_neighbours) {
  const std::string who = kWho;
  PreparedCloud c;
  // ---- finite points, ROI
  c.points_total = P_in.rows();
  std::vector<Eigen::Index> compact(std::size_t(P_in.rows()), -1);
  std::vector<Eigen::Index> keep;
  keep.reserve(std::size_t(P_in.rows()));
  for (Eigen::Index i = 0; i < P_in.rows(); ++i)
    if (P_in.row(i).allFinite() && (N_in.rows() == 0 || (N_in.row(i).allFinite() && N_in.row(i).norm() > 0))) {
      compact[std::size_t(i)] = Eigen::Index(keep.size());
      keep.push_back(i);
    }
  c.points_skipped_nonfinite = P_in.rows() - Eigen::Index(keep.size());
  if (keep.empty()) {
    Eigen::Index nonfinite = 0;
    for (Eigen::Index i = 0; i < P_in.rows(); ++i) nonfinite += !P_in.row(i).allFinite();
    if (nonfinite == P_in.rows())
      throw InvalidInput(who + "the input cloud has no finite points (all " + std::to_string(P_in.rows()) + " are NaN/Inf)");
    // finite points whose normals are unusable: given that way, or estimated from too few
    // neighbours or from coordinates whose squares overflow single precision (|x| > ~1e19)
    throw InvalidInput(who + "no point of the input cloud has a usable normal (" + std::to_string(P_in.rows() - nonfinite) +
                       " finite points, every normal NaN/Inf or zero); give finite unit normals, or for normals "
                       "estimated from the points: enough neighbours per point and coordinates in a sane unit (metres, "
                       "millimetres)");
  }
  const Eigen::Index np = c.np = Eigen::Index(keep.size());
  Eigen::MatrixX3d& P = c.P;
  P.resize(np, 3);
  for (Eigen::Index i = 0; i < np; ++i) P.row(i) = P_in.row(keep[std::size_t(i)]);
  std::vector<char>& roi_ok = c.roi_ok;
  roi_ok.assign(std::size_t(np), 1);
  for (Eigen::Index e : roi.exclude_cloud_points) {
    if (e < 0 || e >= P_in.rows())
      throw InvalidInput(who + "ROI excludes cloud point " + std::to_string(e) + " but the cloud has " +
                         std::to_string(P_in.rows()) + " points");
    if (compact[std::size_t(e)] >= 0) roi_ok[std::size_t(compact[std::size_t(e)])] = 0;
  }
  for (Eigen::Index i = 0; i < np; ++i)
    if (inside(P.row(i).transpose(), roi.exclude_cloud_spheres, roi.exclude_cloud_boxes)) roi_ok[std::size_t(i)] = 0;
  c.points_excluded = np - std::count(roi_ok.begin(), roi_ok.end(), 1);
  c.lo = Eigen::Vector3d::Constant(1e300);
  c.hi = -c.lo;
  for (Eigen::Index i = 0; i < np; ++i)
    if (roi_ok[std::size_t(i)]) {
      c.lo = c.lo.cwiseMin(P.row(i).transpose());
      c.hi = c.hi.cwiseMax(P.row(i).transpose());
    }
  if (c.points_excluded == np) throw InvalidInput(who + "the region of interest excludes every cloud point");
  c.diag = (c.hi - c.lo).norm();
  if (!(c.diag > 0)) throw InvalidInput(who + "the cloud's points all coincide; nothing to fit");
  // ---- search tree, spacing, normals
  auto t0 = Clock::now();
  c.search = PointSearch(P);
  c.spacing = median_spacing(c.search);
  c.t_search = seconds_since(t0);
  t0 = Clock::now();
  if (N_in.rows() == 0) {
    c.N = estimate_normals_pca(c.search, normal_neighbours);
    c.normals_estimated = true;
  } else {
    c.N.resize(np, 3);
    for (Eigen::Index i = 0; i < np; ++i) c.N.row(i) = N_in.row(keep[std::size_t(i)]).normalized();
  }
  c.t_normals = seconds_since(t0);
  return c;
}

void use_cloud(FitState& s, const FitParameters& params, bool orient_normals) {
  const PreparedCloud& c = s.cloud;
  FitReport& rep = s.rep;
  rep.points_total = c.points_total;
  rep.points_skipped_nonfinite = c.points_skipped_nonfinite;
  rep.points_excluded = c.points_excluded;
  rep.bbox_diagonal = c.diag;
  rep.point_spacing = c.spacing;
  rep.t_search = c.t_search;
  rep.t_normals = c.t_normals;
  rep.normals_estimated = c.normals_estimated;
  s.orient = orient_normals || c.normals_estimated;
  derive_parameters(s, params);
}

void prepare_markers(FitState& s, const Eigen::MatrixX3d& P_in, const RegionOfInterest& roi) {
  const std::string who = kWho;
  const auto& markers = s.markers;
  const Eigen::Index nv0 = s.templ().V.rows();
  for (std::size_t k = 0; k < markers.size(); ++k) {
    const auto& m = markers[k];
    const std::string w = who + "marker " + std::to_string(k) + ": ";
    if (m.template_vertex < 0 || m.template_vertex >= nv0)
      throw InvalidInput(w + "template vertex " + std::to_string(m.template_vertex) + " does not exist (template has " +
                         std::to_string(nv0) + " vertices)");
    if (!(m.weight > 0 && std::isfinite(m.weight))) throw InvalidInput(w + "weight must be > 0");
    Eigen::Vector3d t;
    if (m.cloud_index >= 0) {
      if (m.cloud_index >= P_in.rows())
        throw InvalidInput(w + "cloud point " + std::to_string(m.cloud_index) + " does not exist (cloud has " +
                           std::to_string(P_in.rows()) + " points)");
      if (!P_in.row(m.cloud_index).allFinite())
        throw InvalidInput(w + "cloud point " + std::to_string(m.cloud_index) + " is NaN/Inf; pick another point");
      t = P_in.row(m.cloud_index).transpose();
    } else {
      if (!m.position.allFinite()) throw InvalidInput(w + "needs a cloud_index or a finite free position");
      t = m.position;
      // a free marker far outside the data poses the template away from it (and blows up the
      // global scale): legal, but almost always a unit or typing mistake
      const double out = (t - t.cwiseMax(s.cloud.lo).cwiseMin(s.cloud.hi)).norm();
      if (out > s.rep.bbox_diagonal) {
        const std::string msg = "marker " + std::to_string(k) + "'s free position lies " +
                                std::to_string(out / s.rep.bbox_diagonal) +
                                " cloud diagonals outside the cloud's bounding box (check its units). ";
        s.rep.message += msg;
        logger()->warn("[TemplateFitting] {}", msg);
      }
    }
    s.mtarget.push_back(t);
    s.mverts.push_back(m.template_vertex);
  }
  // ---- template mask
  s.masked.assign(std::size_t(nv0), 0);
  for (int v : roi.exclude_template_vertices) {
    if (v < 0 || v >= nv0)
      throw InvalidInput(who + "ROI excludes template vertex " + std::to_string(v) + " but the template has " +
                         std::to_string(nv0) + " vertices");
    s.masked[std::size_t(v)] = 1;
  }
  for (Eigen::Index v = 0; v < nv0; ++v)
    if (inside(s.templ().V.row(v).transpose(), roi.exclude_template_spheres, roi.exclude_template_boxes))
      s.masked[std::size_t(v)] = 1;
  if (nv0 > 0 && std::all_of(s.masked.begin(), s.masked.end(), [](char c) { return c != 0; }))
    throw InvalidInput(who + "the region of interest excludes every template vertex: nothing would be fitted to the data; "
                             "shrink the template exclusions (exclude_template_*)");
}

}  // namespace fit_impl

int FitParameters::resolvedDetailRounds(Eigen::Index template_vertices) const {
  if (detail_rounds != -1) return detail_rounds;
  return !laplacian_updating && !remeshing && template_vertices <= kAutoDetailVertices ? 4 : 0;
}

bool FitParameters::isValid(std::string* why) const {
  auto bad = [&](const std::string& m) { if (why) *why = m; return false; };
  if (!(max_match_distance >= 0)) return bad("max_match_distance must be >= 0 (0 = automatic)");
  if (!(initial_match_distance >= 0)) return bad("initial_match_distance must be >= 0 (0 = automatic)");
  if (!(max_normal_angle_deg > 0 && max_normal_angle_deg <= 180)) return bad("max_normal_angle_deg must be in (0, 180]");
  if (max_iterations < 0 || max_iterations > 1000) return bad("max_iterations must be in 0..1000");
  if (!(tolerance >= 0)) return bad("tolerance must be >= 0 (0 = automatic)");
  if (radius_steps < 0 || radius_steps > 100) return bad("radius_steps must be in 0..100");
  if (freeze_iteration < 0) return bad("freeze_iteration must be >= 0 (0 = when r reaches max_match_distance)");
  if (!(relaxation >= 1 && relaxation < 2)) return bad("relaxation must be in [1, 2)");
  if (!(rim_rejection > 0 && rim_rejection <= 1)) return bad("rim_rejection must be in (0, 1]");
  if (!(marker_weight > 0) || !(match_weight > 0) || !(propagation_weight > 0) || !(updating_match_weight > 0))
    return bad("weights must be > 0");
  if (!(subdivision_error >= 0)) return bad("subdivision_error must be >= 0 (0 = automatic)");
  if (!(fairing_lambda > 0 && fairing_lambda <= 1)) return bad("fairing_lambda must be in (0, 1]");
  if (fairing_steps < 0) return bad("fairing_steps must be >= 0");
  if (detail_rounds < -1 || detail_rounds > 100) return bad("detail_rounds must be in -1..100 (-1 = automatic)");
  if (pull_rounds < 0 || pull_rounds > 100) return bad("pull_rounds must be in 0..100");
  if (detail_iterations < 1 || detail_iterations > 1000) return bad("detail_iterations must be in 1..1000");
  if (!(detail_weight > 0)) return bad("detail_weight must be > 0");
  if (!(detail_marker_weight > 0)) return bad("detail_marker_weight must be > 0");
  if (!(detail_radius_factor >= 0.5 && detail_radius_factor <= 10)) return bad("detail_radius_factor must be in [0.5, 10]");
  if (!(detail_normal_angle_deg > 0 && detail_normal_angle_deg <= 180)) return bad("detail_normal_angle_deg must be in (0, 180]");
  if (!(detail_tolerance >= 0)) return bad("detail_tolerance must be >= 0 (0 = tolerance / 2)");
  if (!(support_points >= 0)) return bad("support_points must be >= 0 (0 = off)");
  if (!(detail_surface_weight >= 0)) return bad("detail_surface_weight must be >= 0 (0 = off)");
  if (normal_neighbours < 3) return bad("normal_neighbours must be >= 3");
  if (max_vertices < 4) return bad("max_vertices must be >= 4");
  if (auto_markers < 0 || auto_markers > 1000) return bad("auto_markers must be in 0..1000 (0 = one pass)");
  if (coarse_nodes != 0 && coarse_nodes != -1 && (coarse_nodes < 4 || coarse_nodes > 20000))
    return bad("coarse_nodes must be -1 (automatic), 0 (off) or in 4..20000");
  for (int c : coarse_prepass_nodes)
    if (c < 4 || c > 20000)
      return bad("coarse_prepass_nodes: each entry must be in 4..20000 (" + std::to_string(c) + " given; an empty list = one hypothesis)");
  if (coarse_rounds < 1 || coarse_rounds > 100) return bad("coarse_rounds must be in 1..100");
  if (coarse_steps < 1 || coarse_steps > 100) return bad("coarse_steps must be in 1..100");
  if (!(coarse_radius > 0 && coarse_radius <= 1)) return bad("coarse_radius must be in (0, 1] (a fraction of the diagonal)");
  if (!(coarse_stiffness > 0 && std::isfinite(coarse_stiffness)) || !(coarse_final_stiffness > 0 && std::isfinite(coarse_final_stiffness)))
    return bad("coarse_stiffness and coarse_final_stiffness must be > 0");
  if (!(coarse_normal_angle_deg > 0 && coarse_normal_angle_deg <= 180)) return bad("coarse_normal_angle_deg must be in (0, 180]");
  if (!(coarse_point_weight >= 0 && std::isfinite(coarse_point_weight))) return bad("coarse_point_weight must be >= 0");
  return true;
}

}  // namespace tbsp
