// Coarse stage of a fit (fitting v2): a stiffness-annealed non-rigid ICP of an embedded
// deformation graph (deformation_graph.h) between the initial deformation and the §5.3
// iterations, so that parts turned about joints (a head, an ear, a limb) follow the data as
// wholes instead of being pulled along their normals vertex by vertex.
//
// Each step: correspondences both ways between the deformed template and the cloud (a sample of
// template vertices → nearest cloud point, a sample of cloud points → nearest deformed vertex;
// normal-compatible, within a radius that shrinks over the rounds, the farthest 10 % dropped),
// point-to-plane residuals on the cloud normal plus a small point-to-point part, the markers as
// point-to-point residuals, one Gauss-Newton step of the graph. The stiffness α falls
// geometrically over the rounds (Amberg et al. 2007): the first rounds move near-rigid parts,
// the last ones let the graph bend. The cloud → template direction is what pulls a template
// part towards data that no template vertex is near yet (a turned ear's points). Afterwards the
// coarse shape is the rest shape of the later stages: its Laplacian coordinates carry the
// template's detail as the graph turned it. (Steering the template's δ by the graph's
// rotations instead was measured worse: 45° bunny, clean Hausdorff 1.22 % against 0.59 %, the
// compressed inner side of a bend springs back; docs/dev/fitting_experiments.md.)
#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

#include "fit_state.h"
#include "tbsp/core/logging.h"
#include "tbsp/core/timer.h"
#include "tbsp/deform/deformation_graph.h"
#include "tbsp/mesh/point_normals.h"
#include "tbsp/mesh/topology.h"

