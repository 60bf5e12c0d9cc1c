#include "tbsp/mesh/point_normals.h"

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

#include "tbsp/core/error.h"

namespace tbsp {

namespace {
struct Pair {
  double alignment;  // |n_i · n_j|
  Eigen::Index i, j;
};

// union-find with parity: parity(x) = sign relation of x to its root (1: opposite)
class ParityForest {
public:
  explicit ParityForest(Eigen::Index n) : up_(static_cast<std::size_t>(n)), parity_(static_cast<std::size_t>(n), 0), size_(static_cast<std::size_t>(n), 1) {
    for (Eigen::Index x = 0; x < n; ++x) up_[std::size_t(x)] = x;
  }
  // root of x and x's parity relative to it (iterative, with path compression)
  std::pair<Eigen::Index, char> find(Eigen::Index x) {
    Eigen::Index r = x;
    char p = 0;
    while (up_[std::size_t(r)] != r) {
      p ^= parity_[std::size_t(r)];
      r = up_[std::size_t(r)];
    }
    // compress: every node on the path points at r with its parity to r
    char px = p;
    while (up_[std::size_t(x)] != x) {
      const Eigen::Index next = up_[std::size_t(x)];
      const char pn = px ^ parity_[std::size_t(x)];
      up_[std::size_t(x)] = r;
      parity_[std::size_t(x)] = px;
      x = next;
      px = pn;
    }
    return {r, p};
  }
  // joins the sets of a and b so that parity(a) ^ parity(b) == rel; false if already joined
  bool unite(Eigen::Index a, Eigen::Index b, char rel, bool* consistent) {
    auto [ra, pa] = find(a);
    auto [rb, pb] = find(b);
    if (ra == rb) {
      *consistent = char(pa ^ pb) == rel;
      return false;
    }
    if (size_[std::size_t(ra)] > size_[std::size_t(rb)]) std::swap(ra, rb);
    up_[std::size_t(ra)] = rb;
    parity_[std::size_t(ra)] = char(pa ^ pb ^ rel);
    size_[std::size_t(rb)] += size_[std::size_t(ra)];
    *consistent = true;
    return true;
  }

private:
  std::vector<Eigen::Index> up_;
  std::vector<char> parity_;
  std::vector<Eigen::Index> size_;
};
}  // namespace

NormalOrientationResult orient_normals_consistently(const PointSearch& tree, Eigen::MatrixX3d& N,
                                                    const Eigen::VectorXd& confidence, int k, double min_alignment,
                                                    double max_normal_offset) {
  const std::string who = "[tbsp::orient_normals_consistently] ";
  const Eigen::Index n = tree.size();
  if (N.rows() != n) throw InvalidInput(who + "N has " + std::to_string(N.rows()) + " rows for " + std::to_string(n) + " points");
  if (confidence.rows() != n)
    throw InvalidInput(who + "confidence has " + std::to_string(confidence.rows()) + " entries for " + std::to_string(n) + " points");
  if (k < 2) throw InvalidInput(who + "k must be >= 2");
  const Eigen::MatrixX3d& P = tree.points();
  NormalOrientationResult res;

  // candidate pairs, per point in parallel, then merged in point order (deterministic)
  std::vector<std::vector<Pair>> per_point(static_cast<std::size_t>(n));
#pragma omp parallel
  {
    std::vector<Eigen::Index> idx;
    std::vector<double> d2;
#pragma omp for schedule(dynamic, 512)
    for (Eigen::Index i = 0; i < n; ++i) {
      if (!N.row(i).allFinite() || N.row(i).squaredNorm() == 0) continue;
      tree.knn(P.row(i).transpose(), k, idx, d2);
      for (const Eigen::Index j : idx) {
        if (j <= i || !N.row(j).allFinite()) continue;
        const double a = std::abs(N.row(i).dot(N.row(j)));
        if (a < min_alignment) continue;
        const Eigen::RowVector3d e = P.row(j) - P.row(i);
        const double len = e.norm();
        if (!(len > 0) || std::abs(e.dot(N.row(i))) > max_normal_offset * len ||
            std::abs(e.dot(N.row(j))) > max_normal_offset * len)
          continue;
        per_point[std::size_t(i)].push_back({a, i, j});
      }
    }
  }
  std::vector<Pair> pairs;
  for (auto& v : per_point) pairs.insert(pairs.end(), v.begin(), v.end());
  per_point.clear();
  std::sort(pairs.begin(), pairs.end(), [](const Pair& a, const Pair& b) {
    if (a.alignment != b.alignment) return a.alignment > b.alignment;
    return a.i != b.i ? a.i < b.i : a.j < b.j;
  });
  res.edges = int(pairs.size());

  ParityForest forest(n);
  for (const Pair& p : pairs) {
    bool consistent = true;
    forest.unite(p.i, p.j, N.row(p.i).dot(N.row(p.j)) < 0 ? 1 : 0, &consistent);
    if (!consistent) ++res.conflicts;
  }
  // per component: the parity class with more confidence keeps its orientation
  std::vector<double> score(static_cast<std::size_t>(n), 0.0);
  std::vector<Eigen::Index> root(static_cast<std::size_t>(n));
  std::vector<char> parity(static_cast<std::size_t>(n));
  for (Eigen::Index i = 0; i < n; ++i) {
    const auto [r, p] = forest.find(i);
    root[std::size_t(i)] = r;
    parity[std::size_t(i)] = p;
    const double c = std::isfinite(confidence(i)) ? std::max(confidence(i), 0.0) : 0.0;
    score[std::size_t(r)] += p ? -c : c;
    if (r == i) ++res.components;
  }
  for (Eigen::Index i = 0; i < n; ++i) {
    const char keep = score[std::size_t(root[std::size_t(i)])] >= 0 ? 0 : 1;  // parity class kept
    if (parity[std::size_t(i)] != keep) {
      N.row(i) *= -1;
      ++res.flipped;
    }
  }
  return res;
}

Eigen::MatrixX3d estimate_normals_pca(const PointSearch& tree, int k) {
  if (k < 3) throw InvalidInput("[tbsp::estimate_normals_pca] k must be >= 3 (got " + std::to_string(k) + ")");
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

}  // namespace tbsp
