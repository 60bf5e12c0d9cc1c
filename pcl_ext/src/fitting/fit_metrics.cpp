// The figures of a fit's report: distances from the ROI points to the result, folds, flips and
// self-intersections, vertex counts.
#include <algorithm>
#include <cmath>
#include <vector>

#include "fit_state.h"
#include "tbsp/core/error.h"
#include "tbsp/core/timer.h"
#include "tbsp/mesh/mesh_validation.h"
#include "tbsp/mesh/point_mesh_distance.h"
#include "tbsp/mesh/remeshing.h"

namespace tbsp {
namespace fit_impl {

void compute_metrics(FitState& s, int known_crossings) {
  FitReport& rep = s.rep;
  const FitParameters& u = s.u;
  const Eigen::MatrixX3d& V = s.V;
  const Eigen::MatrixX3i& F = s.F;
  const Eigen::MatrixX3d& P = s.cloud.P;
  const std::vector<char>& roi_ok = s.cloud.roi_ok;
  const Eigen::Index np = s.cloud.np;
  const double diag = s.cloud.diag;
  report_progress(s.progress, 0.95, "metrics");
  const auto t0 = Clock::now();
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
    std::vector<double> sorted(dist.data(), dist.data() + nq);
    const auto i99 = sorted.begin() + long(0.99 * double(nq - 1));
    std::nth_element(sorted.begin(), i99, sorted.end());
    rep.p99 = *i99;
    // the largest 1 % (at least one) lie at or right of the p99 element after the partition above
    const std::size_t k = std::max<std::size_t>(1, std::size_t(nq) / 100);
    std::nth_element(i99, sorted.end() - std::ptrdiff_t(k), sorted.end());
    std::sort(sorted.end() - std::ptrdiff_t(k), sorted.end());  // one summation order
    double tail = 0;
    for (auto it = sorted.end() - std::ptrdiff_t(k); it != sorted.end(); ++it) tail += *it;
    rep.tail_mean = tail / double(k);
    rep.coverage_points = double((dist.array() <= u.max_match_distance).count()) / double(nq);
    // fold-overs: face normal against the cloud normals near the face centre. Estimated normals
    // are first made consistent for this count (unless the fit already did): a patch the
    // template oriented inwards (a sphere over a concave ledge) is not a patch of flipped faces.
    rep.flipped_faces = flipped_faces(s, V, s.consistentNormals());
    rep.folded_edges = folded_edges(F, V, nullptr);
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
  for (auto st : s.status) {
    rep.matched += st == VertexStatus::Matched;
    rep.propagated += st == VertexStatus::Propagated;
    rep.masked += st == VertexStatus::Masked;
    active += st != VertexStatus::Masked;
  }
  rep.coverage_vertices = active ? double(rep.matched) / double(active) : 0;
}

}  // namespace fit_impl
}  // namespace tbsp
