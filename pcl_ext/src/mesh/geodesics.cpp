#include "tbsp/mesh/geodesics.h"

#include <algorithm>
#include <atomic>
#include <limits>
#include <cmath>
#include <set>
#include <string>

#include "dary_heap.h"
#include "tbsp/core/error.h"
#include "tbsp/mesh/topology.h"

namespace tbsp {

Eigen::VectorXd dijkstra_distances(const Eigen::MatrixX3d& V, const std::vector<std::vector<int>>& adjacency,
                                   const std::vector<int>& sources) {
  const Eigen::Index n = V.rows();
  const double inf = std::numeric_limits<double>::infinity();
  Eigen::VectorXd d = Eigen::VectorXd::Constant(n, inf);
  using Item = std::pair<double, int>;
  detail::DaryMinHeap<Item> heap;
  for (int s : sources) {
    if (s < 0 || s >= n)
      throw InvalidInput("[tbsp::dijkstra_distances] source vertex " + std::to_string(s) + " is out of range (mesh has " +
                         std::to_string(n) + " vertices)");
    d(s) = 0;
    heap.emplace(0.0, s);
  }
  while (!heap.empty()) {
    auto [du, u] = heap.top();
    heap.pop();
    if (du > d(u)) continue;
    for (int v : adjacency[std::size_t(u)]) {
      const double nd = du + (V.row(u) - V.row(v)).norm();
      if (nd < d(v)) {
        d(v) = nd;
        heap.emplace(nd, v);
      }
    }
  }
  return d;
}

namespace {
/// The edge graph in compressed rows with the edge lengths precomputed: the Dijkstra loop then
/// reads contiguous memory instead of gathering vertex rows (column-major V) per relaxation.
struct EdgeGraph {
  std::vector<int> start, to;
  std::vector<double> length;
  EdgeGraph(const Eigen::MatrixX3d& V, const Eigen::MatrixX3i& F) {
    vertex_adjacency_compressed(F, V.rows(), start, to);
    length.resize(to.size());
    for (std::size_t u = 0; u + 1 < start.size(); ++u)
      for (int e = start[u]; e < start[u + 1]; ++e) length[std::size_t(e)] = (V.row(Eigen::Index(u)) - V.row(to[std::size_t(e)])).norm();
  }
};

/// Dijkstra from one source that stops once every target is settled: distances at the targets.
std::vector<double> dijkstra_to_targets(const EdgeGraph& g, int source, const std::vector<int>& targets,
                                        std::vector<int>& target_slot, std::vector<int>* predecessor = nullptr) {
  const double inf = std::numeric_limits<double>::infinity();
  const std::size_t n = g.start.size() - 1;
  std::vector<double> d(n, inf);
  if (predecessor) predecessor->assign(n, -1);
  using Item = std::pair<double, int>;
  detail::DaryMinHeap<Item> heap;
  d[static_cast<std::size_t>(source)] = 0;
  heap.emplace(0.0, source);
  std::size_t left = targets.size();
  std::vector<char> settled(targets.size(), 0);
  while (!heap.empty() && left > 0) {
    auto [du, u] = heap.top();
    heap.pop();
    if (du > d[static_cast<std::size_t>(u)]) continue;
    const int slot = target_slot[static_cast<std::size_t>(u)];
    if (slot >= 0 && !settled[static_cast<std::size_t>(slot)]) {
      settled[static_cast<std::size_t>(slot)] = 1;
      --left;
    }
    for (int e = g.start[std::size_t(u)]; e < g.start[std::size_t(u) + 1]; ++e) {
      const int v = g.to[std::size_t(e)];
      const double nd = du + g.length[std::size_t(e)];
      if (nd < d[static_cast<std::size_t>(v)]) {
        d[static_cast<std::size_t>(v)] = nd;
        if (predecessor) (*predecessor)[static_cast<std::size_t>(v)] = u;
        heap.emplace(nd, v);
      }
    }
  }
  std::vector<double> out(targets.size());
  for (std::size_t t = 0; t < targets.size(); ++t) out[t] = d[static_cast<std::size_t>(targets[t])];
  return out;
}

/// Checks the vertex indices; vertex -> index in `vertices` (a repeated vertex: its first index;
/// the others read the same distance because they are the same vertex), -1 elsewhere.
std::vector<int> target_slots(Eigen::Index n, const std::vector<int>& vertices, const char* who) {
  for (int v : vertices)
    if (v < 0 || v >= n)
      throw InvalidInput(std::string("[tbsp::") + who + "] vertex " + std::to_string(v) + " is out of range (mesh has " +
                         std::to_string(n) + " vertices)");
  std::vector<int> slot(static_cast<std::size_t>(n), -1);
  for (int b = int(vertices.size()) - 1; b >= 0; --b) slot[std::size_t(vertices[std::size_t(b)])] = b;
  return slot;
}
}  // namespace

Eigen::MatrixXd geodesic_distance_matrix(const Eigen::MatrixX3d& V, const Eigen::MatrixX3i& F,
                                         const std::vector<int>& vertices, const ProgressCallback& progress) {
  const EdgeGraph graph(V, F);
  const int k = int(vertices.size());
  Eigen::MatrixXd D(k, k);
  std::vector<int> slot = target_slots(V.rows(), vertices, "geodesic_distance_matrix");
  std::atomic<int> done{0};
  std::atomic<bool> cancelled{false};
#pragma omp parallel for schedule(dynamic)
  for (int a = 0; a < k; ++a) {
    if (cancelled) continue;
    const std::vector<double> d = dijkstra_to_targets(graph, vertices[std::size_t(a)], vertices, slot);
    for (int b = 0; b < k; ++b) D(a, b) = d[std::size_t(b)];
    const int n_done = ++done;
#pragma omp critical
    {
      if (progress && !cancelled && !progress(double(n_done) / k, "geodesics")) cancelled = true;
    }
  }
  if (cancelled) throw Cancelled("cancelled during 'geodesics'");
  return 0.5 * (D + D.transpose());
}

std::vector<std::vector<std::vector<int>>> geodesic_paths(const Eigen::MatrixX3d& V, const Eigen::MatrixX3i& F,
                                                         const std::vector<int>& vertices) {
  const EdgeGraph graph(V, F);
  const int k = int(vertices.size());
  std::vector<int> slot = target_slots(V.rows(), vertices, "geodesic_paths");
  std::vector<std::vector<std::vector<int>>> paths(static_cast<std::size_t>(k));
  for (auto& row : paths) row.resize(static_cast<std::size_t>(k));
#pragma omp parallel for schedule(dynamic)
  for (int a = 0; a < k; ++a) {
    std::vector<int> pred;
    const std::vector<double> d = dijkstra_to_targets(graph, vertices[std::size_t(a)], vertices, slot, &pred);
    for (int b = 0; b < k; ++b) {
      if (!std::isfinite(d[std::size_t(b)]) || vertices[std::size_t(b)] == vertices[std::size_t(a)]) continue;
      std::vector<int>& path = paths[std::size_t(a)][std::size_t(b)];
      for (int v = vertices[std::size_t(b)]; v >= 0; v = pred[std::size_t(v)]) path.push_back(v);
      std::reverse(path.begin(), path.end());
    }
  }
  return paths;
}

double path_length(const Eigen::MatrixX3d& V, const std::vector<int>& path) {
  double len = 0;
  for (std::size_t i = 1; i < path.size(); ++i) len += (V.row(path[i]) - V.row(path[i - 1])).norm();
  return len;
}

double global_scale_from_geodesics(const Eigen::MatrixX3d& V_reference, const Eigen::MatrixX3d& V_deformed,
                                   const Eigen::MatrixX3i& F, const std::vector<int>& marked) {
  const std::string who = "[tbsp::global_scale_from_geodesics] ";
  if (V_reference.rows() != V_deformed.rows())
    throw InvalidInput(who + "reference and deformed meshes differ in vertex count (" +
                       std::to_string(V_reference.rows()) + " vs " + std::to_string(V_deformed.rows()) +
                       "); pass two poses of the same mesh");
  std::vector<int> m(marked);
  std::sort(m.begin(), m.end());
  m.erase(std::unique(m.begin(), m.end()), m.end());
  if (m.size() < 2) throw InvalidInput(who + "needs at least 2 distinct marked vertices (got " + std::to_string(m.size()) + ")");
  const Eigen::MatrixXd D0 = geodesic_distance_matrix(V_reference, F, m);
  const Eigen::MatrixXd D1 = geodesic_distance_matrix(V_deformed, F, m);
  double sum = 0;
  int count = 0;
  for (std::size_t a = 0; a < m.size(); ++a)
    for (std::size_t b = a + 1; b < m.size(); ++b) {
      const double d0 = D0(Eigen::Index(a), Eigen::Index(b)), d1 = D1(Eigen::Index(a), Eigen::Index(b));
      if (std::isfinite(d0) && std::isfinite(d1) && d0 > 0) {
        sum += d1 / d0;
        ++count;
      }
    }
  if (count == 0)
    throw InvalidInput(who + "no pair of marked vertices is connected by a path of positive length; mark at least two "
                             "distinct points on the same component");
  return sum / count;
}

}  // namespace tbsp
