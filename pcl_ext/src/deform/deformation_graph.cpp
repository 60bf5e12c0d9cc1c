// Embedded deformation graph (deformation_graph.h): node sampling, geodesic binding,
// Gauss-Newton solve with exact rotations.
#include "tbsp/deform/deformation_graph.h"

#include <Eigen/Geometry>
#include <Eigen/SVD>
#include <Eigen/SparseCore>
#include <algorithm>
#include <cmath>
#include <limits>
#include <tuple>
#include <string>

#include "../mesh/dary_heap.h"
#include "tbsp/core/error.h"
#include "tbsp/deform/rotations.h"
#include "tbsp/mesh/point_search.h"
#include "tbsp/mesh/topology.h"
#include "tbsp/solve/sparse_cholesky.h"

namespace tbsp {
namespace {

using Mat6 = Eigen::Matrix<double, 6, 6>;
using Vec6 = Eigen::Matrix<double, 6, 1>;

Eigen::Matrix3d skew(const Eigen::Vector3d& a) {
  Eigen::Matrix3d S;
  S << 0, -a.z(), a.y(), a.z(), 0, -a.x(), -a.y(), a.x(), 0;
  return S;
}

}  // namespace

// The normal equations' matrix (lower triangle, 6 × 6 blocks of the node pattern) built once per
// graph; value_of maps (block slot, r, c) in the order solve() visits them to its entry.
struct DeformationGraph::Factor::Pattern {
  Eigen::SparseMatrix<double> A;
  std::vector<Eigen::Index> value_of;
};

DeformationGraph::Factor::Factor() : chol(std::make_unique<SparseCholesky>()) {}
DeformationGraph::Factor::Factor(const Factor&) : Factor() {}
DeformationGraph::Factor& DeformationGraph::Factor::operator=(const Factor&) {
  chol = std::make_unique<SparseCholesky>();
  pattern.reset();
  return *this;
}
DeformationGraph::Factor::Factor(Factor&&) noexcept = default;
DeformationGraph::Factor& DeformationGraph::Factor::operator=(Factor&&) noexcept = default;
DeformationGraph::Factor::~Factor() = default;

// Separate surface components (a body modelled as parts: limbs pushed into or set against a
// torso, a skirt around it) share no vertex, so the edges above never join their nodes and each
// part would be a free rigid body, held only by its correspondences (point-to-plane ones leave a
// cylinder free to slide and spin): a leg under a skirt, matched to the skirt's points, swings
// out with them. Parts are joined where they touch at the mesh's resolution: a vertex whose
// nearest vertex of another component lies within the median edge length links the two
// vertices' nearest nodes. This only adds regulariser edges: vertices stay bound to nodes of
// their own surface (the Dijkstra binding above), so touching parts still bend apart where
// their data say so. Parts farther apart stay independent; a single-component mesh gets no
// edge here. O(#V log #V), only for meshes of several components.
void DeformationGraph::link_components(const Eigen::MatrixX3d& V, const Eigen::MatrixX3i& F, std::vector<std::pair<int, int>>& e) {
  cross_edges_ = 0;
  Eigen::VectorXi comp;
  if (F.rows() == 0 || connected_components(F, V.rows(), comp) < 2) return;
  std::vector<double> len;
  len.reserve(std::size_t(F.rows()) * 3);
  for (Eigen::Index f = 0; f < F.rows(); ++f)
    for (int c = 0; c < 3; ++c) len.push_back((V.row(F(f, c)) - V.row(F(f, (c + 1) % 3))).norm());
  std::nth_element(len.begin(), len.begin() + long(len.size() / 2), len.end());
  const double touch = len[len.size() / 2];
  const PointSearch vertex_tree(V);
  std::vector<Eigen::Index> idx;
  std::vector<double> d2;
  std::vector<std::pair<int, int>> x;
  const int knn = int(std::min<Eigen::Index>(16, V.rows()));
  for (Eigen::Index v = 0; v < V.rows(); ++v) {
    vertex_tree.knn(V.row(v).transpose(), knn, idx, d2);
    for (std::size_t m = 0; m < idx.size() && std::sqrt(d2[m]) <= touch; ++m) {
      if (comp(idx[m]) == comp(v)) continue;
      const int p = bind_(v, 0), q = bind_(idx[m], 0);
      if (p != q) x.push_back({std::min(p, q), std::max(p, q)});
      break;  // the nearest vertex of another component
    }
  }
  std::sort(x.begin(), x.end());
  x.erase(std::unique(x.begin(), x.end()), x.end());
  cross_edges_ = x.size();
  e.insert(e.end(), x.begin(), x.end());
}

void DeformationGraph::build(const Eigen::MatrixX3d& V, const Eigen::MatrixX3i& F, int nodes, int k) {
  const char* who = "[tbsp::DeformationGraph::build] ";
  if (V.rows() == 0) throw InvalidInput(std::string(who) + "the mesh has no vertices");
  if (k < 1 || k > 8) throw InvalidInput(std::string(who) + "k = " + std::to_string(k) + " nodes per vertex; use 1..8");
  if (F.size() && (F.minCoeff() < 0 || F.maxCoeff() >= V.rows()))
    throw InvalidInput(std::string(who) + "a face index is outside the " + std::to_string(V.rows()) + " vertices");
  V_ = V;
  std::vector<int> all(static_cast<std::size_t>(V.rows()));
  for (std::size_t i = 0; i < all.size(); ++i) all[i] = int(i);
  nodes = std::max(1, std::min<int>(nodes, int(V.rows())));
  node_vertex_ = farthest_point_sample(V, all, nodes);
  const int n = int(node_vertex_.size());
  k_ = std::min(k, std::max(1, n - 1));
  g_.resize(n, 3);
  for (int j = 0; j < n; ++j) g_.row(j) = V.row(node_vertex_[std::size_t(j)]);
  const PointSearch node_tree(g_);
  // per vertex its k + 1 nearest nodes along the surface: one Dijkstra from all nodes at once
  // that keeps up to k + 1 labels (node, distance) per vertex, settled in order of distance
  // (ties by vertex, then node: deterministic). O((k + 1)(#V + #E) log) for any node count.
  // Flat arrays (adjacency, labels, queued bests) instead of a vector per vertex: the same
  // labels, without the allocations and pointer chasing.
  const Eigen::Index nv = V.rows();
  std::vector<int> adj_start, adj_list;
  vertex_adjacency_compressed(F, nv, adj_start, adj_list);
  const int K = k_ + 1;
  std::vector<std::pair<double, int>> near(std::size_t(nv) * std::size_t(K));  // (distance, node), K per vertex
  std::vector<int> n_near(std::size_t(nv), 0);
  {
    using Item = std::tuple<double, int, int>;  // distance, vertex, node
    detail::DaryMinHeap<Item> q;
    // per vertex the best distance queued so far for each node reaching it: an item no shorter
    // than one already queued for the same (vertex, node) would pop later and be skipped, so it
    // is not queued (the same labels, fewer heap operations). kInline per vertex in a flat
    // array, more in a per-vertex overflow list (rare).
    constexpr int kInline = 8;
    std::vector<std::pair<int, double>> queued(std::size_t(nv) * kInline);
    std::vector<unsigned char> n_queued(std::size_t(nv), 0);
    std::vector<std::vector<std::pair<int, double>>> overflow;
    std::vector<int> overflow_of;  // vertex -> index in overflow, −1 none (allocated on first use)
    for (int j = 0; j < n; ++j) q.push({0.0, node_vertex_[std::size_t(j)], j});
    auto settled = [&](int v, int j) {
      const std::pair<double, int>* l = &near[std::size_t(v) * std::size_t(K)];
      for (int m = 0; m < n_near[std::size_t(v)]; ++m)
        if (l[m].second == j) return true;
      return false;
    };
    auto improves = [&](int w, int j, double d) {
      auto update = [&](std::pair<int, double>& e) {
        if (d >= e.second) return false;
        e.second = d;
        return true;
      };
      std::pair<int, double>* l = &queued[std::size_t(w) * kInline];
      const int m = n_queued[std::size_t(w)];
      for (int i = 0; i < m; ++i)
        if (l[i].first == j) return update(l[i]);
      if (m < kInline) {
        l[m] = {j, d};
        n_queued[std::size_t(w)] = static_cast<unsigned char>(m + 1);
        return true;
      }
      if (overflow_of.empty()) overflow_of.assign(std::size_t(nv), -1);
      int& o = overflow_of[std::size_t(w)];
      if (o < 0) {
        o = int(overflow.size());
        overflow.emplace_back();
      }
      for (auto& e : overflow[std::size_t(o)])
        if (e.first == j) return update(e);
      overflow[std::size_t(o)].push_back({j, d});
      return true;
    };
    while (!q.empty()) {
      const auto [d, v, j] = q.top();
      q.pop();
      int& nl = n_near[std::size_t(v)];
      if (nl >= K || settled(v, j)) continue;
      near[std::size_t(v) * std::size_t(K) + std::size_t(nl)] = {d, j};
      ++nl;
      const Eigen::RowVector3d pv = V.row(v);
      for (int a = adj_start[std::size_t(v)]; a < adj_start[std::size_t(v) + 1]; ++a) {
        const int w = adj_list[std::size_t(a)];
        if (n_near[std::size_t(w)] >= K || settled(w, j)) continue;
        const double dw = d + (pv - V.row(w)).norm();
        if (improves(w, j, dw)) q.push({dw, w, j});
      }
    }
  }
  bind_.resize(nv, k_);
  weight_.resize(nv, k_);
  std::vector<Eigen::Index> idx;
  std::vector<double> d2;
  for (Eigen::Index v = 0; v < nv; ++v) {
    std::pair<double, int>* c = &near[std::size_t(v) * std::size_t(K)];
    int nc = n_near[std::size_t(v)];
    if (nc == 0) {  // a component without a node (more components than nodes): Euclidean nearest
      node_tree.knn(V.row(v).transpose(), std::min(k_ + 1, n), idx, d2);
      for (std::size_t m = 0; m < idx.size() && nc < K; ++m) c[nc++] = {std::sqrt(d2[m]), int(idx[m])};
    }
    std::sort(c, c + nc);
    const double dmax = nc > k_ ? c[k_].first : c[nc - 1].first * 1.5 + 1e-12;
    double sum = 0;
    for (int m = 0; m < k_; ++m) {
      const bool have = m < nc;
      const double w = have ? std::pow(std::max(0.0, 1.0 - c[m].first / std::max(dmax, 1e-300)), 2) : 0.0;
      bind_(v, m) = have ? c[m].second : c[0].second;
      weight_(v, m) = w;
      sum += w;
    }
    if (sum <= 0) {  // all at the (k+1)-th distance: equal weights
      for (int m = 0; m < k_; ++m) weight_(v, m) = 1.0 / k_;
    } else {
      weight_.row(v) /= sum;
    }
  }
  // node edges: nodes that share a vertex
  std::vector<std::pair<int, int>> e;
  for (Eigen::Index v = 0; v < V.rows(); ++v)
    for (int a = 0; a < k_; ++a)
      for (int b = a + 1; b < k_; ++b) {
        const int p = bind_(v, a), q = bind_(v, b);
        if (p != q && weight_(v, a) > 0 && weight_(v, b) > 0) e.push_back({std::min(p, q), std::max(p, q)});
      }
  link_components(V, F, e);
  std::sort(e.begin(), e.end());
  e.erase(std::unique(e.begin(), e.end()), e.end());
  edges_ = e;
  // block pattern of the normal equations: diagonal + edges, both triangles
  nb_.assign(static_cast<std::size_t>(n), {});
  for (const auto& [a, b] : edges_) { nb_[std::size_t(a)].push_back(b); nb_[std::size_t(b)].push_back(a); }
  for (int j = 0; j < n; ++j) { nb_[std::size_t(j)].push_back(j); std::sort(nb_[std::size_t(j)].begin(), nb_[std::size_t(j)].end()); }
  start_.assign(std::size_t(n) + 1, 0);
  for (int j = 0; j < n; ++j) start_[std::size_t(j) + 1] = start_[std::size_t(j)] + nb_[std::size_t(j)].size();
  factor_ = Factor();
  reset();
}

void DeformationGraph::reset() {
  R_.assign(std::size_t(g_.rows()), Eigen::Matrix3d::Identity());
  t_.assign(std::size_t(g_.rows()), Eigen::Vector3d::Zero());
}

void DeformationGraph::fitTransformsTo(const Eigen::MatrixX3d& X) {
  const char* who = "[tbsp::DeformationGraph::fitTransformsTo] ";
  if (g_.rows() == 0) throw InvalidInput(std::string(who) + "call build() first");
  if (X.rows() != V_.rows())
    throw InvalidInput(std::string(who) + "X has " + std::to_string(X.rows()) + " rows for the graph's " + std::to_string(V_.rows()) +
                       " vertices");
  if (!X.allFinite()) throw InvalidInput(std::string(who) + "X has a non-finite coordinate");
  const std::size_t n = std::size_t(g_.rows());
  std::vector<double> wsum(n, 0.0);
  std::vector<Eigen::Vector3d> cr(n, Eigen::Vector3d::Zero()), cx(n, Eigen::Vector3d::Zero());
  for (Eigen::Index v = 0; v < V_.rows(); ++v)
    for (int m = 0; m < k_; ++m) {
      const std::size_t j = std::size_t(bind_(v, m));
      const double w = weight_(v, m);
      wsum[j] += w;
      cr[j] += w * V_.row(v).transpose();
      cx[j] += w * X.row(v).transpose();
    }
  std::vector<Eigen::Matrix3d> H(n, Eigen::Matrix3d::Zero());
  for (std::size_t j = 0; j < n; ++j)
    if (wsum[j] > 0) {
      cr[j] /= wsum[j];
      cx[j] /= wsum[j];
    }
  for (Eigen::Index v = 0; v < V_.rows(); ++v)
    for (int m = 0; m < k_; ++m) {
      const std::size_t j = std::size_t(bind_(v, m));
      H[j] += weight_(v, m) * (V_.row(v).transpose() - cr[j]) * (X.row(v).transpose() - cx[j]).transpose();
    }
  reset();
  for (std::size_t j = 0; j < n; ++j) {
    if (!(wsum[j] > 0)) continue;  // a node no vertex follows: identity
    const Eigen::JacobiSVD<Eigen::Matrix3d> svd(H[j], Eigen::ComputeFullU | Eigen::ComputeFullV);
    Eigen::Matrix3d D = Eigen::Matrix3d::Identity();
    if ((svd.matrixV() * svd.matrixU().transpose()).determinant() < 0) D(2, 2) = -1;
    R_[j] = svd.matrixV() * D * svd.matrixU().transpose();
    const Eigen::Vector3d g = g_.row(Eigen::Index(j)).transpose();
    t_[j] = cx[j] - g - R_[j] * (cr[j] - g);
  }
}

Eigen::Vector3d DeformationGraph::deformVertex(int v) const {
  Eigen::Vector3d p = Eigen::Vector3d::Zero();
  const Eigen::Vector3d x = V_.row(v).transpose();
  for (int m = 0; m < k_; ++m) {
    const int j = bind_(v, m);
    const Eigen::Vector3d g = g_.row(j).transpose();
    p += weight_(v, m) * (R_[std::size_t(j)] * (x - g) + g + t_[std::size_t(j)]);
  }
  return p;
}

Eigen::MatrixX3d DeformationGraph::deform() const {
  Eigen::MatrixX3d X(V_.rows(), 3);
#pragma omp parallel for schedule(static)
  for (Eigen::Index v = 0; v < V_.rows(); ++v) X.row(v) = deformVertex(int(v)).transpose();
  return X;
}

Eigen::Matrix3d DeformationGraph::vertexRotation(int v) const {
  Eigen::Matrix3d M = Eigen::Matrix3d::Zero();
  for (int m = 0; m < k_; ++m) M += weight_(v, m) * R_[std::size_t(bind_(v, m))];
  return closest_rotation(M);
}

Eigen::Vector3d DeformationGraph::turnedNormal(int v, const Eigen::Vector3d& n) const {
  Eigen::Vector3d m = Eigen::Vector3d::Zero();
  for (int k = 0; k < k_; ++k) m += weight_(v, k) * (R_[std::size_t(bind_(v, k))] * n);
  const double len = m.norm();
  return len > 0 ? Eigen::Vector3d(m / len) : n;
}

std::vector<Eigen::Matrix3d> DeformationGraph::vertexRotations() const {
  std::vector<Eigen::Matrix3d> out(std::size_t(V_.rows()));
#pragma omp parallel for schedule(static)
  for (Eigen::Index v = 0; v < V_.rows(); ++v) {
    out[std::size_t(v)] = vertexRotation(int(v));
  }
  return out;
}

double DeformationGraph::solve(const std::vector<GraphConstraint>& constraints, double alpha, int steps) {
  const char* who = "[tbsp::DeformationGraph::solve] ";
  if (nodeCount() == 0) throw InvalidInput(std::string(who) + "the graph has no nodes: call build() first");
  if (!(alpha > 0) || !std::isfinite(alpha)) throw InvalidInput(std::string(who) + "the stiffness must be > 0");
  for (std::size_t c = 0; c < constraints.size(); ++c) {
    const GraphConstraint& gc = constraints[c];
    if (gc.vertex < 0 || gc.vertex >= V_.rows())
      throw InvalidInput(std::string(who) + "constraint " + std::to_string(c) + " names vertex " + std::to_string(gc.vertex) +
                         " of " + std::to_string(V_.rows()));
    if (!(gc.weight >= 0) || !std::isfinite(gc.weight) || !gc.target.allFinite() || !gc.normal.allFinite())
      throw InvalidInput(std::string(who) + "constraint " + std::to_string(c) + " has a non-finite value or a negative weight");
  }
  const int n = nodeCount();
  auto slot = [&](int a, int b) {
    const auto& l = nb_[std::size_t(a)];
    return start_[std::size_t(a)] + std::size_t(std::lower_bound(l.begin(), l.end(), b) - l.begin());
  };
  std::vector<Mat6> H(start_.back());
  std::vector<Vec6> gvec(static_cast<std::size_t>(n));
  double last_move = 0;
  SparseCholesky& chol = *factor_.chol;  // CHOLMOD (supernodal) when built with it; the pattern is analysed once per graph
  // The matrix's pattern once per graph: the lower triangle (6b + c, 6a + r), b ≥ a, in the
  // order the values are filled below; value_of[t] is the t-th entry's place in A.
  if (!factor_.pattern) {
    auto pat = std::make_unique<Factor::Pattern>();
    std::vector<Eigen::Triplet<double>> trip;
    for (int a = 0; a < n; ++a)
      for (std::size_t s = start_[std::size_t(a)]; s < start_[std::size_t(a) + 1]; ++s) {
        const int b = nb_[std::size_t(a)][s - start_[std::size_t(a)]];
        if (b < a) continue;
        for (int r = 0; r < 6; ++r)
          for (int c = (a == b ? r : 0); c < 6; ++c) trip.emplace_back(6 * b + c, 6 * a + r, double(trip.size()));
      }
    pat->A.resize(6 * n, 6 * n);
    pat->A.setFromTriplets(trip.begin(), trip.end());  // no duplicates: every value is its triplet's index
    pat->value_of.resize(trip.size());
    for (Eigen::Index i = 0; i < pat->A.nonZeros(); ++i) pat->value_of[std::size_t(pat->A.valuePtr()[i])] = i;
    factor_.pattern = std::move(pat);
  }
  Eigen::SparseMatrix<double>& A = factor_.pattern->A;
  const std::vector<Eigen::Index>& value_of = factor_.pattern->value_of;
  // per vertex, the constraints summed into one weighted residual: W_v = Σ w nnᵀ (plane) or
  // w I (point), e_v = Σ W_c (v' − target_c); the Gauss-Newton system of a vertex is then
  // J_vᵀ W_v J_v, the same as the sum over its constraints (and k² block updates per vertex,
  // not per constraint). Sequential sums in constraint order: deterministic. (Summing the
  // blocks per slot in parallel was measured slower on 2 cores: the per-slot gathers miss the
  // cache where this loop streams.)
  std::vector<int> cverts;
  for (const GraphConstraint& gc : constraints)
    if (gc.weight > 0) cverts.push_back(gc.vertex);
  std::sort(cverts.begin(), cverts.end());
  cverts.erase(std::unique(cverts.begin(), cverts.end()), cverts.end());
  std::vector<Eigen::Matrix3d> W(cverts.size());
  std::vector<Eigen::Vector3d> e(cverts.size());
  auto vslot = [&](int v) { return std::size_t(std::lower_bound(cverts.begin(), cverts.end(), v) - cverts.begin()); };
  for (int step = 0; step < steps; ++step) {
    for (auto& h : H) h.setZero();
    for (auto& gv : gvec) gv.setZero();
    for (auto& w : W) w.setZero();
    for (auto& x : e) x.setZero();
    std::vector<Eigen::Vector3d> X(cverts.size());
#pragma omp parallel for schedule(static)
    for (std::size_t i = 0; i < cverts.size(); ++i) X[i] = deformVertex(cverts[i]);
    for (const GraphConstraint& gc : constraints) {
      if (gc.weight <= 0) continue;
      const std::size_t i = vslot(gc.vertex);
      const Eigen::Matrix3d Wc = gc.normal.squaredNorm() > 0 ? Eigen::Matrix3d(gc.weight * gc.normal * gc.normal.transpose())
                                                             : Eigen::Matrix3d(gc.weight * Eigen::Matrix3d::Identity());
      W[i] += Wc;
      e[i] += Wc * (X[i] - gc.target);
    }
    for (std::size_t i = 0; i < cverts.size(); ++i) {
      const int v = cverts[i];
      const Eigen::Vector3d x = V_.row(v).transpose();
      Eigen::Matrix<double, 3, 6> J[8];
      Eigen::Matrix<double, 6, 3> JW[8];
      for (int m = 0; m < k_; ++m) {
        const int j = bind_(v, m);
        const Eigen::Vector3d b = R_[std::size_t(j)] * (x - g_.row(j).transpose());
        J[m].leftCols<3>() = -weight_(v, m) * skew(b);
        J[m].rightCols<3>() = weight_(v, m) * Eigen::Matrix3d::Identity();
        JW[m] = J[m].transpose() * W[i];
        gvec[std::size_t(j)] += J[m].transpose() * e[i];
      }
      // a binding of weight 0 contributes nothing, and its node pair need not be an edge; only
      // the blocks (p, q) with q >= p are read below (the lower triangle), so the transposed
      // ones are not summed
      for (int a = 0; a < k_; ++a)
        for (int b = 0; b < k_; ++b) {
          const int p = bind_(v, a), q = bind_(v, b);
          if (q >= p && weight_(v, a) > 0 && weight_(v, b) > 0) H[slot(p, q)] += JW[a] * J[b];
        }
    }
    // regulariser, both directions of every edge
    for (const auto& [a0, b0] : edges_)
      for (int dir = 0; dir < 2; ++dir) {
        const int j = dir ? b0 : a0, l = dir ? a0 : b0;
        const Eigen::Vector3d d = R_[std::size_t(j)] * (g_.row(l) - g_.row(j)).transpose();
        const Eigen::Vector3d r = d + g_.row(j).transpose() + t_[std::size_t(j)] - g_.row(l).transpose() - t_[std::size_t(l)];
        Eigen::Matrix<double, 3, 6> Jj, Jl;
        Jj.leftCols<3>() = -skew(d);
        Jj.rightCols<3>() = Eigen::Matrix3d::Identity();
        Jl.leftCols<3>().setZero();
        Jl.rightCols<3>() = -Eigen::Matrix3d::Identity();
        gvec[std::size_t(j)] += alpha * Jj.transpose() * r;
        gvec[std::size_t(l)] += alpha * Jl.transpose() * r;
        H[slot(j, j)] += alpha * Jj.transpose() * Jj;
        H[slot(l, l)] += alpha * Jl.transpose() * Jl;
        if (l >= j) H[slot(j, l)] += alpha * Jj.transpose() * Jl;  // (the transposed block is not read)
        else H[slot(l, j)] += alpha * Jl.transpose() * Jj;
      }
    // Levenberg damping relative to the mean diagonal (keeps nodes with nothing but the
    // regulariser's relative terms, e.g. a part without data, from a singular system)
    double diag_mean = 0;
    for (int j = 0; j < n; ++j) diag_mean += H[slot(j, j)].trace() / (6.0 * n);
    const double mu = 1e-6 * std::max(diag_mean, 1e-300);
    double* val = A.valuePtr();
    std::size_t t = 0;
    for (int a = 0; a < n; ++a)
      for (std::size_t s = start_[std::size_t(a)]; s < start_[std::size_t(a) + 1]; ++s) {
        const int b = nb_[std::size_t(a)][s - start_[std::size_t(a)]];
        if (b < a) continue;  // the factorization reads the lower triangle: (6b + c, 6a + r)
        for (int r = 0; r < 6; ++r)
          for (int c = (a == b ? r : 0); c < 6; ++c) val[value_of[t++]] = H[s](r, c) + (a == b && r == c ? mu : 0.0);
      }
    Eigen::VectorXd rhs(6 * n);
    for (int j = 0; j < n; ++j) rhs.segment<6>(6 * j) = -gvec[std::size_t(j)];
    chol.compute(A);
    const Eigen::VectorXd dx = chol.solve(rhs);
    // move of the vertices: the nodes' displacement at their own vertex is a fair proxy
    Eigen::MatrixX3d nodes_before(n, 3);
    for (int j = 0; j < n; ++j) nodes_before.row(j) = deformVertex(node_vertex_[std::size_t(j)]);
    for (int j = 0; j < n; ++j) {
      const Eigen::Vector3d w = dx.segment<3>(6 * j);
      const double ang = w.norm();
      if (ang > 0) R_[std::size_t(j)] = Eigen::AngleAxisd(ang, w / ang).toRotationMatrix() * R_[std::size_t(j)];
      t_[std::size_t(j)] += dx.segment<3>(6 * j + 3);
    }
    last_move = 0;
    for (int j = 0; j < n; ++j)
      last_move = std::max(last_move, (deformVertex(node_vertex_[std::size_t(j)]) - nodes_before.row(j).transpose()).norm());
  }
  return last_move;
}

}  // namespace tbsp
