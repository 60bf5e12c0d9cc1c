#include "tbsp/fitting/template_fitter.h"

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <numeric>
#include <optional>
#include <set>
#include <unordered_map>

#include "tbsp/core/error.h"
#include "tbsp/core/timer.h"
#include "tbsp/core/logging.h"
#include "tbsp/deform/laplacian_deformer.h"
#include "tbsp/deform/rotation_field.h"
#include "tbsp/deform/rotations.h"
#include "tbsp/mesh/cotan_laplacian.h"
#include "tbsp/mesh/geodesics.h"
#include "tbsp/mesh/mesh_validation.h"
#include "tbsp/mesh/point_mesh_distance.h"
#include "tbsp/mesh/point_normals.h"
#include "tbsp/mesh/point_search.h"
#include "tbsp/mesh/remeshing.h"
#include "tbsp/mesh/topology.h"
#include "tbsp/solve/blas_threads.h"
#include "tbsp/mesh/harmonic.h"

namespace tbsp {

namespace {

bool inside(const Eigen::Vector3d& p, const std::vector<Sphere>& s, const std::vector<Box>& b) {
  for (const auto& x : s)
    if ((p - x.center).norm() <= x.radius) return true;
  for (const auto& x : b)
    if ((p.array() >= x.min.array()).all() && (p.array() <= x.max.array()).all()) return true;
  return false;
}

// PCA normals over k nearest neighbours (unoriented).
Eigen::MatrixX3d pca_normals(const PointSearch& tree, int k) {
  const Eigen::MatrixX3d& P = tree.points();
  Eigen::MatrixX3d N(P.rows(), 3);
#pragma omp parallel
  {
    std::vector<Eigen::Index> idx;
    std::vector<double> d2;
#pragma omp for schedule(dynamic, 512)
    for (Eigen::Index i = 0; i < P.rows(); ++i) {
      tree.knn(P.row(i).transpose(), k, idx, d2);
      Eigen::Vector3d mean = Eigen::Vector3d::Zero();
      for (auto j : idx) mean += P.row(j).transpose();
      mean /= double(std::max<std::size_t>(idx.size(), 1));
      Eigen::Matrix3d C = Eigen::Matrix3d::Zero();
      for (auto j : idx) {
        const Eigen::Vector3d d = P.row(j).transpose() - mean;
        C += d * d.transpose();
      }
      Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(C);
      N.row(i) = es.eigenvectors().col(0).transpose();
    }
  }
  return N;
}

// The cloud summarised on a grid for matching at large radii: per (voxel, normal octant) bin
// the point count, the sums of p and p pᵀ and the mean normal. The kernel-weighted mean and
// covariance of §5.3 over a ball of radius r ≥ 4 h are then sums over bins (the kernel taken at
// the bin centroid, exact within O((h/r)²)), at a fraction of the neighbour visits. The octant
// split keeps the two sides of thin parts apart, so the normal test still works per bin.
struct BinnedCloud {
  Eigen::MatrixX3d centroid, normal, sum_p;
  std::vector<Eigen::Matrix3d> sum_pp;
  Eigen::VectorXd count;
  PointSearch search;
};

BinnedCloud bin_cloud(const Eigen::MatrixX3d& P, const Eigen::MatrixX3d& N, const std::vector<char>& use, double h) {
  Eigen::Vector3d lo = Eigen::Vector3d::Constant(1e300);
  for (Eigen::Index i = 0; i < P.rows(); ++i)
    if (use[std::size_t(i)]) lo = lo.cwiseMin(P.row(i).transpose());
  std::unordered_map<std::uint64_t, int> bin_of;
  bin_of.reserve(std::size_t(P.rows()));
  std::vector<int> bin(std::size_t(P.rows()), -1);
  int nb = 0;
  for (Eigen::Index i = 0; i < P.rows(); ++i) {
    if (!use[std::size_t(i)]) continue;
    const Eigen::Vector3d c = ((P.row(i).transpose() - lo) / h).array().floor();
    const std::uint64_t oct = (N(i, 0) < 0 ? 1u : 0u) | (N(i, 1) < 0 ? 2u : 0u) | (N(i, 2) < 0 ? 4u : 0u);
    const std::uint64_t key = (std::uint64_t(c.x()) & 0x1FFFFF) | ((std::uint64_t(c.y()) & 0x1FFFFF) << 21) |
                              ((std::uint64_t(c.z()) & 0x1FFFFF) << 42) | (oct << 61);
    const auto [it, fresh] = bin_of.emplace(key, nb);
    if (fresh) ++nb;
    bin[std::size_t(i)] = it->second;
  }
  BinnedCloud b;
  b.sum_p = Eigen::MatrixX3d::Zero(nb, 3);
  b.normal = Eigen::MatrixX3d::Zero(nb, 3);
  b.sum_pp.assign(std::size_t(nb), Eigen::Matrix3d::Zero());
  b.count = Eigen::VectorXd::Zero(nb);
  for (Eigen::Index i = 0; i < P.rows(); ++i) {
    const int k = bin[std::size_t(i)];
    if (k < 0) continue;
    const Eigen::Vector3d p = P.row(i).transpose();
    b.sum_p.row(k) += p.transpose();
    b.sum_pp[std::size_t(k)] += p * p.transpose();
    b.normal.row(k) += N.row(i);
    b.count(k) += 1;
  }
  b.centroid = b.sum_p.array().colwise() / b.count.array();
  for (Eigen::Index k = 0; k < nb; ++k) {
    const double len = b.normal.row(k).norm();
    if (len > 0) b.normal.row(k) /= len;
  }
  b.search = PointSearch(b.centroid);
  return b;
}


/// Target of §5.3 from kernel-weighted sums over a vertex's neighbourhood (Σw, Σw p, Σw ppᵀ):
/// the weighted mean, or with `plane_fit` where the vertex's normal line meets the weighted
/// least-squares plane (if well defined). Also returns the tangential offset of the mean from
/// the normal line (the rim test). \pre sw > 0.
Eigen::Vector3d kernel_target(const Eigen::Vector3d& vj, const Eigen::Vector3d& nj, double sw, const Eigen::Vector3d& sp,
                              const Eigen::Matrix3d& spp, bool plane_fit, double in_ball, double* tangential_offset) {
  Eigen::Vector3d q = sp / sw;  // weighted average of §5.3
  *tangential_offset = ((q - vj) - (q - vj).dot(nj) * nj).norm();
  if (plane_fit && in_ball >= 6) {
    // weighted plane through q: the normal line of the vertex meets it at the projection
    // (unbiased for one-sided neighbourhoods at the rim of the data)
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(spp / sw - q * q.transpose());
    Eigen::Vector3d m = es.eigenvectors().col(0);
    if (m.dot(nj) < 0) m = -m;
    if (m.dot(nj) > 0.7 && es.eigenvalues()(1) > 4 * es.eigenvalues()(0)) q = vj + ((q - vj).dot(m) / m.dot(nj)) * nj;
    else q = vj + (q - vj).dot(nj) * nj;
  }
  return q;
}

/// Kernel sums over the cloud points `nb` (index, squared distance) within radius rr of a vertex
/// with normal nj: ROI points whose normals deviate at most θ_max (cos_max).
void kernel_sums(const std::vector<std::pair<Eigen::Index, double>>& nb, const Eigen::MatrixX3d& P, const Eigen::MatrixX3d& N,
                 const std::vector<char>& roi_ok, const Eigen::Vector3d& nj, double cos_max, double rr, double& sw,
                 Eigen::Vector3d& sp, Eigen::Matrix3d& spp, double* sw2 = nullptr) {
  for (const auto& [k, d2] : nb) {
    if (!roi_ok[std::size_t(k)] || N.row(k).dot(nj) < cos_max) continue;
    const double w = bspline_weight(std::sqrt(d2) / rr);
    const Eigen::Vector3d pk = P.row(k).transpose();
    sw += w;
    if (sw2) *sw2 += w * w;
    sp += w * pk;
    spp += w * pk * pk.transpose();
  }
}
}  // namespace

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
  if (detail_rounds < 0 || detail_rounds > 100) return bad("detail_rounds must be in 0..100");
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
  return true;
}