namespace tbsp {
namespace fit_impl {
namespace {

// Fixed-stride sample of at most `cap` of the indices with ok[i] (deterministic).
std::vector<Eigen::Index> stride_sample(const std::vector<char>& ok, std::size_t cap) {
  std::size_t n = 0;
  for (char c : ok) n += c != 0;
  const std::size_t stride = std::max<std::size_t>(1, (n + cap - 1) / std::max<std::size_t>(cap, 1));
  std::vector<Eigen::Index> out;
  for (std::size_t i = 0, k = 0; i < ok.size(); ++i)
    if (ok[i] && k++ % stride == 0) out.push_back(Eigen::Index(i));
  return out;
}

struct Pair {
  int vertex;
  Eigen::Vector3d point, normal;
  double dist;
};

// One graph of `nodes` nodes built on X and fitted to the cloud over the stiffness schedule;
// returns the deformed template (all vertices), adds the Gauss-Newton steps to `steps_run` and
// sets `node_count` to the graph's nodes. Progress from `lo` to `hi` over the rounds (a stop
// asked for through it is seen within one step).
// With `rest` (#V rows), the graph is built on that shape instead (its rigidity is measured
// against it) and starts with the transforms that carry it onto X0 (fitTransformsTo); only the
// rounds from `first_round` on run.
Eigen::MatrixX3d fit_graph(FitState& s, const Eigen::MatrixX3d& X0, int nodes, int& steps_run, int& node_count, double lo, double hi,
                           const Eigen::MatrixX3d* rest = nullptr, int first_round = 0) {
  const Eigen::Index nv = X0.rows();
  const Eigen::MatrixX3d& base = rest ? *rest : X0;  // the shape the graph is built on
  DeformationGraph graph;
  graph.build(base, s.F, nodes, 4);
  if (rest) graph.fitTransformsTo(X0);
  node_count = graph.nodeCount();
  if (logger()->should_log(spdlog::level::debug))
    logger()->debug("[TemplateFitting] coarse graph{}: {} nodes, {} edges ({} between separate parts)",
                    rest ? " on the template (rounds " + std::to_string(first_round + 1) + "-" + std::to_string(s.u.coarse_rounds) + " again)"
                         : std::string(),
                    node_count, graph.edges().size(), graph.crossComponentEdges());
  // samples: template vertices (not masked) and ROI cloud points
  std::vector<char> vok(std::size_t(nv), 1);
  for (std::size_t v = 0; v < s.masked.size() && v < vok.size(); ++v) vok[v] = !s.masked[v];
  const std::vector<Eigen::Index> vs = stride_sample(vok, 6000);
  const std::vector<Eigen::Index> ps = stride_sample(s.cloud.roi_ok, 6000);
  const double cos_max = std::cos(s.u.coarse_normal_angle_deg * M_PI / 180.0);
  const int rounds = s.u.coarse_rounds;
  const double r_start = s.u.coarse_radius * s.cloud.diag, r_end = std::max(2.0 * s.u.max_match_distance, 0.01 * s.cloud.diag);
  const double a_start = s.u.coarse_stiffness, a_end = s.u.coarse_final_stiffness;
  const double tol = 1e-3 * s.cloud.diag;  // a round ends when the graph moves less (measured: same fit as 1e-4, 40 % fewer steps)
  // the iterations need the sampled vertices only: their positions, and normals turned by the
  // graph (the blended node rotations applied to the rest normal); all vertices at the end
  const Eigen::MatrixX3d N0 = vertex_normals(base, s.F);
  // on a graph built on another rest shape, a surface component without data or markers is not
  // at rest (its start transforms reproduce X0 only up to the blending) and nothing anchors it:
  // its sampled vertices are held at X0 (a component that keeps no constraint could otherwise
  // turn as a whole)
  Eigen::VectorXi component;
  const int n_components = rest ? connected_components(s.F, nv, component) : 0;
  Eigen::MatrixX3d Xs(Eigen::Index(vs.size()), 3), Ns(Eigen::Index(vs.size()), 3);
  for (int round = first_round; round < rounds; ++round) {
    const double f = rounds > 1 ? double(round) / (rounds - 1) : 1.0;
    const double radius = r_start * std::pow(r_end / r_start, f);
    const double stiff = a_start * std::pow(a_end / a_start, f);
    for (int step = 0; step < s.u.coarse_steps; ++step) {
      report_progress(s.progress, lo + (hi - lo) * (round + double(step) / s.u.coarse_steps) / rounds, "coarse stage");
#pragma omp parallel for schedule(static)
      for (std::size_t k = 0; k < vs.size(); ++k) {
        const int v = int(vs[k]);
        Xs.row(Eigen::Index(k)) = graph.deformVertex(v).transpose();
        Ns.row(Eigen::Index(k)) = graph.turnedNormal(v, N0.row(v).transpose()).transpose();
      }
      const PointSearch xs(Xs);
      std::vector<Pair> fwd(vs.size()), bwd(ps.size());
#pragma omp parallel for schedule(static)
      for (std::size_t k = 0; k < vs.size(); ++k) {
        const Eigen::Vector3d x = Xs.row(Eigen::Index(k)).transpose();
        double d2 = 0;
        const Eigen::Index c = s.cloud.search.nearest(x, &d2);
        Pair p{int(vs[k]), Eigen::Vector3d::Zero(), Eigen::Vector3d::Zero(), -1};
        if (c >= 0 && s.cloud.roi_ok[std::size_t(c)] && std::sqrt(d2) < radius && s.N.row(c).dot(Ns.row(Eigen::Index(k))) > cos_max)
          p = Pair{int(vs[k]), s.cloud.P.row(c).transpose(), s.N.row(c).transpose(), std::sqrt(d2)};
        fwd[k] = p;
      }
#pragma omp parallel for schedule(static)
      for (std::size_t k = 0; k < ps.size(); ++k) {
        const Eigen::Vector3d q = s.cloud.P.row(ps[k]).transpose();
        double d2 = 0;
        const Eigen::Index j = xs.nearest(q, &d2);
        Pair p{-1, q, s.N.row(ps[k]).transpose(), -1};
        if (j >= 0 && std::sqrt(d2) < radius && s.N.row(ps[k]).dot(Ns.row(j)) > cos_max) {
          p.vertex = int(vs[std::size_t(j)]);
          p.dist = std::sqrt(d2);
        }
        bwd[k] = p;
      }
      std::vector<double> d;
      for (const auto* set : {&fwd, &bwd})
        for (const Pair& p : *set)
          if (p.dist >= 0) d.push_back(p.dist);
      double cut = radius;
      if (d.size() > 10) {
        const std::size_t q = std::size_t(0.9 * double(d.size()));
        std::nth_element(d.begin(), d.begin() + long(q), d.end());
        cut = d[q];
      }
      std::vector<GraphConstraint> cons;
      const double n_data = double(d.size());
      for (const auto* set : {&fwd, &bwd})
        for (const Pair& p : *set) {
          if (p.dist < 0 || p.dist > cut) continue;
          cons.push_back({p.vertex, p.point, p.normal, 1.0});
          cons.push_back({p.vertex, p.point, Eigen::Vector3d::Zero(), s.u.coarse_point_weight});
        }
      const double wm = s.u.marker_weight * std::max(1.0, n_data) / std::max(1, graph.nodeCount());
      for (std::size_t m = 0; m < s.mverts.size() && m < s.mtarget.size(); ++m)
        cons.push_back({s.mverts[m], s.mtarget[m], Eigen::Vector3d::Zero(), wm * s.markers[m].weight});
      if (n_components > 0) {
        std::vector<char> held(std::size_t(n_components), 0);
        for (const GraphConstraint& c : cons) held[std::size_t(component(c.vertex))] = 1;
        for (Eigen::Index v : vs)
          if (!held[std::size_t(component(v))]) cons.push_back({int(v), X0.row(v).transpose(), Eigen::Vector3d::Zero(), 1.0});
      }
      const double alpha = stiff * std::max(1.0, n_data) / std::max<std::size_t>(1, 2 * graph.edges().size());
      const double move = graph.solve(cons, alpha, 1);
      ++steps_run;
      if (move < tol) break;
    }
  }
  return graph.deform();
}

}  // namespace

void coarse_stage(FitState& s) {
  if (s.u.coarse_nodes <= 0) return;
  const auto t0 = Clock::now();
  report_progress(s.progress, 0.08, "coarse stage");
  FitReport& rep = s.rep;
  int steps_run = 0, nodes = 0;
  // the second hypothesis of a fit without markers: a coarser graph first, whose part-sized
  // regions (a head, a limb) turn as wholes towards the data, then the fine graph from there
  Eigen::MatrixX3d X = s.V;
  if (s.coarse_prepass > 0 && s.coarse_prepass < s.u.coarse_nodes) {
    X = fit_graph(s, X, s.coarse_prepass, steps_run, nodes, 0.08, 0.09);
    rep.coarse_prepass_nodes = nodes;
  }
  const bool second_half = !s.markers.empty() && !s.markers_from_fit && s.u.coarse_rounds > 1;
  X = fit_graph(s, X, s.u.coarse_nodes, steps_run, nodes, s.coarse_prepass > 0 ? 0.09 : 0.08, second_half ? 0.095 : 0.1);
  if (second_half) {
    // The user's markers posed the template (stage 1), and the graph above measured its
    // rigidity against that pose: where few markers sit on a part (a forearm), the pose is
    // distorted (more so without the rotation field), and the graph kept the distortion as its
    // rest. So the second half of the rounds runs again on a graph built on the template itself
    // (scaled by stage 1's λ, rigidly aligned to the shape so far; its transforms start at that
    // shape): rigid against the template's own shape where the data leave the shape open
    // (measured: articulated Armadillo at 45°, clean Hausdorff 0.80–1.28 → 0.30–0.52 %; a hole
    // that swallows a bent limb keeps the limb less bent; docs/dev/fitting_experiments.md
    // 2026-12-07 (12)).
    const Eigen::MatrixX3d scaled = s.rep.scale * s.templ().V;
    const Eigen::Matrix4d T = Eigen::umeyama(scaled.transpose(), X.transpose(), false);
    const Eigen::MatrixX3d rest = (scaled * T.topLeftCorner<3, 3>().transpose()).rowwise() + T.topRightCorner<3, 1>().transpose();
    X = fit_graph(s, X, s.u.coarse_nodes, steps_run, nodes, 0.095, 0.1, &rest, (s.u.coarse_rounds + 1) / 2);
  }
  // the later stages refine the coarse shape: it becomes their rest shape (its Laplacian
  // coordinates carry the template's detail as the graph turned it), at scale 1, no rotations
  s.coarse.V = X;
  s.coarse.F = s.F;
  s.useTemplate(s.coarse);
  s.D.setMesh(s.coarse);
  s.D.setScale(1.0);
  s.D.setRotations({});
  s.D.setUseRotationField(false);
  s.V = X;
  s.V0 = X;
  rep.coarse_steps = steps_run;
  rep.coarse_nodes = nodes;
  rep.t_coarse = seconds_since(t0);
  logger()->debug("[TemplateFitting] coarse stage: {} nodes, {} steps, {:.3f} s", rep.coarse_nodes, steps_run, rep.t_coarse);
}

}  // namespace fit_impl
}  // namespace tbsp
