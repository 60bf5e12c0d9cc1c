#include "tbsp/mesh/topology.h"

#include <algorithm>
#include <numeric>

namespace tbsp {

Eigen::MatrixX2i unique_edges(const Eigen::MatrixX3i& F) {
  std::vector<std::pair<int, int>> e;
  e.reserve(std::size_t(F.rows()) * 3);
  for (Eigen::Index f = 0; f < F.rows(); ++f)
    for (int k = 0; k < 3; ++k) {
      int a = F(f, k), b = F(f, (k + 1) % 3);
      if (a == b) continue;
      e.emplace_back(std::min(a, b), std::max(a, b));
    }
  std::sort(e.begin(), e.end());
  e.erase(std::unique(e.begin(), e.end()), e.end());
  Eigen::MatrixX2i E(Eigen::Index(e.size()), 2);
  for (std::size_t i = 0; i < e.size(); ++i) E.row(Eigen::Index(i)) << e[i].first, e[i].second;
  return E;
}

std::vector<std::vector<int>> vertex_adjacency(const Eigen::MatrixX3i& F, Eigen::Index num_vertices) {
  std::vector<std::vector<int>> adj(static_cast<std::size_t>(num_vertices));
  for (Eigen::Index f = 0; f < F.rows(); ++f)
    for (int k = 0; k < 3; ++k) {
      int a = F(f, k), b = F(f, (k + 1) % 3);
      if (a == b) continue;
      adj[std::size_t(a)].push_back(b);
      adj[std::size_t(b)].push_back(a);
    }
  for (auto& n : adj) {
    std::sort(n.begin(), n.end());
    n.erase(std::unique(n.begin(), n.end()), n.end());
  }
  return adj;
}

void vertex_adjacency_compressed(const Eigen::MatrixX3i& F, Eigen::Index num_vertices, std::vector<int>& offsets,
                                 std::vector<int>& neighbours) {
  const std::vector<std::vector<int>> adj = vertex_adjacency(F, num_vertices);
  offsets.assign(adj.size() + 1, 0);
  for (std::size_t v = 0; v < adj.size(); ++v) offsets[v + 1] = offsets[v] + int(adj[v].size());
  neighbours.clear();
  neighbours.reserve(std::size_t(offsets.back()));
  for (const auto& a : adj) neighbours.insert(neighbours.end(), a.begin(), a.end());
}

void vertex_faces(const Eigen::MatrixX3i& F, Eigen::Index num_vertices, std::vector<int>& offsets, std::vector<int>& faces) {
  offsets.assign(std::size_t(num_vertices) + 1, 0);
  for (Eigen::Index f = 0; f < F.rows(); ++f)
    for (int k = 0; k < 3; ++k) ++offsets[std::size_t(F(f, k)) + 1];
  for (std::size_t v = 0; v < std::size_t(num_vertices); ++v) offsets[v + 1] += offsets[v];
  faces.assign(std::size_t(offsets.back()), 0);
  std::vector<int> fill(offsets.begin(), offsets.end() - 1);
  for (Eigen::Index f = 0; f < F.rows(); ++f)
    for (int k = 0; k < 3; ++k) faces[std::size_t(fill[std::size_t(F(f, k))]++)] = int(f);
}

int connected_components(const Eigen::MatrixX3i& F, Eigen::Index num_vertices, Eigen::VectorXi& labels) {
  std::vector<int> parent(static_cast<std::size_t>(num_vertices));
  std::iota(parent.begin(), parent.end(), 0);
  auto find = [&](int x) {
    while (parent[std::size_t(x)] != x) {
      parent[std::size_t(x)] = parent[std::size_t(parent[std::size_t(x)])];
      x = parent[std::size_t(x)];
    }
    return x;
  };
  for (Eigen::Index f = 0; f < F.rows(); ++f)
    for (int k = 1; k < 3; ++k) {
      int a = find(F(f, 0)), b = find(F(f, k));
      if (a != b) parent[std::size_t(std::max(a, b))] = std::min(a, b);
    }
  labels.resize(num_vertices);
  std::vector<int> id(std::size_t(num_vertices), -1);
  int k = 0;
  for (Eigen::Index i = 0; i < num_vertices; ++i) {
    int r = find(int(i));
    if (id[std::size_t(r)] < 0) id[std::size_t(r)] = k++;
    labels(i) = id[std::size_t(r)];
  }
  return k;
}

void grow_region(std::vector<char>& region, const std::vector<std::vector<int>>& adj, int rings) {
  for (int ring = 0; ring < rings; ++ring) {
    const std::vector<char> prev = region;
    for (std::size_t i = 0; i < prev.size() && i < adj.size(); ++i)
      if (prev[i])
        for (int j : adj[i]) region[std::size_t(j)] = 1;
  }
}

void umbrella_step(Eigen::MatrixX3d& V, const std::vector<std::vector<int>>& adj, const std::vector<char>& region,
                   double lambda, std::vector<char>* moved) {
  Eigen::MatrixX3d Vs = V;
  for (Eigen::Index i = 0; i < V.rows(); ++i) {
    const std::size_t k = std::size_t(i);
    if (k >= region.size() || k >= adj.size() || !region[k] || adj[k].empty()) continue;
    Eigen::RowVector3d c = Eigen::RowVector3d::Zero();
    for (int j : adj[k]) c += V.row(j);
    Vs.row(i) = (1 - lambda) * V.row(i) + lambda * c / double(adj[k].size());
    if (moved) (*moved)[k] = 1;
  }
  V = Vs;
}

}  // namespace tbsp
