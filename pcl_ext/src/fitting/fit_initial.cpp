// Stage 1 of a fit: initial deformation from the markers and the global scale (§5.2); the
// orientation of estimated cloud normals by the posed template.
#include <algorithm>
#include <cmath>
#include <limits>
#include <set>

#include "fit_state.h"
#include "tbsp/core/error.h"
#include "tbsp/core/logging.h"
#include "tbsp/core/timer.h"
#include "tbsp/deform/rotation_field.h"
#include "tbsp/mesh/cotan_laplacian.h"
#include "tbsp/mesh/geodesics.h"
#include "tbsp/mesh/point_normals.h"

namespace tbsp {
namespace fit_impl {
namespace {

// λ = mean ratio of marker geodesics on the posed template to those on the rest template
// (§5.2). Iterated to the self-consistent value: the re-solved shape with scale λ has geodesic
// ratio λ (the thesis does one step; data far out of scale needs a few).
double estimate_scale(FitState& s) {
  double lambda = 1.0;
  std::set<int> distinct(s.mverts.begin(), s.mverts.end());
  if (distinct.size() < 2) {
    s.rep.message += "scale not estimated: it needs 2 or more distinct markers. ";
    return lambda;
  }
  std::vector<int> dm(distinct.begin(), distinct.end());
  // rest-pose geodesics between the markers: the rotation field's skeleton has them already
  const ConstraintGraph* graph = s.D.rotationGraph();
  const Eigen::MatrixXd D0 =
      graph && graph->nodes == dm ? graph->geodesic : geodesic_distance_matrix(s.templ().V, s.templ().F, dm);
  // the shortest paths between the markers are searched once, on the first posed shape; the
  // later rounds re-measure the same curves on the re-solved shape (a uniform rescale keeps
  // them shortest; the search is the expensive part)
  std::vector<std::vector<std::vector<int>>> paths;
  auto ratio_of = [&](const Eigen::MatrixX3d& X) {
    if (paths.empty()) paths = geodesic_paths(X, s.templ().F, dm);
    double sum = 0;
    int cnt = 0;
    for (Eigen::Index a = 0; a < D0.rows(); ++a)
      for (Eigen::Index b = a + 1; b < D0.cols(); ++b) {
        const auto& path = paths[std::size_t(a)][std::size_t(b)];
        if (std::isfinite(D0(a, b)) && D0(a, b) > 0 && !path.empty()) {
          sum += path_length(X, path) / D0(a, b);
          ++cnt;
        }
      }
    return cnt ? sum / cnt : std::numeric_limits<double>::quiet_NaN();
  };
  for (int k = 0; k < 8; ++k) {
    const double ratio = ratio_of(s.V);  // = global_scale_from_geodesics(templ.V, V, F, markers)
    if (!(ratio > 0 && std::isfinite(ratio))) break;
    const double change = std::abs(ratio / lambda - 1);
    lambda = ratio;
    s.D.setScale(lambda);
    s.V = s.D.deform();
    if (change < 2e-3) break;
  }
  return lambda;
}

}  // namespace

void initial_pose(FitState& s) {
  FitReport& rep = s.rep;
  report_progress(s.progress, 0.05, "initial deformation");
  auto t0 = Clock::now();
  s.D.setMesh(s.templ());
  if (s.markers.empty()) {
    // aligned by align_without_markers: the fit starts from the aligned template, the
    // matches are the only constraints (no rotation field: it interpolates marker rotations)
    s.D.setUseRotationField(false);
    s.V = s.templ().V;
    rep.scale = rep.alignment_scale;
    rep.t_initial = seconds_since(t0);
    s.V0 = s.V;
    s.F = s.templ().F;
    return;
  }
  s.addMarkers(s.D, s.u.marker_weight);
  bool field = s.u.rotation_field;
  if (field) {
    std::set<int> distinct(s.mverts.begin(), s.mverts.end());
    bool all_rot = std::all_of(s.markers.begin(), s.markers.end(), [](const FitMarker& m) { return bool(m.rotation); });
    if (distinct.size() < 3 && !all_rot) {
      field = false;
      rep.message += "rotation field skipped: it needs 3 or more markers (or marker rotations). ";
      logger()->warn("[TemplateFitting] fewer than 3 markers: no rotation field");
    }
  }
  s.D.setUseRotationField(field);
  // components without markers move by the markers' mean displacement
  Eigen::Vector3d shift = Eigen::Vector3d::Zero();
  for (std::size_t k = 0; k < s.mverts.size() && k < s.mtarget.size(); ++k)
    shift += (s.mtarget[k] - s.templ().V.row(s.mverts[k]).transpose()) / double(s.mverts.size());
  anchor_free_components(s, s.templ().V, s.templ().F, shift, false);
  try {
    s.V = s.D.deform();
  } catch (const InvalidInput& e) {
    throw InvalidInput(std::string(kWho) + "the markers cannot pose the template: " + e.what());
  }
  rep.t_initial = seconds_since(t0);
  const auto& dr = s.D.report();
  logger()->trace("[TemplateFitting] initial: {:.3f} s: setMesh+laplacian {:.3f}, graph {:.3f}, factorize {:.3f}, rotations {:.3f}, solve {:.3f}",
                  rep.t_initial, dr.t_laplacian, dr.t_graph, dr.t_factorize, dr.t_rotations, dr.t_solve);
  t0 = Clock::now();
  rep.scale = s.u.estimate_scale ? estimate_scale(s) : 1.0;
  rep.t_scale = seconds_since(t0);
  if (!s.D.lastRotations().empty()) s.D.setRotations(s.D.lastRotations());  // freeze the field
  s.V0 = s.V;
  s.F = s.templ().F;
}

void orient_cloud_normals(FitState& s) {
  if (!s.orient) return;
  const PointSearch vt(s.V);
  const Eigen::MatrixX3d VN = vertex_normals(s.V, s.F);
  const Eigen::Index np = s.cloud.np;
#pragma omp parallel for schedule(static)
  for (Eigen::Index i = 0; i < np; ++i) {
    const Eigen::Index j = vt.nearest(s.cloud.P.row(i).transpose());
    if (j >= 0 && s.N.row(i).dot(VN.row(j)) < 0) s.N.row(i) *= -1;
  }
  if (s.u.consistent_normals) {
    const auto tc = Clock::now();
    Eigen::VectorXd confidence(np);
#pragma omp parallel for schedule(static)
    for (Eigen::Index i = 0; i < np; ++i) {
      const Eigen::Index j = vt.nearest(s.cloud.P.row(i).transpose());
      confidence(i) = j >= 0 ? std::abs(s.N.row(i).dot(VN.row(j))) : 0.0;
    }
    const NormalOrientationResult o = orient_normals_consistently(s.cloud.search, s.N, confidence, s.u.normal_neighbours);
    s.rep.normals_flipped_for_consistency = o.flipped;
    s.rep.t_normals += seconds_since(tc);
    logger()->debug("[TemplateFitting] consistent normals: {} pairs, {} components, {} conflicts, {} flipped", o.edges,
                    o.components, o.conflicts, o.flipped);
  }
}

}  // namespace fit_impl
}  // namespace tbsp
