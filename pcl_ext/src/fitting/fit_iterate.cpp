// Stage 2 of a fit (§5.3, §5.5): iterative matching + solve until the fit stops moving.
#include <algorithm>
#include <cmath>
#include <limits>

#include "fit_state.h"
#include "tbsp/core/error.h"
#include "tbsp/core/logging.h"
#include "tbsp/core/timer.h"
#include "tbsp/deform/rotation_field.h"
#include "tbsp/deform/rotations.h"
#include "tbsp/mesh/cotan_laplacian.h"
#include "tbsp/mesh/topology.h"

namespace tbsp {
namespace fit_impl {
namespace {

// What the iterations carry over from one to the next.
struct Iterations {
  std::vector<int> frozen_ids;       // constraint id per vertex while the set is frozen (-1: none)
  Eigen::MatrixX3d frozen_target;    // last target of each frozen vertex
  std::vector<double> frozen_moves;  // 99th percentile moves of the frozen iterations
  // frozen phase: each vertex's cloud neighbours within nb_cache_r of where it was when they were
  // found. Frozen iterations move vertices by a small fraction of r, so the radius-r neighbours
  // are the cached ones within r of the vertex as long as it stays within nb_cache_r - r of the
  // cache centre (exact; the tree is searched again otherwise). Saves most kd-tree searches of
  // the frozen iterations.
  NeighbourCache cache;
  Propagation prop;  // displacement propagation inside the frozen iterations (stage 3)
};

// Rotation field from the current fit: local rotations at matched vertices and markers,
// harmonically interpolated elsewhere (FitParameters::refine_rotations).
void refine_rotation_field(FitState& s, const Eigen::SparseMatrix<double>& Ct) {
  const Eigen::MatrixX3d& V = s.V;
  std::vector<int> nodes;
  std::vector<Eigen::Matrix3d> rots;
  std::vector<char> is_node(std::size_t(V.rows()), 0);
  for (Eigen::Index j = 0; j < V.rows(); ++j)
    if (s.matched[std::size_t(j)]) is_node[std::size_t(j)] = 1;
  for (int mv : s.mverts) is_node[std::size_t(mv)] = 1;
  for (int k = 0; k < Ct.outerSize(); ++k) {
    if (!is_node[std::size_t(k)]) continue;
    Eigen::Matrix3d S = Eigen::Matrix3d::Zero();
    for (Eigen::SparseMatrix<double>::InnerIterator itc(Ct, k); itc; ++itc) {
      if (itc.row() == k) continue;
      const Eigen::Vector3d e0 = (s.templ().V.row(itc.row()) - s.templ().V.row(k)).transpose();
      const Eigen::Vector3d e1 = (V.row(itc.row()) - V.row(k)).transpose();
      S += std::abs(itc.value()) * e1 * e0.transpose();
    }
    nodes.push_back(k);
    rots.push_back(closest_rotation(S));
  }
  try {
    RotationField rf;
    rf.compute(s.templ().V, s.F, nodes);
    s.D.setRotations(rf.interpolate(rots));
  } catch (const InvalidInput&) {
    // a component without nodes: keep the previous field
  }
}

// The constraints of this iteration's solve. From freeze_iteration on (and without Laplacian
// updating / remeshing, which change the system anyway), the constrained set and weights are
// frozen: later iterations only move targets, i.e. one back-substitution instead of a
// factorization, and vertices can no longer flicker in and out of the system. A frozen vertex
// that finds no match keeps its last target.
void set_constraints(FitState& s, Iterations& st, bool freeze, double w_data, const Eigen::VectorXd& match_scale) {
  const Eigen::MatrixX3d& V = s.V;
  std::vector<char>& matched = s.matched;
  if (freeze && !st.frozen_ids.empty()) {
    for (Eigen::Index j = 0; j < V.rows(); ++j) {
      const int id = st.frozen_ids[std::size_t(j)];
      if (id < 0) continue;
      if (matched[std::size_t(j)]) {
        s.D.setPositionTarget(id, s.target.row(j).transpose());
        st.frozen_target.row(j) = s.target.row(j);
      } else {
        s.target.row(j) = st.frozen_target.row(j);
      }
      matched[std::size_t(j)] = 1;
    }
    for (Eigen::Index j = 0; j < V.rows(); ++j)
      if (st.frozen_ids[std::size_t(j)] < 0) matched[std::size_t(j)] = 0;
    if (st.prop.in_loop) update_propagation(s, st.prop);
    return;
  }
  s.D.clearConstraints();
  s.addMarkers(s.D, s.u.marker_weight);
  st.frozen_ids.assign(std::size_t(V.rows()), -1);
  for (Eigen::Index j = 0; j < V.rows(); ++j)
    if (matched[std::size_t(j)])
      st.frozen_ids[std::size_t(j)] = s.D.addPositionConstraint(SurfacePoint::atVertex(int(j)), s.target.row(j).transpose(),
                                                                w_data * std::sqrt(match_scale(j)));
  st.frozen_target = s.target;
  if (!freeze) st.frozen_ids.clear();
  anchor_free_components(s, s.V, s.F, Eigen::Vector3d::Zero(), true);
  // Once frozen, the propagated constraints of §5.3 join the system right away (their targets
  // follow the matched displacements each iteration): the final system of the thesis — matched
  // + propagated constraints — is then the frozen one, factorized once, instead of a separate
  // propagation solve with a factorization of its own.
  if (freeze && s.u.propagate_displacements) start_propagation(s, st.prop);
}

}  // namespace

void anchor_free_components(FitState& s, const Eigen::MatrixX3d& X, const Eigen::MatrixX3i& F, const Eigen::Vector3d& offset,
                            bool use_matches) {
  Eigen::VectorXi label;
  const int n = connected_components(F, X.rows(), label);
  const bool any_match = use_matches && std::count(s.matched.begin(), s.matched.end(), 1) > 0;
  if (n <= 1 && (!s.mverts.empty() || any_match)) return;
  std::vector<char> held(std::size_t(n), 0);
  if (use_matches)
    for (Eigen::Index j = 0; j < X.rows() && std::size_t(j) < s.matched.size(); ++j)
      if (s.matched[std::size_t(j)]) held[std::size_t(label(j))] = 1;
  for (int mv : s.mverts)
    if (label(mv) >= 0) held[std::size_t(label(mv))] = 1;
  std::vector<Eigen::Vector3d> centre(std::size_t(n), Eigen::Vector3d::Zero());
  std::vector<int> count(std::size_t(n), 0);
  for (Eigen::Index j = 0; j < X.rows(); ++j)
    if (!held[std::size_t(label(j))]) {
      centre[std::size_t(label(j))] += X.row(j).transpose();
      ++count[std::size_t(label(j))];
    }
  std::vector<Eigen::Index> pick(std::size_t(n), -1);
  std::vector<double> best(std::size_t(n), std::numeric_limits<double>::infinity());
  for (Eigen::Index j = 0; j < X.rows(); ++j) {
    const int c = label(j);
    if (held[std::size_t(c)]) continue;
    const double d = (X.row(j).transpose() - centre[std::size_t(c)] / count[std::size_t(c)]).squaredNorm();
    if (d < best[std::size_t(c)]) {  // first vertex wins ties: deterministic
      best[std::size_t(c)] = d;
      pick[std::size_t(c)] = j;
    }
  }
  int anchored = 0;
  for (int c = 0; c < n; ++c)
    if (pick[std::size_t(c)] >= 0) {
      s.D.addPositionConstraint(SurfacePoint::atVertex(int(pick[std::size_t(c)])), X.row(pick[std::size_t(c)]).transpose() + offset,
                                s.u.propagation_weight);
      ++anchored;
    }
  if (anchored > 0)
    logger()->debug("[TemplateFitting] {} mesh component(s) without data or markers held in place", anchored);
}

bool iterate_fit(FitState& s) {
  FitReport& rep = s.rep;
  const FitParameters& u = s.u;
  const double diag = s.cloud.diag;
  Eigen::MatrixX3d& V = s.V;
  s.matched.assign(std::size_t(V.rows()), 0);
  s.target = V;
  Eigen::SparseMatrix<double> Ct;  // for refine_rotations only (built on its first use)
  Iterations st;
  bool converged = false;
  const auto t_it = Clock::now();
  for (int it = 1; it <= u.max_iterations; ++it) {
    const auto t_iter = Clock::now();
    report_progress(s.progress, 0.1 + 0.75 * double(it - 1) / std::max(u.max_iterations, 1), "matching");
    const int rsteps = u.radius_steps;
    const int freeze_it = u.freeze_iteration > 0 ? u.freeze_iteration : std::max(1, rsteps);
    const double frac = rsteps > 0 ? std::min(1.0, double(it - 1) / rsteps) : 1.0;
    const double r = u.initial_match_distance * std::pow(u.max_match_distance / u.initial_match_distance, frac);
    auto tm = Clock::now();
    // in the frozen phase (see set_constraints) only the frozen set is matched
    const bool frozen_phase = u.freeze_constraints && it >= freeze_it && !u.laplacian_updating && !u.remeshing &&
                              !st.frozen_ids.empty();
    const std::vector<char> prev_matched = s.matched;
    Eigen::VectorXd match_scale;
    const bool used_bins = match_vertices(s, r, frozen_phase, st.frozen_ids, st.cache, match_scale);
    const double t_match_it = seconds_since(tm);
    rep.t_matching += t_match_it;
    const Eigen::Index n_matched = std::count(s.matched.begin(), s.matched.end(), 1);
    if (logger()->should_log(spdlog::level::trace)) {
      Eigen::Index flips = 0;
      for (std::size_t j = 0; j < s.matched.size() && j < prev_matched.size(); ++j) flips += s.matched[j] != prev_matched[j];
      logger()->trace("[TemplateFitting] it {} r {:.4f}% matched {} flips {}", it, 100 * r / diag, n_matched, flips);
    }
    tm = Clock::now();
    double w_data = u.match_weight;
    if (u.laplacian_updating) {
      TriMesh cur;
      cur.V = V;
      cur.F = s.F;
      // the current shape can have slivers (subdivision, fairing): their vertices' rows must
      // not dominate the system (they made the solve return the current shape unchanged, or
      // the factorization fail)
      s.D.setSliverGuard(0.1);
      s.D.setMesh(cur);  // §5.5.1: the Laplacian system of the current shape
      s.D.setScale(1.0);
      s.D.setAnchor(1e-9);  // folded intermediate shapes must not make the system singular
      w_data = u.updating_match_weight;
    }
    if (u.refine_rotations && !u.laplacian_updating && it >= 2) {
      if (Ct.rows() == 0) Ct = cotangent_matrix(s.templ().V, s.templ().F);
      refine_rotation_field(s, Ct);
    }
    const bool freeze = u.freeze_constraints && it >= freeze_it && !u.laplacian_updating && !u.remeshing;
    set_constraints(s, st, freeze, w_data, match_scale);
    const Eigen::MatrixX3d Vn = s.D.deform();
    const double t_solve_it = seconds_since(tm);
    rep.t_solve += t_solve_it;
    logger()->trace("[TemplateFitting] it {} solve {:.3f} s: factorize {:.3f}, back-substitution {:.3f}, rotations {:.3f}", it,
                    t_solve_it, s.D.report().t_factorize, s.D.report().t_solve, s.D.report().t_rotations);
    // convergence is judged on the data-supported vertices: unmatched regions (holes) are
    // floppy and keep swinging slowly as a whole while the matched ones have settled (99th
    // percentile: a handful of vertices in 2-cycles through their own normals must not keep
    // the whole fit from converging)
    const double move = percentile99_move(Vn, V, s.matched);
    if (logger()->should_log(spdlog::level::trace)) {
      const Eigen::VectorXd moves = (Vn - V).rowwise().norm();
      Eigen::Index arg = 0;
      for (Eigen::Index j = 0; j < moves.rows(); ++j)
        if (s.matched[std::size_t(j)] && moves(j) > moves(arg)) arg = j;
      logger()->trace("[TemplateFitting] it {} max matched move {:.4f}% at vertex {} (target dist {:.4f}%), #moving>0.1%d {}", it,
                      100 * move / diag, arg, 100 * (s.target.row(arg) - V.row(arg)).norm() / diag,
                      (moves.array() > 1e-3 * diag).count());
    }
    // stop: the 99th percentile move is below the tolerance, or it has stalled near it (a few
    // vertices cycling through their own normals or in and out of thin parts: no progress is
    // being made, more iterations only cost time)
    const bool in_freeze = freeze && !st.frozen_ids.empty();
    bool stop = move < u.tolerance && frac >= 1.0;
    bool stalled = false;
    const auto& fm = st.frozen_moves;
    if (!stop && in_freeze && frac >= 1.0 && fm.size() >= 3 && move < 5 * u.tolerance) {
      const double best = std::min(fm[fm.size() - 1], fm[fm.size() - 2]);
      stalled = stop = move > 0.95 * best;
    }
    if (in_freeze) st.frozen_moves.push_back(move);
    // frozen iterations are a linear solve after a projection: over-relaxing the step speeds up
    // the slow creep of the fixed point; the last step is never relaxed (the output solves the
    // system)
    if (in_freeze && !stop && it < u.max_iterations && u.relaxation != 1.0) V += u.relaxation * (Vn - V);
    else V = Vn;
    bool remeshed = false;
    if (u.remeshing && V.rows() < u.max_vertices && it >= 2 && it < u.max_iterations) remeshed = remesh_step(s, r);
    if (u.fairing && u.fairing_steps > 0) fairing_step(s, r);
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
    rep.message += "stopped after max_iterations (" + std::to_string(u.max_iterations) +
                   ") before the largest vertex move fell below the tolerance. ";
  }
  return converged;
}

}  // namespace fit_impl
}  // namespace tbsp