FitReport fit_template(const TriMesh& templ, const Eigen::MatrixX3d& P_in, const Eigen::MatrixX3d& N_in,
                       const std::vector<FitMarker>& markers, const RegionOfInterest& roi, const FitParameters& params,
                       TriMesh& result, std::vector<VertexStatus>& status, const ProgressCallback& progress,
                       bool orient_normals) {
  const std::string who = "[tbsp::TemplateFitting::reconstruct] ";
  const auto t_all = Clock::now();
  // one BLAS thread: no contention with our OpenMP loops (blas_threads.h)
  const ScopedBlasThreads blas_threads(1);
  FitReport rep;
  std::string why;
  if (!params.isValid(&why)) throw InvalidInput(who + "invalid parameters: " + why);
  MeshRequirements req;
  req.allow_nonmanifold = !params.remeshing;
  require_valid_mesh(templ, req, "tbsp::TemplateFitting::setInputTemplate");
  if (P_in.rows() == 0) throw InvalidInput(who + "the input cloud is empty; give a cloud with points");
  if (N_in.rows() != 0 && N_in.rows() != P_in.rows())
    throw InvalidInput(who + "the normals have " + std::to_string(N_in.rows()) + " rows for " +
                       std::to_string(P_in.rows()) + " points");
  report_progress(progress, 0.0, "prepare");
  // ---- finite points, ROI
  rep.points_total = P_in.rows();
  std::vector<Eigen::Index> compact(std::size_t(P_in.rows()), -1);
  std::vector<Eigen::Index> keep;
  keep.reserve(std::size_t(P_in.rows()));
  for (Eigen::Index i = 0; i < P_in.rows(); ++i)
    if (P_in.row(i).allFinite() && (N_in.rows() == 0 || (N_in.row(i).allFinite() && N_in.row(i).norm() > 0))) {
      compact[std::size_t(i)] = Eigen::Index(keep.size());
      keep.push_back(i);
    }
  rep.points_skipped_nonfinite = P_in.rows() - Eigen::Index(keep.size());
  if (keep.empty())
    throw InvalidInput(who + "the input cloud has no finite points (all " + std::to_string(P_in.rows()) + " are NaN/Inf)");
  const Eigen::Index np = Eigen::Index(keep.size());
  Eigen::MatrixX3d P(np, 3), N;
  for (Eigen::Index i = 0; i < np; ++i) P.row(i) = P_in.row(keep[std::size_t(i)]);
  std::vector<char> roi_ok(std::size_t(np), 1);
  for (Eigen::Index e : roi.exclude_cloud_points) {
    if (e < 0 || e >= P_in.rows())
      throw InvalidInput(who + "ROI excludes cloud point " + std::to_string(e) + " but the cloud has " +
                         std::to_string(P_in.rows()) + " points");
    if (compact[std::size_t(e)] >= 0) roi_ok[std::size_t(compact[std::size_t(e)])] = 0;
  }
  for (Eigen::Index i = 0; i < np; ++i)
    if (inside(P.row(i).transpose(), roi.exclude_cloud_spheres, roi.exclude_cloud_boxes)) roi_ok[std::size_t(i)] = 0;
  rep.points_excluded = np - std::count(roi_ok.begin(), roi_ok.end(), 1);
  Eigen::Vector3d cloud_lo = Eigen::Vector3d::Constant(1e300), cloud_hi = -cloud_lo;
  for (Eigen::Index i = 0; i < np; ++i)
    if (roi_ok[std::size_t(i)]) {
      cloud_lo = cloud_lo.cwiseMin(P.row(i).transpose());
      cloud_hi = cloud_hi.cwiseMax(P.row(i).transpose());
    }
  if (rep.points_excluded == np) throw InvalidInput(who + "the region of interest excludes every cloud point");
  rep.bbox_diagonal = (cloud_hi - cloud_lo).norm();
  const double diag = rep.bbox_diagonal;
  if (!(diag > 0)) throw InvalidInput(who + "the cloud's points all coincide; nothing to fit");
  auto t0 = Clock::now();
  const PointSearch search(P);
  rep.point_spacing = median_spacing(search);
  rep.t_search = seconds_since(t0);
  t0 = Clock::now();
  bool orient = orient_normals;
  if (N_in.rows() == 0) {
    N = pca_normals(search, params.normal_neighbours);
    rep.normals_estimated = orient = true;
  } else {
    N.resize(np, 3);
    for (Eigen::Index i = 0; i < np; ++i) N.row(i) = N_in.row(keep[std::size_t(i)]).normalized();
  }
  rep.t_normals = seconds_since(t0);
  // ---- derived parameters
  FitParameters& u = rep.used;
  u = params;
  if (u.max_match_distance == 0) u.max_match_distance = std::max(3 * rep.point_spacing, 0.005 * diag);
  if (u.initial_match_distance == 0) u.initial_match_distance = std::max(u.max_match_distance, 0.03 * diag);
  if (u.tolerance == 0) u.tolerance = 2e-4 * diag;
  if (u.detail_tolerance == 0) u.detail_tolerance = 0.5 * u.tolerance;
  if (u.subdivision_error == 0) u.subdivision_error = 0.0015 * diag;
  if (u.remeshing && !u.laplacian_updating) {
    u.laplacian_updating = true;
    rep.message += "remeshing implies Laplacian updating (enabled). ";
  }
  const double cos_max = std::cos(u.max_normal_angle_deg * M_PI / 180.0);
  // ---- markers
  if (markers.empty())
    throw InvalidInput(who + "no markers: give at least one template vertex <-> cloud point correspondence (3 or more "
                             "for the rotation field)");
  const Eigen::Index nv0 = templ.V.rows();
  std::vector<Eigen::Vector3d> mtarget;
  std::vector<int> mverts;
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
      if (!m.position.allFinite())
        throw InvalidInput(w + "needs a cloud_index or a finite free position");
      t = m.position;
      // a free marker far outside the data poses the template away from it (and blows up the
      // global scale): legal, but almost always a unit or typing mistake
      const double out = (t - t.cwiseMax(cloud_lo).cwiseMin(cloud_hi)).norm();
      if (out > rep.bbox_diagonal) {
        const std::string msg = "marker " + std::to_string(k) + "'s free position lies " + std::to_string(out / rep.bbox_diagonal) +
                                " cloud diagonals outside the cloud's bounding box (check its units). ";
        rep.message += msg;
        logger()->warn("[TemplateFitting] {}", msg);
      }
    }
    mtarget.push_back(t);
    mverts.push_back(m.template_vertex);
  }
  // ---- template mask
  std::vector<char> masked(std::size_t(nv0), 0);
  for (int v : roi.exclude_template_vertices) {
    if (v < 0 || v >= nv0)
      throw InvalidInput(who + "ROI excludes template vertex " + std::to_string(v) + " but the template has " +
                         std::to_string(nv0) + " vertices");
    masked[std::size_t(v)] = 1;
  }
  for (Eigen::Index v = 0; v < nv0; ++v)
    if (inside(templ.V.row(v).transpose(), roi.exclude_template_spheres, roi.exclude_template_boxes)) masked[std::size_t(v)] = 1;
  if (nv0 > 0 && std::all_of(masked.begin(), masked.end(), [](char c) { return c != 0; }))
    throw InvalidInput(who + "the region of interest excludes every template vertex: nothing would be fitted to the data; "
                             "shrink the template exclusions (exclude_template_*)");

  // ---- stage 1: initial deformation + global scale
  report_progress(progress, 0.05, "initial deformation");
  t0 = Clock::now();
  LaplacianDeformer D;
  D.setMesh(templ);
  auto add_markers = [&](LaplacianDeformer& d, double weight) {
    for (std::size_t k = 0; k < markers.size(); ++k) {
      DeformConstraint c;
      c.at = SurfacePoint::atVertex(mverts[k]);
      c.target = mtarget[k];
      c.weight = weight * markers[k].weight;
      c.rotation = markers[k].rotation;
      d.addConstraint(c);
    }
  };
  add_markers(D, u.marker_weight);
  bool field = u.rotation_field;
  if (field) {
    std::set<int> distinct(mverts.begin(), mverts.end());
    bool all_rot = std::all_of(markers.begin(), markers.end(), [](const FitMarker& m) { return bool(m.rotation); });
    if (distinct.size() < 3 && !all_rot) {
      field = false;
      rep.message += "rotation field skipped: it needs 3 or more markers (or marker rotations). ";
      logger()->warn("[TemplateFitting] fewer than 3 markers: no rotation field");
    }
  }
  D.setUseRotationField(field);
  Eigen::MatrixX3d V;
  try {
    V = D.deform();
  } catch (const InvalidInput& e) {
    throw InvalidInput(who + "the markers cannot pose the template: " + e.what());
  }
  rep.t_initial = seconds_since(t0);
  logger()->trace("[TemplateFitting] initial: {:.3f} s: setMesh+laplacian {:.3f}, graph {:.3f}, factorize {:.3f}, rotations {:.3f}, solve {:.3f}",
                  rep.t_initial, D.report().t_laplacian, D.report().t_graph, D.report().t_factorize, D.report().t_rotations, D.report().t_solve);
  t0 = Clock::now();
  double lambda = 1.0;
  if (u.estimate_scale) {
    std::set<int> distinct(mverts.begin(), mverts.end());
    if (distinct.size() >= 2) {
      // λ = mean ratio of marker geodesics on the posed template to those on the rest template
      // (§5.2). Iterated to the self-consistent value: the re-solved shape with scale λ has
      // geodesic ratio λ (the thesis does one step; data far out of scale needs a few).
      std::vector<int> dm(distinct.begin(), distinct.end());
      // rest-pose geodesics between the markers: the rotation field's skeleton has them already
      const ConstraintGraph* graph = D.rotationGraph();
      const Eigen::MatrixXd D0 = graph && graph->nodes == dm ? graph->geodesic : geodesic_distance_matrix(templ.V, templ.F, dm);
      // the shortest paths between the markers are searched once, on the first posed shape; the
      // later rounds re-measure the same curves on the re-solved shape (a uniform rescale keeps
      // them shortest; the search is the expensive part)
      std::vector<std::vector<std::vector<int>>> paths;
      auto ratio_of = [&](const Eigen::MatrixX3d& X) {
        if (paths.empty()) paths = geodesic_paths(X, templ.F, dm);
        double sum = 0;
        int cnt = 0;
        for (Eigen::Index a = 0; a < D0.rows(); ++a)
          for (Eigen::Index b = a + 1; b < D0.cols(); ++b) {
            const auto& path = paths[std::size_t(a)][std::size_t(b)];
            if (std::isfinite(D0(a, b)) && D0(a, b) > 0 && !path.empty()) { sum += path_length(X, path) / D0(a, b); ++cnt; }
          }
        return cnt ? sum / cnt : std::numeric_limits<double>::quiet_NaN();
      };
      for (int k = 0; k < 8; ++k) {
        const double ratio = ratio_of(V);  // = global_scale_from_geodesics(templ.V, V, F, markers)
        if (!(ratio > 0 && std::isfinite(ratio))) break;
        const double change = std::abs(ratio / lambda - 1);
        lambda = ratio;
        D.setScale(lambda);
        V = D.deform();
        if (change < 2e-3) break;
      }
    } else {
      rep.message += "scale not estimated: it needs 2 or more distinct markers. ";
    }
  }
  rep.scale = lambda;
  rep.t_scale = seconds_since(t0);
  if (!D.lastRotations().empty()) D.setRotations(D.lastRotations());  // freeze the field
  Eigen::MatrixX3d V0 = V;
  Eigen::MatrixX3i F = templ.F;
  const Eigen::SparseMatrix<double> Ct = cotangent_matrix(templ.V, templ.F);  // for refine_rotations

  // ---- orient estimated normals by the posed template
  if (orient) {
    const PointSearch vt(V);
    const Eigen::MatrixX3d VN = vertex_normals(V, F);
#pragma omp parallel for schedule(static)
    for (Eigen::Index i = 0; i < np; ++i) {
      const Eigen::Index j = vt.nearest(P.row(i).transpose());
      if (j >= 0 && N.row(i).dot(VN.row(j)) < 0) N.row(i) *= -1;
    }
    if (u.consistent_normals) {
      const auto tc = Clock::now();
      Eigen::VectorXd confidence(np);
#pragma omp parallel for schedule(static)
      for (Eigen::Index i = 0; i < np; ++i) {
        const Eigen::Index j = vt.nearest(P.row(i).transpose());
        confidence(i) = j >= 0 ? std::abs(N.row(i).dot(VN.row(j))) : 0.0;
      }
      const NormalOrientationResult o = orient_normals_consistently(search, N, confidence, u.normal_neighbours);
      rep.normals_flipped_for_consistency = o.flipped;
      rep.t_normals += seconds_since(tc);
      logger()->debug("[TemplateFitting] consistent normals: {} pairs, {} components, {} conflicts, {} flipped", o.edges,
                      o.components, o.conflicts, o.flipped);
    }
  }

  // ---- stage 2: iterative matching
  std::vector<char> matched(std::size_t(V.rows()), 0);
  Eigen::MatrixX3d target = V;
  std::vector<int> frozen_ids;     // constraint id per vertex while the set is frozen (-1: none)
  // frozen phase: each vertex's cloud neighbours within nb_cache_r of where it was when they were
  // found. Frozen iterations move vertices by a small fraction of r, so the radius-r neighbours
  // are the cached ones within r of the vertex as long as it stays within nb_cache_r - r of the
  // cache centre (exact; the tree is searched again otherwise). Saves most kd-tree searches of
  // the frozen iterations.
  std::vector<std::vector<std::pair<Eigen::Index, double>>> nb_cache;
  Eigen::MatrixX3d nb_cache_at;
  std::vector<double> nb_cache_r;
  Eigen::MatrixX3d frozen_target;
  std::vector<double> frozen_moves;  // 99th percentile moves of the frozen iterations
  // displacement propagation inside the frozen iterations (see stage 3)
  HarmonicInterpolator prop_harmonic;
  std::vector<int> prop_ids;        // per vertex: id of its propagated constraint (-1: none)
  std::vector<int> prop_sources;    // the matched vertices the interpolation starts from
  Eigen::MatrixX3d N0;              // normals of the initial deformation
  bool propagate_in_loop = false;   // propagated constraints are in the frozen system (N0 set up)
  bool propagation_handled = false; // propagation decided in the loop (done or skipped for good)
  // normal displacements of the matched vertices relative to the initial deformation,
  // harmonically interpolated, as targets of the unmatched ones (§5.3 end)
  auto propagated_targets = [&](const Eigen::MatrixX3d& X) {
    Eigen::MatrixXd d(Eigen::Index(prop_sources.size()), 1);
    for (std::size_t k = 0; k < prop_sources.size(); ++k)
      d(Eigen::Index(k), 0) = (X.row(prop_sources[k]) - V0.row(prop_sources[k])).dot(N0.row(prop_sources[k]));
    const Eigen::MatrixXd dense = prop_harmonic.interpolate(d);
    Eigen::MatrixX3d T = V0;
    for (Eigen::Index j = 0; j < V0.rows(); ++j) T.row(j) += dense(j, 0) * N0.row(j);
    return T;
  };
  bool converged = false;
  const auto t_it = Clock::now();
  for (int it = 1; it <= u.max_iterations; ++it) {
    const auto t_iter = Clock::now();
    report_progress(progress, 0.1 + 0.75 * double(it - 1) / std::max(u.max_iterations, 1), "matching");
    const int rsteps = u.radius_steps;
    const int freeze_it = u.freeze_iteration > 0 ? u.freeze_iteration : std::max(1, rsteps);
    const double frac = rsteps > 0 ? std::min(1.0, double(it - 1) / rsteps) : 1.0;
    const double r = u.initial_match_distance * std::pow(u.max_match_distance / u.initial_match_distance, frac);
    auto tm = Clock::now();
    const Eigen::MatrixX3d VN = vertex_normals(V, F);
    // in the frozen phase (see below) only the frozen set is matched
    const bool frozen_phase = u.freeze_constraints && it >= freeze_it && !u.laplacian_updating && !u.remeshing &&
                              !frozen_ids.empty();
    const std::vector<char> prev_matched = matched;
    std::fill(matched.begin(), matched.end(), 0);
    matched.resize(std::size_t(V.rows()), 0);
    target = V;
    Eigen::VectorXd match_scale = Eigen::VectorXd::Ones(V.rows());
    // large radius: match against the binned cloud (bins of r/3) when it has under half as
    // many entries as the cloud (FitParameters::binned_matching)
    std::optional<BinnedCloud> binned;
    if (u.binned_matching && !frozen_phase && !u.laplacian_updating && !u.remeshing && r > u.max_match_distance) {
      BinnedCloud b = bin_cloud(P, N, roi_ok, r / 3);
      if (2 * b.count.rows() < np) binned = std::move(b);
    }
    if (frozen_phase && nb_cache.empty()) {
      nb_cache.resize(std::size_t(V.rows()));
      nb_cache_at = Eigen::MatrixX3d::Constant(V.rows(), 3, std::numeric_limits<double>::quiet_NaN());
      nb_cache_r.assign(std::size_t(V.rows()), 0.0);
    }
#pragma omp parallel
    {
      std::vector<std::pair<Eigen::Index, double>> nb;
#pragma omp for schedule(dynamic, 256)
      for (Eigen::Index j = 0; j < V.rows(); ++j) {
        if (masked[std::size_t(j)]) continue;
        if (frozen_phase && frozen_ids[std::size_t(j)] < 0) continue;  // cannot join the frozen set
        const Eigen::Vector3d vj = V.row(j).transpose(), nj = VN.row(j).transpose();
        if (nj.squaredNorm() == 0) continue;
        // expanding search: the scheduled radius first (precision), then doubled up to the
        // initial radius for vertices the fit has not brought close to the data yet (reach)
        bool found = false;
        double neff = 0;  // effective number of points of the accepted match
        Eigen::Vector3d q;
        double used_r = r;
        for (double rr = r; rr <= u.initial_match_distance * 1.0001 && !found; rr *= 2) {
          double sw = 0, sw2 = 0, in_ball = 0;
          Eigen::Vector3d sp = Eigen::Vector3d::Zero();
          Eigen::Matrix3d spp = Eigen::Matrix3d::Zero();
          if (binned) {
            binned->search.radius(vj, rr, nb);
            for (const auto& [k, d2] : nb) {
              in_ball += binned->count(k);
              if (binned->normal.row(k).dot(nj) < cos_max) continue;
              const double w = bspline_weight(std::sqrt(d2) / rr);
              sw += w * binned->count(k);
              sw2 += w * w * binned->count(k);  // every point of a bin at the bin's weight
              sp += w * binned->sum_p.row(k).transpose();
              spp += w * binned->sum_pp[std::size_t(k)];
            }
          } else if (frozen_phase && rr == r) {
            // the cached neighbours (see nb_cache), refreshed with a 25 % margin when the
            // vertex has left the region where they are complete
            const std::size_t js = std::size_t(j);
            const double dc = (vj - nb_cache_at.row(j).transpose()).norm();  // NaN before the first search
            if (!(dc + rr <= nb_cache_r[js])) {
              nb_cache_r[js] = 1.25 * rr;
              nb_cache_at.row(j) = vj.transpose();
              search.radius(vj, nb_cache_r[js], nb_cache[js]);
            }
            nb.clear();
            const double rr2 = rr * rr;
            for (const auto& e : nb_cache[js]) {
              const double d2 = (P.row(e.first).transpose() - vj).squaredNorm();
              if (d2 <= rr2) nb.emplace_back(e.first, d2);
            }
            in_ball = double(nb.size());
            kernel_sums(nb, P, N, roi_ok, nj, cos_max, rr, sw, sp, spp, &sw2);
          } else {
            search.radius(vj, rr, nb);
            in_ball = double(nb.size());
            kernel_sums(nb, P, N, roi_ok, nj, cos_max, rr, sw, sp, spp, &sw2);
          }
          if (sw <= 0) continue;
          double off = 0;
          q = kernel_target(vj, nj, sw, sp, spp, u.plane_fit, in_ball, &off);
          // one-sided neighbourhood far beyond the rim of the data: no match
          found = off <= u.rim_rejection * rr;
          neff = sw * sw / sw2;
          used_r = rr;
          if (rr >= u.initial_match_distance) break;
        }
        if (!found) continue;
        // a step of at most the scheduled radius, and matches found only at an expanded radius
        // count less: targets then vary continuously with the shape and the iteration settles
        const double d = std::clamp((q - vj).dot(nj), -r, r);
        target.row(j) = (vj + d * nj).transpose();
        match_scale(j) = (r / used_r) * (r / used_r);
        // sparse support: weight ∝ n_eff (inverse variance of the mean of n_eff noisy points)
        if (u.support_points > 0 && !u.laplacian_updating) match_scale(j) *= std::min(1.0, neff / u.support_points);
        matched[std::size_t(j)] = 1;
      }
    }
    const double t_match_it = seconds_since(tm);
    const bool used_bins = binned.has_value();
    rep.t_matching += t_match_it;
    const Eigen::Index n_matched = std::count(matched.begin(), matched.end(), 1);
    if (logger()->should_log(spdlog::level::trace)) {
      Eigen::Index flips = 0;
      for (std::size_t j = 0; j < matched.size() && j < prev_matched.size(); ++j) flips += matched[j] != prev_matched[j];
      logger()->trace("[TemplateFitting] it {} r {:.4f}% matched {} flips {}", it, 100 * r / diag, n_matched, flips);
    }
    tm = Clock::now();
    double w_data = u.match_weight;
    if (u.laplacian_updating) {
      TriMesh cur;
      cur.V = V;
      cur.F = F;
      // the current shape can have slivers (subdivision, fairing): their vertices' rows must
      // not dominate the system (they made the solve return the current shape unchanged, or
      // the factorization fail)
      D.setSliverGuard(0.1);
      D.setMesh(cur);  // §5.5.1: the Laplacian system of the current shape
      D.setScale(1.0);
      D.setAnchor(1e-9);  // folded intermediate shapes must not make the system singular
      w_data = u.updating_match_weight;
    }
    if (u.refine_rotations && !u.laplacian_updating && it >= 2) {
      // rotation field from the current fit: local rotations at matched vertices and markers,
      // harmonically interpolated elsewhere
      std::vector<int> nodes;
      std::vector<Eigen::Matrix3d> rots;
      std::vector<char> is_node(std::size_t(V.rows()), 0);
      for (Eigen::Index j = 0; j < V.rows(); ++j) if (matched[std::size_t(j)]) is_node[std::size_t(j)] = 1;
      for (int mv : mverts) is_node[std::size_t(mv)] = 1;
      for (int k = 0; k < Ct.outerSize(); ++k) {
        if (!is_node[std::size_t(k)]) continue;
        Eigen::Matrix3d S = Eigen::Matrix3d::Zero();
        for (Eigen::SparseMatrix<double>::InnerIterator itc(Ct, k); itc; ++itc) {
          if (itc.row() == k) continue;
          const Eigen::Vector3d e0 = (templ.V.row(itc.row()) - templ.V.row(k)).transpose();
          const Eigen::Vector3d e1 = (V.row(itc.row()) - V.row(k)).transpose();
          S += std::abs(itc.value()) * e1 * e0.transpose();
        }
        nodes.push_back(k);
        rots.push_back(closest_rotation(S));
      }
      try {
        RotationField rf;
        rf.compute(templ.V, F, nodes);
        D.setRotations(rf.interpolate(rots));
      } catch (const InvalidInput&) {
        // a component without nodes: keep the previous field
      }
    }
    // From freeze_iteration on (and without Laplacian updating / remeshing, which change the
    // system anyway), the constrained set and weights are frozen: later iterations only move
    // targets, i.e. one back-substitution instead of a factorization, and vertices can no longer
    // flicker in and out of the system. A frozen vertex that finds no match keeps its last target.
    const bool freeze = u.freeze_constraints && it >= freeze_it && !u.laplacian_updating && !u.remeshing;
    if (freeze && !frozen_ids.empty()) {
      for (Eigen::Index j = 0; j < V.rows(); ++j) {
        const int id = frozen_ids[std::size_t(j)];
        if (id < 0) continue;
        if (matched[std::size_t(j)]) {
          D.setPositionTarget(id, target.row(j).transpose());
          frozen_target.row(j) = target.row(j);
        } else {
          target.row(j) = frozen_target.row(j);
        }
        matched[std::size_t(j)] = 1;
      }
      for (Eigen::Index j = 0; j < V.rows(); ++j)
        if (frozen_ids[std::size_t(j)] < 0) matched[std::size_t(j)] = 0;
      if (propagate_in_loop) {
        const auto tp = Clock::now();
        const Eigen::MatrixX3d T = propagated_targets(V);
        for (Eigen::Index j = 0; j < V.rows(); ++j)
          if (prop_ids[std::size_t(j)] >= 0) D.setPositionTarget(prop_ids[std::size_t(j)], T.row(j).transpose());
        rep.t_propagation += seconds_since(tp);
      }
    } else {
      D.clearConstraints();
      add_markers(D, u.marker_weight);
      frozen_ids.assign(std::size_t(V.rows()), -1);
      for (Eigen::Index j = 0; j < V.rows(); ++j)
        if (matched[std::size_t(j)])
          frozen_ids[std::size_t(j)] = D.addPositionConstraint(SurfacePoint::atVertex(int(j)), target.row(j).transpose(),
                                                               w_data * std::sqrt(match_scale(j)));
      frozen_target = target;
      if (!freeze) frozen_ids.clear();
      // Once frozen, the propagated constraints of §5.3 join the system right away (their
      // targets follow the matched displacements each iteration): the final system of the
      // thesis — matched + propagated constraints — is then the frozen one, factorized once,
      // instead of a separate propagation solve with a factorization of its own.
      if (freeze && u.propagate_displacements) {
        const auto tp = Clock::now();
        prop_sources.clear();
        bool any_unmatched = false;
        for (Eigen::Index j = 0; j < V.rows(); ++j) {
          if (matched[std::size_t(j)]) prop_sources.push_back(int(j));
          else if (!masked[std::size_t(j)]) any_unmatched = true;
        }
        prop_ids.assign(std::size_t(V.rows()), -1);
        propagate_in_loop = false;
        if (!prop_sources.empty() && any_unmatched) {
          try {
            N0 = vertex_normals(V0, F);
            prop_harmonic.compute(V0, F, prop_sources);
            const Eigen::MatrixX3d T = propagated_targets(V);
            for (Eigen::Index j = 0; j < V.rows(); ++j)
              if (!matched[std::size_t(j)] && !masked[std::size_t(j)])
                prop_ids[std::size_t(j)] = D.addPositionConstraint(SurfacePoint::atVertex(int(j)), T.row(j).transpose(),
                                                                   u.propagation_weight);
            propagate_in_loop = true;
          } catch (const InvalidInput&) {
            prop_ids.assign(std::size_t(V.rows()), -1);
            rep.message += "displacement propagation skipped (a mesh component has no matched vertex). ";
          }
        }
        // done here (or nothing to propagate: every unmasked vertex matched), not again in stage 3
        propagation_handled = true;
        rep.t_propagation += seconds_since(tp);
      }
    }
    const Eigen::MatrixX3d Vn = D.deform();
    const double t_solve_it = seconds_since(tm);
    rep.t_solve += t_solve_it;
    logger()->trace("[TemplateFitting] it {} solve {:.3f} s: factorize {:.3f}, back-substitution {:.3f}, rotations {:.3f}", it,
                    t_solve_it, D.report().t_factorize, D.report().t_solve, D.report().t_rotations);
    const Eigen::VectorXd moves = (Vn - V).rowwise().norm();
    // convergence is judged on the data-supported vertices: unmatched regions (holes) are
    // floppy and keep swinging slowly as a whole while the matched ones have settled
    double move = 0;
    // (99th percentile: a handful of vertices in 2-cycles through their own normals must not
    // keep the whole fit from converging)
    Eigen::Index arg = 0;
    std::vector<double> mm;
    for (Eigen::Index j = 0; j < moves.rows(); ++j)
      if (matched[std::size_t(j)]) {
        mm.push_back(moves(j));
        if (moves(j) > moves(arg)) arg = j;
      }
    if (!mm.empty()) {
      const std::size_t k = std::size_t(0.99 * double(mm.size() - 1));
      std::nth_element(mm.begin(), mm.begin() + long(k), mm.end());
      move = mm[k];
    }
    if (logger()->should_log(spdlog::level::trace)) {
      logger()->trace("[TemplateFitting] it {} max matched move {:.4f}% at vertex {} (target dist {:.4f}%), #moving>0.1%d {}", it,
                      100 * move / diag, arg, 100 * (target.row(arg) - V.row(arg)).norm() / diag, (moves.array() > 1e-3 * diag).count());
    }
    // stop: the 99th percentile move is below the tolerance, or it has stalled near it (a few
    // vertices cycling through their own normals or in and out of thin parts: no progress is
    // being made, more iterations only cost time)
    const bool in_freeze = freeze && !frozen_ids.empty();
    bool stop = move < u.tolerance && frac >= 1.0;
    bool stalled = false;
    if (!stop && in_freeze && frac >= 1.0 && frozen_moves.size() >= 3 && move < 5 * u.tolerance) {
      const double best = std::min(frozen_moves[frozen_moves.size() - 1], frozen_moves[frozen_moves.size() - 2]);
      stalled = stop = move > 0.95 * best;
    }
    if (in_freeze) frozen_moves.push_back(move);
    // frozen iterations are a linear solve after a projection: over-relaxing the step speeds up
    // the slow creep of the fixed point; the last step is never relaxed (the output solves the
    // system)
    if (in_freeze && !stop && it < u.max_iterations && u.relaxation != 1.0) V += u.relaxation * (Vn - V);
    else V = Vn;
    bool remeshed = false;
    if (u.remeshing && V.rows() < u.max_vertices && it >= 2 && it < u.max_iterations) {
      tm = Clock::now();
      const MeshDistance md(V, F);
      Eigen::VectorXi face;
      const Eigen::VectorXd dist = md.distances(P, &face);
      Eigen::VectorXd sum = Eigen::VectorXd::Zero(F.rows());
      Eigen::VectorXi cnt = Eigen::VectorXi::Zero(F.rows());
      for (Eigen::Index i = 0; i < np; ++i)
        if (roi_ok[std::size_t(i)] && dist(i) < r) { sum(face(i)) += dist(i); ++cnt(face(i)); }
      std::vector<char> mark(std::size_t(F.rows()), 0);
      int n_mark = 0;
      for (Eigen::Index f = 0; f < F.rows(); ++f)
        if (cnt(f) > 0 && sum(f) / cnt(f) > u.subdivision_error) { mark[std::size_t(f)] = 1; ++n_mark; }
      if (n_mark > 0) {
        SubdivisionResult sub = adaptive_subdivide(V, F, mark);
        valence_edge_flips(sub.V, sub.F);
        const Eigen::Index old_n = V.rows();
        V0.conservativeResize(sub.V.rows(), 3);
        masked.resize(std::size_t(sub.V.rows()), 0);
        for (std::size_t k = 0; k < sub.parents.size(); ++k) {
          const auto [a, b] = sub.parents[k];
          V0.row(old_n + Eigen::Index(k)) = 0.5 * (V0.row(a) + V0.row(b));
          masked[std::size_t(old_n) + k] = masked[std::size_t(a)] && masked[std::size_t(b)];
        }
        V = sub.V;
        F = sub.F;
        // a new mid-edge vertex is matched when both ends are: the fairing below (matched
        // vertices only) then also runs in remeshing iterations. (Resetting every vertex to
        // unmatched skipped it there, and left the stretched regions of a growing sphere
        // unfaired: results then swung between 0.4 % and 3.4 % with ±0.5 % changes of a weight.)
        matched.resize(std::size_t(V.rows()), 0);
        for (std::size_t k = 0; k < sub.parents.size(); ++k) {
          const auto [a, b] = sub.parents[k];
          matched[std::size_t(old_n) + k] = matched[std::size_t(a)] && matched[std::size_t(b)];
        }
        remeshed = true;
      }
      rep.t_remeshing += seconds_since(tm);
    }
    if (u.fairing && u.fairing_steps > 0) {
      tm = Clock::now();
      const auto adj = vertex_adjacency(F, V.rows());
      for (int s = 0; s < u.fairing_steps; ++s) {
        const Eigen::VectorXd A = voronoi_areas(V, F);
        const Eigen::MatrixX3d VN2 = vertex_normals(V, F);
        // sharp features (thin rims): the one-ring centroid lies inwards and the tangent plane
        // would let the rim slide in; such vertices are left alone
        const Eigen::MatrixX3d FN2 = face_normals(V, F);
        std::vector<char> sharp(std::size_t(V.rows()), 0);
        for (Eigen::Index f = 0; f < F.rows(); ++f)
          for (int k = 0; k < 3; ++k)
            if (FN2.row(f).dot(VN2.row(F(f, k))) < std::cos(M_PI / 6)) sharp[std::size_t(F(f, k))] = 1;
        Eigen::MatrixX3d Vf = V;
#pragma omp parallel
        {
          std::vector<Eigen::Index> idx;
          std::vector<double> d2;
#pragma omp for schedule(dynamic, 256)
          for (Eigen::Index i = 0; i < V.rows(); ++i) {
            const auto& nb = adj[std::size_t(i)];
            if (nb.empty() || masked[std::size_t(i)] || !matched[std::size_t(i)] || sharp[std::size_t(i)]) continue;
            double mean_edge = 0;
            for (int j : nb) mean_edge += (V.row(j) - V.row(i)).norm();
            mean_edge /= double(nb.size());
            Eigen::Vector3d g = Eigen::Vector3d::Zero();
            double sa = 0;
            for (int j : nb) { g += A(j) * V.row(j).transpose(); sa += A(j); }
            if (!(sa > 0)) continue;
            g /= sa;  // eq. 5.1
            // normal of the target surface: average of the nearest cloud normals (if close)
            Eigen::Vector3d n = VN2.row(i).transpose();
            search.knn(V.row(i).transpose(), u.normal_neighbours, idx, d2);
            Eigen::Vector3d cn = Eigen::Vector3d::Zero();
            for (std::size_t k = 0; k < idx.size(); ++k)  // same side only (thin parts!)
              if (d2[k] < r * r && N.row(idx[k]).dot(n) > cos_max) cn += N.row(idx[k]).transpose();
            if (cn.norm() > 0) n = cn.normalized();
            const Eigen::Vector3d dv = g - V.row(i).transpose();
            Eigen::Vector3d step = u.fairing_lambda * (dv - n * n.dot(dv));  // eq. 5.2
            if (step.norm() > 0.25 * mean_edge) step *= 0.25 * mean_edge / step.norm();
            Vf.row(i) += step.transpose();
          }
        }
        V = Vf;
      }
      rep.t_fairing += seconds_since(tm);
    }
    rep.history.push_back({it, r, n_matched, move, seconds_since(t_iter), t_match_it, t_solve_it, used_bins});
    rep.iterations = it;
    logger()->debug("[TemplateFitting] iteration {}: r={:.4g}, matched {}, max move {:.3g}", it, r, n_matched, move);
    if (stop && !remeshed) {
      converged = true;
      if (stalled)
        rep.message += "converged: the 99th percentile move stalled at " + std::to_string(move) + " (tolerance " +
                       std::to_string(u.tolerance) + "). ";
      break;
    }
  }
  rep.t_iterations = seconds_since(t_it);
  if (!converged && u.max_iterations > 0) {
    rep.status = FitReport::Status::NotConverged;
    rep.message += "stopped after max_iterations (" + std::to_string(u.max_iterations) + ") before the largest vertex move fell below the tolerance. ";
  }

  // ---- stage 3: displacement propagation (§5.3)
  status.assign(std::size_t(V.rows()), VertexStatus::Unmatched);
  for (Eigen::Index j = 0; j < V.rows(); ++j) {
    if (masked[std::size_t(j)]) status[std::size_t(j)] = VertexStatus::Masked;
    else if (matched[std::size_t(j)]) status[std::size_t(j)] = VertexStatus::Matched;
  }
  if (propagation_handled) {
    for (Eigen::Index j = 0; j < V.rows(); ++j)
      if (j < Eigen::Index(prop_ids.size()) && prop_ids[std::size_t(j)] >= 0) status[std::size_t(j)] = VertexStatus::Propagated;
  } else if (u.propagate_displacements && u.max_iterations > 0) {
    t0 = Clock::now();
    report_progress(progress, 0.88, "propagation");
    std::vector<int> m_idx;
    for (Eigen::Index j = 0; j < V.rows(); ++j)
      if (status[std::size_t(j)] == VertexStatus::Matched) m_idx.push_back(int(j));
    const bool any_unmatched = std::any_of(status.begin(), status.end(), [](VertexStatus s) { return s == VertexStatus::Unmatched; });
    if (!m_idx.empty() && any_unmatched) {
      N0 = vertex_normals(V0, F);
      Eigen::MatrixXd d(Eigen::Index(m_idx.size()), 1);
      for (std::size_t k = 0; k < m_idx.size(); ++k)
        d(Eigen::Index(k), 0) = (V.row(m_idx[k]) - V0.row(m_idx[k])).dot(N0.row(m_idx[k]));
      Eigen::MatrixXd dense;
      try {
        dense = harmonic_interpolation(V0, F, m_idx, d);
      } catch (const InvalidInput&) {
        dense.resize(0, 1);  // a component without matches: nothing to propagate there
        rep.message += "displacement propagation skipped (a mesh component has no matched vertex). ";
      }
      if (dense.rows() == V.rows()) {
        D.clearConstraints();
        add_markers(D, u.marker_weight);
        for (Eigen::Index j = 0; j < V.rows(); ++j) {
          if (status[std::size_t(j)] == VertexStatus::Matched)
            D.addPositionConstraint(SurfacePoint::atVertex(int(j)), target.row(j).transpose(),
                                    u.laplacian_updating ? u.updating_match_weight : u.match_weight);
          else if (status[std::size_t(j)] == VertexStatus::Unmatched) {
            D.addPositionConstraint(SurfacePoint::atVertex(int(j)), (V0.row(j) + dense(j, 0) * N0.row(j)).transpose(),
                                    u.propagation_weight);
            status[std::size_t(j)] = VertexStatus::Propagated;
          }
        }
        V = D.deform();
      }
    }
    rep.t_propagation = seconds_since(t0);
  }

  // ---- detail rounds (beyond the thesis; FitParameters::detail_rounds): §5.5.1's Laplacian
  // updating after the §5.3 fit, with everything the data does not support held where the fit
  // put it. Each round takes the Laplacian and differential coordinates of the current fit as
  // the regularizer (so the template's detail no longer holds protrusions back), constrains the
  // matched vertices to data targets with detail_weight — the kernel mean of the data -> fit
  // residuals (detail_residual_matching) or the §5.3 kernel targets — every other vertex to its
  // current position with match_weight (the semantic hole filling stays) and, with
  // detail_surface_weight, faces to the cloud points that project onto them; it factorizes once
  // and iterates matching + back-substitution.
  if (u.detail_rounds > 0 && (u.laplacian_updating || u.remeshing))
    rep.message += "detail rounds skipped: Laplacian updating already regularizes with the current shape. ";
  if (u.detail_rounds > 0 && u.max_iterations > 0 && !u.laplacian_updating && !u.remeshing) {
    t0 = Clock::now();
    report_progress(progress, 0.9, "detail rounds");
    const double r = u.max_match_distance;
    const double rd = u.detail_radius_factor * r;  // kernel radius of the residual matching
    const double cos_detail = std::cos(u.detail_normal_angle_deg * M_PI / 180.0);
    std::vector<std::vector<int>> vf(std::size_t(V.rows()));  // faces around each vertex
    for (Eigen::Index f = 0; f < F.rows(); ++f)
      for (int c = 0; c < 3; ++c) vf[std::size_t(F(f, c))].push_back(int(f));
    LaplacianDeformer Dd;  // one for all rounds: the solver keeps its symbolic analysis
    Dd.setUseRotationField(false);
    for (int round = 0; round < u.detail_rounds; ++round) {
      TriMesh cur;
      cur.V = V;
      cur.F = F;
      Dd.clearConstraints();
      Dd.setMesh(cur);
      add_markers(Dd, u.detail_marker_weight);
      const auto t_round = Clock::now();
      // residual matching: every ROI point's closest point on the fit, as a face and barycentric
      // weights, found at the start of the round and then updated among the faces around the
      // last one after each solve (the fit moves little per iteration). Points farther than 3 r
      // are not tracked; the kernel below skips those farther than r (outliers, other surfaces).
      std::vector<Eigen::Index> rk;  // cloud index of each tracked point
      std::vector<int> rf;           // its closest face
      Eigen::MatrixX3d rb;           // and the barycentric weights of its closest point
      if (u.detail_residual_matching) {
        const MeshDistance md(V, F);
        std::vector<int> face(std::size_t(np), -1);
#pragma omp parallel for schedule(dynamic, 1024)
        for (Eigen::Index i = 0; i < np; ++i) {
          if (!roi_ok[std::size_t(i)]) continue;
          int f = -1;
          const Eigen::Vector3d p = P.row(i).transpose();
          if ((md.closest(p, &f) - p).norm() <= 3 * r) face[std::size_t(i)] = f;
        }
        for (Eigen::Index i = 0; i < np; ++i)
          if (face[std::size_t(i)] >= 0) { rk.push_back(i); rf.push_back(face[std::size_t(i)]); }
        rb.resize(Eigen::Index(rk.size()), 3);
        for (std::size_t t = 0; t < rk.size(); ++t) {
          const int f = rf[t];
          rb.row(Eigen::Index(t)) = closest_point_barycentric(P.row(rk[t]).transpose(), V.row(F(f, 0)).transpose(),
                                                        V.row(F(f, 1)).transpose(), V.row(F(f, 2)).transpose()).transpose();
        }
      }
      // the tracked points' closest points on the current fit
      auto tracked_closest = [&]() {
        Eigen::MatrixX3d C(Eigen::Index(rk.size()), 3);
        for (Eigen::Index t = 0; t < C.rows(); ++t) {
          const int f = rf[std::size_t(t)];
          C.row(t) = rb(t, 0) * V.row(F(f, 0)) + rb(t, 1) * V.row(F(f, 1)) + rb(t, 2) * V.row(F(f, 2));
        }
        return C;
      };
      // kernel sums of the residual matching at v: Σw, Σw², Σw (p_k − c_k) over the tracked points
      // whose closest point c_k lies within r_d of v, whose normal is within
      // detail_normal_angle_deg of their face's and whose residual is at most r
      struct ResidualSums {
        double sw = 0, sw2 = 0;
        Eigen::Vector3d sr = Eigen::Vector3d::Zero();
      };
      auto residual_sums = [&](const PointSearch& cs, const Eigen::MatrixX3d& C, const Eigen::MatrixX3d& FNc,
                               const Eigen::Vector3d& v, std::vector<std::pair<Eigen::Index, double>>& nb) {
        ResidualSums a;
        cs.radius(v, rd, nb);
        for (const auto& [t, d2] : nb) {
          const Eigen::Index ci = rk[std::size_t(t)];
          if (N.row(ci).dot(FNc.row(rf[std::size_t(t)])) < cos_detail) continue;
          const Eigen::Vector3d res = (P.row(ci) - C.row(t)).transpose();
          if (res.squaredNorm() > r * r) continue;
          const double w = bspline_weight(std::sqrt(d2) / rd);
          a.sw += w;
          a.sw2 += w * w;
          a.sr += w * res;
        }
        return a;
      };
      // sparse support, as in stage 2: a vertex whose residual kernel holds fewer than
      // support_points × (r_d / r)² effective points (the count stage 2's kernel would see in the
      // same patch) gets least-squares weight ∝ n_eff — at the rim of holes one or two noisy
      // points otherwise pull it off the surface
      Eigen::VectorXd dscale = Eigen::VectorXd::Ones(V.rows());
      if (u.detail_residual_matching && u.support_points > 0) {
        const double need = u.support_points * (rd / r) * (rd / r);
        const Eigen::MatrixX3d C = tracked_closest();
        const PointSearch csearch(C);
        const Eigen::MatrixX3d FN0 = face_normals(V, F);
#pragma omp parallel
        {
          std::vector<std::pair<Eigen::Index, double>> nb;
#pragma omp for schedule(dynamic, 256)
          for (Eigen::Index j = 0; j < V.rows(); ++j) {
            if (status[std::size_t(j)] != VertexStatus::Matched) continue;
            const ResidualSums a = residual_sums(csearch, C, FN0, V.row(j).transpose(), nb);
            dscale(j) = a.sw2 > 0 ? std::min(1.0, a.sw * a.sw / a.sw2 / need) : 1.0;
          }
        }
      }
      std::vector<int> ids(std::size_t(V.rows()), -1);
      for (Eigen::Index j = 0; j < V.rows(); ++j) {
        const bool data = status[std::size_t(j)] == VertexStatus::Matched;
        const int id = Dd.addPositionConstraint(SurfacePoint::atVertex(int(j)), V.row(j).transpose(),
                                                data ? u.detail_weight * std::sqrt(dscale(j)) : u.match_weight);
        if (data) ids[std::size_t(j)] = id;
      }
      // data -> surface: each face onto which 3 or more cloud points (ROI, within r) project
      // pulls its centroid by their mean residual. The §5.3 kernel targets (residual matching
      // off) move along the normals only; these also pull sideways where the data reach beyond
      // the mesh (the tip of a protrusion projects onto the faces around the fit's tip vertex).
      if (u.detail_surface_weight > 0) {
        const MeshDistance md(V, F);
        Eigen::MatrixX3d CP(np, 3);
        Eigen::VectorXi CF = Eigen::VectorXi::Constant(np, -1);
#pragma omp parallel for schedule(dynamic, 1024)
        for (Eigen::Index i = 0; i < np; ++i) {
          if (!roi_ok[std::size_t(i)]) continue;
          int f = -1;
          CP.row(i) = md.closest(P.row(i).transpose(), &f).transpose();
          CF(i) = f;
        }
        Eigen::MatrixX3d rsum = Eigen::MatrixX3d::Zero(F.rows(), 3);
        Eigen::VectorXi rcount = Eigen::VectorXi::Zero(F.rows());
        for (Eigen::Index i = 0; i < np; ++i) {
          const int f = CF(i);
          if (f < 0 || (P.row(i) - CP.row(i)).norm() > r) continue;
          rsum.row(f) += P.row(i) - CP.row(i);
          ++rcount(f);
        }
        for (Eigen::Index f = 0; f < F.rows(); ++f) {
          if (rcount(f) < 3) continue;
          const Eigen::RowVector3d centroid = (V.row(F(f, 0)) + V.row(F(f, 1)) + V.row(F(f, 2))) / 3.0;
          Dd.addPositionConstraint(SurfacePoint::onFace(int(f), Eigen::Vector3d::Constant(1.0 / 3)),
                                   (centroid + rsum.row(f) / rcount(f)).transpose(), u.detail_surface_weight);
          ++rep.detail_surface_constraints;
        }
      }
      rep.detail_points_tracked = Eigen::Index(rk.size());
      logger()->trace("[TemplateFitting] detail round {}: set-up {:.3f} s ({} data -> surface constraints, {} points tracked)",
                      round + 1, seconds_since(t_round), rep.detail_surface_constraints, rk.size());
      int k = 0;
      for (; k < u.detail_iterations; ++k) {
        const Eigen::MatrixX3d VN = vertex_normals(V, F);
        Eigen::MatrixX3d T = Eigen::MatrixX3d::Constant(V.rows(), 3, std::numeric_limits<double>::quiet_NaN());
        if (u.detail_residual_matching) {
          if (k > 0) {
            // the fit moved a little: each point's closest point among the faces around its last one
#pragma omp parallel for schedule(dynamic, 1024)
            for (Eigen::Index t = 0; t < Eigen::Index(rk.size()); ++t) {
              const Eigen::Vector3d p = P.row(rk[std::size_t(t)]).transpose();
              const int f0 = rf[std::size_t(t)];
              double best = std::numeric_limits<double>::infinity();
              for (int c = 0; c < 3; ++c)
                for (int f : vf[std::size_t(F(f0, c))]) {
                  const Eigen::Vector3d a = V.row(F(f, 0)).transpose(), b = V.row(F(f, 1)).transpose(), e = V.row(F(f, 2)).transpose();
                  const Eigen::Vector3d w = closest_point_barycentric(p, a, b, e);
                  const double d2 = (p - (w(0) * a + w(1) * b + w(2) * e)).squaredNorm();
                  if (d2 < best) { best = d2; rf[std::size_t(t)] = f; rb.row(t) = w.transpose(); }
                }
            }
          }
          // target = vertex + kernel-weighted mean of the residuals p_k - c_k
          const Eigen::MatrixX3d C = tracked_closest();
          const PointSearch csearch(C);
          const Eigen::MatrixX3d FNd = face_normals(V, F);
#pragma omp parallel
          {
            std::vector<std::pair<Eigen::Index, double>> nb;
#pragma omp for schedule(dynamic, 256)
            for (Eigen::Index j = 0; j < V.rows(); ++j) {
              if (ids[std::size_t(j)] < 0) continue;
              const Eigen::Vector3d vj = V.row(j).transpose();
              const ResidualSums a = residual_sums(csearch, C, FNd, vj, nb);
              if (a.sw <= 0) continue;
              Eigen::Vector3d m = a.sr / a.sw;
              if (m.norm() > r) m *= r / m.norm();
              T.row(j) = (vj + m).transpose();
            }
          }
        } else {
#pragma omp parallel
          {
            std::vector<std::pair<Eigen::Index, double>> nb;
#pragma omp for schedule(dynamic, 256)
            for (Eigen::Index j = 0; j < V.rows(); ++j) {
              if (ids[std::size_t(j)] < 0) continue;
              const Eigen::Vector3d vj = V.row(j).transpose(), nj = VN.row(j).transpose();
              if (nj.squaredNorm() == 0) continue;
              search.radius(vj, r, nb);
              double sw = 0, off = 0;
              Eigen::Vector3d sp = Eigen::Vector3d::Zero();
              Eigen::Matrix3d spp = Eigen::Matrix3d::Zero();
              kernel_sums(nb, P, N, roi_ok, nj, cos_max, r, sw, sp, spp);
              if (sw <= 0) continue;
              const Eigen::Vector3d q = kernel_target(vj, nj, sw, sp, spp, u.plane_fit, double(nb.size()), &off);
              if (off > u.rim_rejection * r) continue;
              T.row(j) = (vj + std::clamp((q - vj).dot(nj), -r, r) * nj).transpose();
            }
          }
        }
        for (Eigen::Index j = 0; j < V.rows(); ++j)  // no data this time: the last target stays
          if (ids[std::size_t(j)] >= 0 && T.row(j).allFinite()) Dd.setPositionTarget(ids[std::size_t(j)], T.row(j).transpose());
        const Eigen::MatrixX3d Vn = Dd.deform();
        // 99th percentile move of the data-supported vertices, as in stage 2
        std::vector<double> mm;
        for (Eigen::Index j = 0; j < V.rows(); ++j)
          if (ids[std::size_t(j)] >= 0) mm.push_back((Vn.row(j) - V.row(j)).norm());
        double move = 0;
        if (!mm.empty()) {
          const std::size_t q = std::size_t(0.99 * double(mm.size() - 1));
          std::nth_element(mm.begin(), mm.begin() + long(q), mm.end());
          move = mm[q];
        }
        V = Vn;
        logger()->debug("[TemplateFitting] detail round {} iteration {}: 99th percentile move {:.3g}", round + 1, k + 1, move);
        logger()->trace("[TemplateFitting] detail solve: factorize {:.3f}, back-substitution {:.3f}", Dd.report().t_factorize,
                        Dd.report().t_solve);
        if (move < u.detail_tolerance) { ++k; break; }
      }
      rep.detail_iterations_run += k;
    }
    rep.t_detail = seconds_since(t0);
  }

  // ---- fold repair (with fairing, §5.5.3): edges whose faces are bent back by more than 120°
  // are fold-overs; their vertices and one-rings get umbrella smoothing steps until none is left
  // (at most 30 rounds); then small crumples (count_local_folds) are untangled; repeated while
  // the untangling bends edges back (at most 3 passes).
  // (flipped_faces, for the report: faces whose normal is more than 120° against the cloud
  // normal NR nearest to their centre)
  auto flipped_faces = [&](const Eigen::MatrixX3d& X, const Eigen::MatrixX3d& NR) {
    const Eigen::MatrixX3d FN = face_normals(X, F);
    int flipped = 0;
#pragma omp parallel for schedule(dynamic, 1024) reduction(+ : flipped)
    for (Eigen::Index f = 0; f < F.rows(); ++f) {
      const Eigen::Vector3d c = (X.row(F(f, 0)) + X.row(F(f, 1)) + X.row(F(f, 2))).transpose() / 3.0;
      double d2 = 0;
      const Eigen::Index k = search.nearest(c, &d2);
      flipped += k >= 0 && roi_ok[std::size_t(k)] && d2 < u.max_match_distance * u.max_match_distance &&
                 FN.row(f).dot(NR.row(k)) < -0.5;
    }
    return flipped;
  };
  // cloud normals for the fold-over checks: estimated normals are made consistent first (unless
  // the fit already did): a patch the template oriented inwards (a sphere over a concave ledge)
  // is not a patch of flipped faces. Computed once, on first use.
  Eigen::MatrixX3d NC;
  bool nc_ready = false;
  auto consistent_N = [&]() -> const Eigen::MatrixX3d& {
    if (!rep.normals_estimated || u.consistent_normals) return N;
    if (!nc_ready) {
      NC = N;
      orient_normals_consistently(search, NC, Eigen::VectorXd::Ones(np), u.normal_neighbours);
      nc_ready = true;
    }
    return NC;
  };
  auto folded_edges = [&](const Eigen::MatrixX3d& X, std::vector<char>* mark) {
    const Eigen::MatrixX3d FN = face_normals(X, F);
    std::unordered_map<std::uint64_t, Eigen::Index> first;
    first.reserve(std::size_t(F.rows()) * 2);
    int folds = 0;
    for (Eigen::Index f = 0; f < F.rows(); ++f)
      for (int k = 0; k < 3; ++k) {
        const int a = F(f, k), b = F(f, (k + 1) % 3);
        const std::uint64_t key = (std::uint64_t(std::uint32_t(std::min(a, b))) << 32) | std::uint32_t(std::max(a, b));
        auto found = first.find(key);
        if (found == first.end()) { first.emplace(key, f); continue; }
        if (FN.row(f).dot(FN.row(found->second)) < -0.5) {
          ++folds;
          if (mark)
            for (Eigen::Index g : {f, found->second})
              for (int q = 0; q < 3; ++q) (*mark)[std::size_t(F(g, q))] = 1;
        }
      }
    return folds;
  };
  // ---- pleat collapse (with remeshing and fairing, after the fold repair): faces against the
  // cloud's (consistent) normal near them are strips whose vertices lie out of order along the
  // surface; the out-of-order vertices are merged by edge collapses (collapse_pleats), the
  // crumples the merges leave are untangled (at most 3 passes), and the fold repair then runs
  // again on any edge the untangling bent back.
  const double r2_pleat = u.max_match_distance * u.max_match_distance;
  auto pleat_reference = [&](const Eigen::Vector3d& c) -> Eigen::Vector3d {
    double d2 = 0;
    const Eigen::Index k = search.nearest(c, &d2);
    if (k < 0 || !roi_ok[std::size_t(k)] || d2 >= r2_pleat) return Eigen::Vector3d::Zero();
    return consistent_N().row(k).transpose();
  };
  auto pleat_step = [&]() {
    t0 = Clock::now();
    consistent_N();  // computed once, before the parallel use
    for (int pass = 0; pass < 3; ++pass) {
      std::vector<int> old_to_new;
      const PleatCollapseResult pr = collapse_pleats(V, F, pleat_reference, &old_to_new);
      if (pass == 0) rep.pleat_faces_before = pr.faces_before;
      if (pr.collapses == 0) break;
      rep.pleat_collapses += pr.collapses;
      std::vector<VertexStatus> st(std::size_t(V.rows()), VertexStatus::Unmatched);
      for (std::size_t i = 0; i < old_to_new.size() && i < status.size(); ++i)
        if (old_to_new[i] >= 0) st[std::size_t(old_to_new[i])] = status[i];
      status = std::move(st);
      const UntangleResult ur = untangle_local_folds(V, F, 0, 20, 1);
      rep.untangled_vertices += ur.vertices_moved;
    }
    rep.t_fairing += seconds_since(t0);
  };

  auto fold_repair = [&]() {
    if (u.fairing) {
      t0 = Clock::now();
      const auto adj = vertex_adjacency(F, V.rows());
      std::vector<char> mark;
      for (int pass = 0; pass < 3; ++pass) {
        for (int round = 0; round < 30; ++round) {
          mark.assign(std::size_t(V.rows()), 0);
          const int bad = folded_edges(V, &mark);  // geometric: independent of estimated normals
          if (bad == 0) break;
          std::vector<char> region = mark;
          grow_region(region, adj, 1 + round / 5);  // the region grows while folds persist
          for (int step = 0; step < 5; ++step) umbrella_step(V, adj, region);
        }
        // small crumples that bend no single edge back (local_folds): their vertices are re-placed
        // by the membrane of their one-ring, grown by one ring only where that is not enough (a
        // wider membrane flattens real detail: 2 rings raised the Igea fit's Hausdorff 0.44 -> 0.63 %)
        const UntangleResult ur = untangle_local_folds(V, F, 0, 20, 1);
        rep.untangled_vertices += ur.vertices_moved;
        if (ur.vertices_moved == 0 || folded_edges(V, nullptr) == 0) break;  // else: repair the edges it bent
      }
      rep.t_fairing += seconds_since(t0);
    }
  };
  fold_repair();

  if (u.remeshing && u.fairing && u.pleat_collapse) {
    pleat_step();
    if (rep.pleat_collapses > 0) {
      fold_repair();  // edges the untangling bent back
      const Eigen::MatrixX3d FN = face_normals(V, F);
      int against = 0;
#pragma omp parallel for schedule(dynamic, 1024) reduction(+ : against)
      for (Eigen::Index f = 0; f < F.rows(); ++f) {
        const Eigen::Vector3d cf = (V.row(F(f, 0)) + V.row(F(f, 1)) + V.row(F(f, 2))).transpose() / 3.0;
        against += FN.row(f).dot(pleat_reference(cf)) < 0;
      }
      rep.pleat_faces_after = against;
    } else {
      rep.pleat_faces_after = rep.pleat_faces_before;
    }
    logger()->debug("[TemplateFitting] pleat collapse: {} faces against the cloud normals -> {}, {} edges collapsed",
                    rep.pleat_faces_before, rep.pleat_faces_after, rep.pleat_collapses);
  }
  // ---- self-intersection repair (with fairing): faces that pass through each other (a pleat
  // pushed through the surface next to it) are smoothed apart (repair_self_intersections); the
  // fold repair then runs again on any edge that bent
  int known_crossings = -1;
  if (u.fairing) {
    t0 = Clock::now();
    try {
      const IntersectionRepairResult ir = repair_self_intersections(V, F);
      rep.self_intersections_before = ir.pairs_before;
      if (ir.pairs_before > 0) fold_repair();
      else known_crossings = 0;  // nothing moved: no need to count again for the report
    } catch (const InvalidInput&) {
      // not a manifold mesh (a template accepted as is): reported as -1 below
    }
    rep.t_fairing += seconds_since(t0);
  }
  // ---- metrics (cloud ROI -> result)
  report_progress(progress, 0.95, "metrics");
  t0 = Clock::now();
  {
    Eigen::MatrixX3d Q(rep.points_total, 3);
    Eigen::Index nq = 0;
    for (Eigen::Index i = 0; i < np; ++i)
      if (roi_ok[std::size_t(i)]) Q.row(nq++) = P.row(i);
    Q.conservativeResize(nq, 3);
    const Eigen::VectorXd dist = point_mesh_distances(V, F, Q);
    rep.hausdorff = dist.maxCoeff();
    rep.hausdorff_rel = rep.hausdorff / diag;
    rep.mean = dist.mean();
    rep.rms = std::sqrt(dist.squaredNorm() / double(nq));
    std::vector<double> s(dist.data(), dist.data() + nq);
    std::nth_element(s.begin(), s.begin() + long(0.99 * double(nq - 1)), s.end());
    rep.p99 = s[std::size_t(0.99 * double(nq - 1))];
    rep.coverage_points = double((dist.array() <= u.max_match_distance).count()) / double(nq);
    // fold-overs: face normal against the cloud normals near the face centre. Estimated normals
    // are first made consistent for this count (unless the fit already did): a patch the
    // template oriented inwards (a sphere over a concave ledge) is not a patch of flipped faces.
    rep.flipped_faces = flipped_faces(V, consistent_N());
    rep.folded_edges = folded_edges(V, nullptr);
    rep.local_folds = u.fairing ? count_local_folds(V, F) : -1;  // 0.11 s on 86k faces: with the fold repair only
    if (u.fairing && rep.local_folds > 0)
      rep.message += std::to_string(rep.local_folds) + " faces still fold against their surroundings after the fold repair. ";
    if (known_crossings >= 0) {
      rep.self_intersections = known_crossings;
    } else if (u.fairing || u.check_self_intersections) {
      try {
        rep.self_intersections = count_self_intersections(V, F);
      } catch (const InvalidInput&) {
        rep.self_intersections = -1;  // e.g. a non-manifold template (accepted without remeshing)
      }
    }
    if (rep.self_intersections > 0)
      rep.message += std::to_string(rep.self_intersections) + " pairs of faces of the result intersect each other. ";
  }
  rep.t_metrics = seconds_since(t0);
  rep.vertices = V.rows();
  rep.faces = F.rows();
  Eigen::Index active = 0;
  for (auto s : status) {
    rep.matched += s == VertexStatus::Matched;
    rep.propagated += s == VertexStatus::Propagated;
    rep.masked += s == VertexStatus::Masked;
    active += s != VertexStatus::Masked;
  }
  rep.coverage_vertices = active ? double(rep.matched) / double(active) : 0;
  result.V = V;
  result.F = F;
  result.N.resize(0, 3);
  result.C.resize(0, 3);
  rep.t_total = seconds_since(t_all);
  report_progress(progress, 1.0, "done");
  return rep;
}

}  // namespace tbsp
