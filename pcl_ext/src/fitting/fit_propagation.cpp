// Stage 3 of a fit (§5.3 end): the normal displacements of the matched vertices relative to the
// initial deformation, harmonically interpolated, as targets of the unmatched ones. With a
// frozen constraint set (the default) the propagated constraints join the frozen system inside
// the iterations (start_propagation / update_propagation); otherwise one extra solve here.
#include <algorithm>

#include "fit_state.h"
#include "tbsp/core/error.h"
#include "tbsp/core/timer.h"
#include "tbsp/mesh/cotan_laplacian.h"

namespace tbsp {
namespace fit_impl {

Eigen::MatrixX3d Propagation::targets(const Eigen::MatrixX3d& X, const Eigen::MatrixX3d& V0) const {
  Eigen::MatrixXd d(Eigen::Index(sources.size()), 1);
  for (std::size_t k = 0; k < sources.size(); ++k)
    d(Eigen::Index(k), 0) = (X.row(sources[k]) - V0.row(sources[k])).dot(N0.row(sources[k]));
  const Eigen::MatrixXd dense = harmonic.interpolate(d);
  Eigen::MatrixX3d T = V0;
  for (Eigen::Index j = 0; j < V0.rows(); ++j) T.row(j) += dense(j, 0) * N0.row(j);
  return T;
}

void start_propagation(FitState& s, Propagation& p) {
  const auto tp = Clock::now();
  const Eigen::MatrixX3d& V = s.V;
  p.sources.clear();
  bool any_unmatched = false;
  for (Eigen::Index j = 0; j < V.rows(); ++j) {
    if (s.matched[std::size_t(j)]) p.sources.push_back(int(j));
    else if (!s.masked[std::size_t(j)]) any_unmatched = true;
  }
  s.prop_ids.assign(std::size_t(V.rows()), -1);
  p.in_loop = false;
  if (!p.sources.empty() && any_unmatched) {
    try {
      p.N0 = vertex_normals(s.V0, s.F);
      p.harmonic.compute(s.V0, s.F, p.sources);
      const Eigen::MatrixX3d T = p.targets(V, s.V0);
      for (Eigen::Index j = 0; j < V.rows(); ++j)
        if (!s.matched[std::size_t(j)] && !s.masked[std::size_t(j)])
          s.prop_ids[std::size_t(j)] =
              s.D.addPositionConstraint(SurfacePoint::atVertex(int(j)), T.row(j).transpose(), s.u.propagation_weight);
      p.in_loop = true;
    } catch (const InvalidInput&) {
      s.prop_ids.assign(std::size_t(V.rows()), -1);
      s.rep.message += "displacement propagation skipped (a mesh component has no matched vertex). ";
    }
  }
  // done here (or nothing to propagate: every unmasked vertex matched), not again in stage 3
  s.propagation_handled = true;
  s.rep.t_propagation += seconds_since(tp);
}

void update_propagation(FitState& s, const Propagation& p) {
  const auto tp = Clock::now();
  const Eigen::MatrixX3d T = p.targets(s.V, s.V0);
  for (Eigen::Index j = 0; j < s.V.rows(); ++j)
    if (s.prop_ids[std::size_t(j)] >= 0) s.D.setPositionTarget(s.prop_ids[std::size_t(j)], T.row(j).transpose());
  s.rep.t_propagation += seconds_since(tp);
}

void propagate_displacements(FitState& s) {
  const FitParameters& u = s.u;
  const Eigen::MatrixX3d& V0 = s.V0;
  Eigen::MatrixX3d& V = s.V;
  std::vector<VertexStatus>& status = s.status;
  status.assign(std::size_t(V.rows()), VertexStatus::Unmatched);
  for (Eigen::Index j = 0; j < V.rows(); ++j) {
    if (s.masked[std::size_t(j)]) status[std::size_t(j)] = VertexStatus::Masked;
    else if (s.matched[std::size_t(j)]) status[std::size_t(j)] = VertexStatus::Matched;
  }
  if (s.propagation_handled) {
    for (Eigen::Index j = 0; j < V.rows(); ++j)
      if (j < Eigen::Index(s.prop_ids.size()) && s.prop_ids[std::size_t(j)] >= 0)
        status[std::size_t(j)] = VertexStatus::Propagated;
    return;
  }
  if (!u.propagate_displacements || u.max_iterations == 0) return;
  const auto t0 = Clock::now();
  report_progress(s.progress, 0.88, "propagation");
  std::vector<int> m_idx;
  for (Eigen::Index j = 0; j < V.rows(); ++j)
    if (status[std::size_t(j)] == VertexStatus::Matched) m_idx.push_back(int(j));
  const bool any_unmatched =
      std::any_of(status.begin(), status.end(), [](VertexStatus st) { return st == VertexStatus::Unmatched; });
  if (!m_idx.empty() && any_unmatched) {
    const Eigen::MatrixX3d N0 = vertex_normals(V0, s.F);
    Eigen::MatrixXd d(Eigen::Index(m_idx.size()), 1);
    for (std::size_t k = 0; k < m_idx.size(); ++k)
      d(Eigen::Index(k), 0) = (V.row(m_idx[k]) - V0.row(m_idx[k])).dot(N0.row(m_idx[k]));
    Eigen::MatrixXd dense;
    try {
      dense = harmonic_interpolation(V0, s.F, m_idx, d);
    } catch (const InvalidInput&) {
      dense.resize(0, 1);  // a component without matches: nothing to propagate there
      s.rep.message += "displacement propagation skipped (a mesh component has no matched vertex). ";
    }
    if (dense.rows() == V.rows()) {
      s.D.clearConstraints();
      s.addMarkers(s.D, u.marker_weight);
      for (Eigen::Index j = 0; j < V.rows(); ++j) {
        if (status[std::size_t(j)] == VertexStatus::Matched)
          s.D.addPositionConstraint(SurfacePoint::atVertex(int(j)), s.target.row(j).transpose(),
                                    u.laplacian_updating ? u.updating_match_weight : u.match_weight);
        else if (status[std::size_t(j)] == VertexStatus::Unmatched) {
          s.D.addPositionConstraint(SurfacePoint::atVertex(int(j)), (V0.row(j) + dense(j, 0) * N0.row(j)).transpose(),
                                    u.propagation_weight);
          status[std::size_t(j)] = VertexStatus::Propagated;
        }
      }
      V = s.D.deform();
    }
  }
  s.rep.t_propagation = seconds_since(t0);
}

}  // namespace fit_impl
}  // namespace tbsp
