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
#include "tbsp/mesh/point_search.h"
#include "tbsp/mesh/remeshing.h"

namespace tbsp {
namespace fit_impl {

std::vector<FitReport::UnexplainedRegion> unexplained_regions(const Eigen::MatrixX3d& Q, const Eigen::VectorXd& dist, double diag,
                                                              double r_max, std::vector<int>* member) {
  if (member) member->assign(std::size_t(Q.rows()), -1);
  const double far = std::max(2 * r_max, 0.01 * diag), link = 0.5 * far;
  std::vector<Eigen::Index> idx;
  for (Eigen::Index i = 0; i < Q.rows(); ++i)
    if (dist(i) > far) idx.push_back(i);
  const std::size_t min_points = std::max<std::size_t>(30, std::size_t(Q.rows()) / 1000);
  if (idx.size() < min_points) return {};
  Eigen::MatrixX3d F(Eigen::Index(idx.size()), 3);
  for (std::size_t k = 0; k < idx.size(); ++k) F.row(Eigen::Index(k)) = Q.row(idx[k]);
  // groups of far points linked within `link`: union-find, the lower index the root (the
  // groups do not depend on the order the links are visited in)
  std::vector<Eigen::Index> root(idx.size());
  for (std::size_t k = 0; k < root.size(); ++k) root[k] = Eigen::Index(k);
  auto find = [&](Eigen::Index a) {
    while (root[std::size_t(a)] != a) a = root[std::size_t(a)] = root[std::size_t(root[std::size_t(a)])];
    return a;
  };
  const PointSearch tree(F);
  std::vector<std::pair<Eigen::Index, double>> nb;
  for (Eigen::Index k = 0; k < F.rows(); ++k) {
    tree.radius(F.row(k).transpose(), link, nb);
    for (const auto& e : nb) {
      const Eigen::Index a = find(k), b = find(e.first);
      if (a != b) root[std::size_t(std::max(a, b))] = std::min(a, b);
    }
  }
  std::vector<FitReport::UnexplainedRegion> regions(idx.size());
  for (Eigen::Index k = 0; k < F.rows(); ++k) {
    FitReport::UnexplainedRegion& r = regions[std::size_t(find(k))];
    ++r.points;
    r.centre += F.row(k).transpose();
    r.max_distance = std::max(r.max_distance, dist(idx[std::size_t(k)]));
  }
  // the roots of the groups large enough, largest first (ties in root order), at most 8
  std::vector<std::size_t> kept;
  for (std::size_t k = 0; k < regions.size(); ++k)
    if (regions[k].points >= Eigen::Index(min_points)) kept.push_back(k);
  std::stable_sort(kept.begin(), kept.end(), [&](std::size_t a, std::size_t b) { return regions[a].points > regions[b].points; });
  if (kept.size() > 8) kept.resize(8);
  std::vector<FitReport::UnexplainedRegion> out;
  std::vector<int> slot(idx.size(), -1);  // per union-find root: its index in `out`
  for (std::size_t k : kept) {
    regions[k].centre /= double(regions[k].points);
    slot[k] = int(out.size());
    out.push_back(regions[k]);
  }
  if (member)
    for (Eigen::Index k = 0; k < F.rows(); ++k) (*member)[std::size_t(idx[std::size_t(k)])] = slot[std::size_t(find(k))];
  return out;
}

Eigen::Index unexplained_points(const std::vector<FitReport::UnexplainedRegion>& regions) {
  Eigen::Index n = 0;
  for (const auto& u : regions) n += u.points;
  return n;
}

Eigen::MatrixX3d roi_points(const PreparedCloud& c) {
  Eigen::MatrixX3d Q(c.np, 3);
  Eigen::Index nq = 0;
  for (Eigen::Index i = 0; i < c.np; ++i)
    if (c.roi_ok[std::size_t(i)]) Q.row(nq++) = c.P.row(i);
  Q.conservativeResize(nq, 3);
  return Q;
}

bool is_surface_point(const PreparedCloud& c, const Eigen::Vector3d& q) {
  std::vector<Eigen::Index> idx;
  std::vector<double> d2;
  c.search.knn(q, 5, idx, d2);  // the point itself and 4 others
  return d2.size() == 5 && d2[4] <= 9 * c.spacing * c.spacing;
}

const RoiDistances& roi_distances(FitState& s) {
  RoiDistances& r = s.roi_dist;
  if (r.V.rows() == 0) r.Q = roi_points(s.cloud);
  if (r.Q.rows() == 0) return r;
  const bool same_mesh = r.V.rows() == s.V.rows() && r.F.rows() == s.F.rows() && r.F == s.F;
  std::vector<char> moved;
  Eigen::Index n_moved = 0;
  if (same_mesh) {
    moved.assign(std::size_t(s.V.rows()), 0);
    for (Eigen::Index v = 0; v < s.V.rows(); ++v)
      if (s.V.row(v) != r.V.row(v)) {
        moved[std::size_t(v)] = 1;
        ++n_moved;
      }
    if (n_moved == 0) return r;
  }
  if (same_mesh && 4 * n_moved <= s.V.rows()) {
    update_point_mesh_distances(s.V, s.F, r.Q, moved, r.d, r.f);
  } else {
    r.d = point_mesh_distances(s.V, s.F, r.Q, &r.f);
    r.F = s.F;
  }
  r.V = s.V;
  return r;
}

double tail_mean(std::vector<double> d) {
  if (d.empty()) return 0;
  const std::size_t k = std::max<std::size_t>(1, d.size() / 100);
  std::nth_element(d.begin(), d.end() - std::ptrdiff_t(k), d.end());
  std::sort(d.end() - std::ptrdiff_t(k), d.end());  // one summation order
  double tail = 0;
  for (auto it = d.end() - std::ptrdiff_t(k); it != d.end(); ++it) tail += *it;
  return tail / double(k);
}

void compute_metrics(FitState& s, int known_crossings) {
  FitReport& rep = s.rep;
  const FitParameters& u = s.u;
  const Eigen::MatrixX3d& V = s.V;
  const Eigen::MatrixX3i& F = s.F;
  const double diag = s.cloud.diag;
  report_progress(s.progress, 0.95, "metrics");
  const auto t0 = Clock::now();
  {
    const RoiDistances& measured = roi_distances(s);
    const Eigen::MatrixX3d& Q = measured.Q;
    const Eigen::Index nq = Q.rows();
    const Eigen::VectorXd& dist = measured.d;
    rep.hausdorff = dist.maxCoeff();
    rep.hausdorff_rel = rep.hausdorff / diag;
    rep.mean = dist.mean();
    rep.rms = std::sqrt(dist.squaredNorm() / double(nq));
    std::vector<double> sorted(dist.data(), dist.data() + nq);
    const auto i99 = sorted.begin() + long(0.99 * double(nq - 1));
    std::nth_element(sorted.begin(), i99, sorted.end());
    rep.p99 = *i99;
    rep.tail_mean = tail_mean(std::move(sorted));  // (its order is not needed after p99)
    rep.coverage_points = double((dist.array() <= u.max_match_distance).count()) / double(nq);
    rep.unexplained = unexplained_regions(Q, dist, diag, u.max_match_distance);
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
