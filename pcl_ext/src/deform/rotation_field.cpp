#include "tbsp/deform/rotation_field.h"

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>
#include <queue>
#include <set>
#include <string>

#include "tbsp/core/error.h"
#include "tbsp/deform/rotations.h"
#include "tbsp/mesh/geodesics.h"

namespace tbsp {

ConstraintGraph ConstraintGraph::build(const Eigen::MatrixX3d& V, const Eigen::MatrixX3i& F,
                                       const std::vector<int>& nodes, int extra_neighbours,
                                       const ProgressCallback& progress) {
  const std::string who = "[tbsp::ConstraintGraph::build] ";
  {
    std::set<int> s;
    for (int v : nodes) {
      if (v < 0 || v >= V.rows())
        throw InvalidInput(who + "node vertex " + std::to_string(v) + " is out of range (mesh has " +
                           std::to_string(V.rows()) + " vertices)");
      if (!s.insert(v).second) throw InvalidInput(who + "vertex " + std::to_string(v) + " is a node twice");
    }
  }
  ConstraintGraph g;
  g.nodes = nodes;
  const int k = int(nodes.size());
  g.geodesic = k ? geodesic_distance_matrix(V, F, nodes, progress) : Eigen::MatrixXd();
  const double inf = std::numeric_limits<double>::infinity();
  std::set<std::pair<int, int>> edges;
  // Prim's MST forest on the dense distance matrix: O(k²).
  g.tree_parent.assign(std::size_t(k), -1);
  std::vector<char> in_tree(std::size_t(k), 0);
  std::vector<double> best(std::size_t(k), inf);
  std::vector<int> best_from(std::size_t(k), -1);
  for (int added = 0; added < k; ++added) {
    int u = -1;
    for (int i = 0; i < k; ++i)
      if (!in_tree[std::size_t(i)] && (u < 0 || best[std::size_t(i)] < best[std::size_t(u)])) u = i;
    in_tree[std::size_t(u)] = 1;
    if (best_from[std::size_t(u)] >= 0 && std::isfinite(best[std::size_t(u)])) {
      g.tree_parent[std::size_t(u)] = best_from[std::size_t(u)];
      edges.emplace(std::min(u, best_from[std::size_t(u)]), std::max(u, best_from[std::size_t(u)]));
    }
    for (int i = 0; i < k; ++i)
      if (!in_tree[std::size_t(i)] && g.geodesic(u, i) < best[std::size_t(i)]) {
        best[std::size_t(i)] = g.geodesic(u, i);
        best_from[std::size_t(i)] = u;
      }
  }
  // + the nearest `extra_neighbours` nodes of each node
  for (int a = 0; a < k; ++a) {
    std::vector<int> idx;
    for (int b = 0; b < k; ++b)
      if (b != a && std::isfinite(g.geodesic(a, b))) idx.push_back(b);
    const std::size_t m = std::min<std::size_t>(std::size_t(std::max(extra_neighbours, 0)), idx.size());
    std::partial_sort(idx.begin(), idx.begin() + long(m), idx.end(),
                      [&](int x, int y) { return g.geodesic(a, x) < g.geodesic(a, y); });
    for (std::size_t j = 0; j < m; ++j) edges.emplace(std::min(a, idx[j]), std::max(a, idx[j]));
  }
  g.edges.assign(edges.begin(), edges.end());
  g.neighbours.assign(std::size_t(k), {});
  for (auto& e : g.edges) {
    g.neighbours[std::size_t(e.first)].push_back(e.second);
    g.neighbours[std::size_t(e.second)].push_back(e.first);
  }
  // BFS order over the MST forest (parents before children)
  std::vector<std::vector<int>> children(static_cast<std::size_t>(k));
  for (int i = 0; i < k; ++i)
    if (g.tree_parent[std::size_t(i)] >= 0) children[std::size_t(g.tree_parent[std::size_t(i)])].push_back(i);
  for (int r = 0; r < k; ++r) {
    if (g.tree_parent[std::size_t(r)] >= 0) continue;
    std::queue<int> q;
    q.push(r);
    while (!q.empty()) {
      int u = q.front();
      q.pop();
      g.tree_order.push_back(u);
      for (int c : children[std::size_t(u)]) q.push(c);
    }
  }
  return g;
}

std::vector<Eigen::Matrix3d> node_rotations(const ConstraintGraph& graph, const Eigen::MatrixX3d& P,
                                            const Eigen::MatrixX3d& Q) {
  const std::size_t k = graph.nodes.size();
  if (std::size_t(P.rows()) != k || std::size_t(Q.rows()) != k)
    throw InvalidInput("[tbsp::node_rotations] expected " + std::to_string(k) + " rest and target positions, got " +
                       std::to_string(P.rows()) + " and " + std::to_string(Q.rows()));
  std::vector<Eigen::Matrix3d> R(k, Eigen::Matrix3d::Identity());
  for (std::size_t i = 0; i < k; ++i) {
    const auto& nb = graph.neighbours[i];
    if (nb.empty()) continue;
    Eigen::MatrixXd E(nb.size(), 3), E2(nb.size(), 3);
    for (std::size_t j = 0; j < nb.size(); ++j) {
      E.row(Eigen::Index(j)) = P.row(Eigen::Index(i)) - P.row(nb[j]);
      E2.row(Eigen::Index(j)) = Q.row(Eigen::Index(i)) - Q.row(nb[j]);
    }
    // eq. 3.13 in row form: E T = E2  =>  T = (EᵀE)⁻¹ EᵀE2; column-vector map A = Tᵀ
    const Eigen::Matrix3d EtE = E.transpose() * E;
    const Eigen::Matrix3d cross = E2.transpose() * E;  // Σ e' eᵀ
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(EtE);
    const auto ev = es.eigenvalues();
    Eigen::Matrix3d A;
    if (ev(0) > 1e-6 * ev(2) && ev(2) > 0)
      A = cross * EtE.inverse();  // = Tᵀ of eq. 3.13
    else
      A = cross;  // Procrustes: closest rotation of Σ e'eᵀ is the best rigid fit
    R[i] = closest_rotation(A);
  }
  return R;
}

void RotationField::compute(const Eigen::MatrixX3d& V, const Eigen::MatrixX3i& F, const std::vector<int>& nodes,
                            std::vector<int> tree_parent, std::vector<int> tree_order, LaplacianWeights weights) {
  compute(laplacian_stiffness(V, F, weights), F, nodes, std::move(tree_parent), std::move(tree_order));
}

void RotationField::compute(const Eigen::SparseMatrix<double>& C, const Eigen::MatrixX3i& F, const std::vector<int>& nodes,
                            std::vector<int> tree_parent, std::vector<int> tree_order) {
  harmonic_.compute(C, F, nodes);
  if (tree_parent.empty()) {
    parent_.assign(nodes.size(), -1);
    order_.resize(nodes.size());
    std::iota(order_.begin(), order_.end(), 0);
  } else {
    if (tree_parent.size() != nodes.size() || tree_order.size() != nodes.size())
      throw InvalidInput("[tbsp::RotationField::compute] tree_parent/tree_order must have one entry per node");
    parent_ = std::move(tree_parent);
    order_ = std::move(tree_order);
  }
}

std::vector<Eigen::Matrix3d> RotationField::interpolate(const std::vector<Eigen::Matrix3d>& node_rot) const {
  const auto& nodes = harmonic_.constrained();
  if (node_rot.size() != nodes.size())
    throw InvalidInput("[tbsp::RotationField::interpolate] got " + std::to_string(node_rot.size()) +
                       " rotations for " + std::to_string(nodes.size()) + " nodes");
  std::vector<Eigen::Quaterniond> q(node_rot.size());
  for (std::size_t i = 0; i < q.size(); ++i) q[i] = Eigen::Quaterniond(closest_rotation(node_rot[i])).normalized();
  make_hemisphere_consistent(q, order_, parent_);
  Eigen::MatrixXd vals(Eigen::Index(q.size()), 4);
  for (std::size_t i = 0; i < q.size(); ++i) vals.row(Eigen::Index(i)) = q[i].coeffs().transpose();
  const Eigen::MatrixXd dense = harmonic_.interpolate(vals);
  std::vector<Eigen::Matrix3d> out(static_cast<std::size_t>(dense.rows()));
  for (Eigen::Index v = 0; v < dense.rows(); ++v) {
    Eigen::Vector4d c = dense.row(v).transpose();
    const double len = c.norm();
    if (!(len > 1e-9)) { out[std::size_t(v)].setIdentity(); continue; }
    Eigen::Quaterniond qq;
    qq.coeffs() = c / len;
    out[std::size_t(v)] = qq.toRotationMatrix();
  }
  return out;
}

}  // namespace tbsp
