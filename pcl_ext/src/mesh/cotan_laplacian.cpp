#include "tbsp/mesh/cotan_laplacian.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <vector>

#include "tbsp/core/error.h"

namespace tbsp {

namespace {

// cot of the angle between u and v, robust to degenerate configurations.
double robust_cot(const Eigen::Vector3d& u, const Eigen::Vector3d& v) {
  const double lu = u.norm(), lv = v.norm();
  if (lu <= 0 || lv <= 0) return 0.0;  // zero-length edge: no angle, no weight
  const double s = std::max(u.cross(v).norm(), 1e-12 * lu * lv);
  return std::clamp(u.dot(v) / s, -kMaxCotangent, kMaxCotangent);
}

}  // namespace

Eigen::SparseMatrix<double> cotangent_matrix(const Eigen::MatrixX3d& V, const Eigen::MatrixX3i& F) {
  std::vector<Eigen::Triplet<double>> t;
  t.reserve(std::size_t(F.rows()) * 12);
  for (Eigen::Index f = 0; f < F.rows(); ++f) {
    for (int k = 0; k < 3; ++k) {
      const int i = F(f, k), j = F(f, (k + 1) % 3), o = F(f, (k + 2) % 3);
      if (i == j) continue;
      const Eigen::Vector3d po = V.row(o);
      const double w = 0.5 * robust_cot(Eigen::Vector3d(V.row(i)) - po, Eigen::Vector3d(V.row(j)) - po);
      t.emplace_back(i, j, w);
      t.emplace_back(j, i, w);
      t.emplace_back(i, i, -w);
      t.emplace_back(j, j, -w);
    }
  }
  Eigen::SparseMatrix<double> C(V.rows(), V.rows());
  C.setFromTriplets(t.begin(), t.end());
  return C;
}

Eigen::VectorXd voronoi_areas(const Eigen::MatrixX3d& V, const Eigen::MatrixX3i& F) {
  Eigen::VectorXd A = Eigen::VectorXd::Zero(V.rows());
  for (Eigen::Index f = 0; f < F.rows(); ++f) {
    const int idx[3] = {F(f, 0), F(f, 1), F(f, 2)};
    const Eigen::Vector3d p[3] = {V.row(idx[0]), V.row(idx[1]), V.row(idx[2])};
    const double area = 0.5 * (p[1] - p[0]).cross(p[2] - p[0]).norm();
    if (!(area > 0)) continue;
    // dot products at each corner: negative = obtuse
    double d[3];
    for (int k = 0; k < 3; ++k) d[k] = (p[(k + 1) % 3] - p[k]).dot(p[(k + 2) % 3] - p[k]);
    const int obtuse = d[0] < 0 ? 0 : d[1] < 0 ? 1 : d[2] < 0 ? 2 : -1;
    for (int k = 0; k < 3; ++k) {
      if (obtuse >= 0) {
        A(idx[k]) += (k == obtuse) ? area / 2 : area / 4;
        continue;
      }
      const int j = (k + 1) % 3, l = (k + 2) % 3;
      // Voronoi part: 1/8 (|e_kl|^2 cot(angle at j) + |e_kj|^2 cot(angle at l))
      const double cot_j = robust_cot(p[k] - p[j], p[l] - p[j]);
      const double cot_l = robust_cot(p[k] - p[l], p[j] - p[l]);
      A(idx[k]) += 0.125 * ((p[l] - p[k]).squaredNorm() * cot_j + (p[j] - p[k]).squaredNorm() * cot_l);
    }
  }
  return A;
}

Eigen::SparseMatrix<double> uniform_graph_laplacian(const Eigen::MatrixX3i& F, Eigen::Index num_vertices) {
  std::vector<Eigen::Triplet<double>> t;
  t.reserve(std::size_t(F.rows()) * 6);
  for (Eigen::Index f = 0; f < F.rows(); ++f)
    for (int k = 0; k < 3; ++k) {
      const int i = F(f, k), j = F(f, (k + 1) % 3);
      if (i == j) continue;
      t.emplace_back(i, j, 1.0);
      t.emplace_back(j, i, 1.0);
    }
  Eigen::SparseMatrix<double> G(num_vertices, num_vertices);
  G.setFromTriplets(t.begin(), t.end());
  // an interior edge appears in two faces: collapse multiplicities to 1
  for (int c = 0; c < G.outerSize(); ++c)
    for (Eigen::SparseMatrix<double>::InnerIterator it(G, c); it; ++it) it.valueRef() = 1.0;
  Eigen::VectorXd deg = G * Eigen::VectorXd::Ones(num_vertices);
  std::vector<Eigen::Triplet<double>> d;
  for (Eigen::Index i = 0; i < num_vertices; ++i)
    if (deg(i) > 0) d.emplace_back(int(i), int(i), -deg(i));
  Eigen::SparseMatrix<double> D(num_vertices, num_vertices);
  D.setFromTriplets(d.begin(), d.end());
  return G + D;
}

Eigen::SparseMatrix<double> laplacian(const Eigen::MatrixX3d& V, const Eigen::MatrixX3i& F, LaplacianWeights weights,
                                      double sliver_guard) {
  if (!(sliver_guard >= 0 && std::isfinite(sliver_guard)))
    throw InvalidInput("[tbsp::laplacian] sliver_guard must be >= 0 and finite (0: off)");
  const Eigen::Index n = V.rows();
  Eigen::SparseMatrix<double> K;
  Eigen::VectorXd scale(n);
  if (weights == LaplacianWeights::Cotangent) {
    K = cotangent_matrix(V, F);
    Eigen::VectorXd A = voronoi_areas(V, F);
    double sum = 0;
    Eigen::Index cnt = 0;
    for (Eigen::Index i = 0; i < n; ++i)
      if (A(i) > 0) { sum += A(i); ++cnt; }
    const double floor = cnt ? 1e-8 * sum / double(cnt) : 1.0;
    // C_ij = ½(cot α + cot β)  =>  w_ij = 2 C_ij / (2 A_i) = C_ij / A_i
    if (sliver_guard > 0) {
      Eigen::VectorXd e2 = Eigen::VectorXd::Zero(n), cnt_e = Eigen::VectorXd::Zero(n);
      for (Eigen::Index f = 0; f < F.rows(); ++f)
        for (int k = 0; k < 3; ++k) {
          const int a = F(f, k), b = F(f, (k + 1) % 3);
          const double len = (V.row(a) - V.row(b)).norm();
          e2(a) += len; e2(b) += len;
          cnt_e(a) += 1; cnt_e(b) += 1;
        }
      for (Eigen::Index i = 0; i < n; ++i)
        if (cnt_e(i) > 0) {
          const double mean_edge = e2(i) / cnt_e(i);
          A(i) = std::max(A(i), sliver_guard * mean_edge * mean_edge);
        }
    }
    for (Eigen::Index i = 0; i < n; ++i) scale(i) = 1.0 / std::max(A(i), floor);
  } else {
    K = uniform_graph_laplacian(F, n);
    for (Eigen::Index i = 0; i < n; ++i) {
      const double deg = -K.coeff(i, i);
      scale(i) = deg > 0 ? 1.0 / deg : 0.0;
    }
  }
  Eigen::SparseMatrix<double> L = scale.asDiagonal() * K;
  if (weights == LaplacianWeights::Cotangent) {
    // rows without any usable weight (a vertex whose incident triangles are all degenerate)
    // would leave the vertex unconstrained: use the uniform row there
    const Eigen::SparseMatrix<double> U = uniform_graph_laplacian(F, n);
    const Eigen::VectorXd deg = -Eigen::VectorXd(U.diagonal());
    Eigen::VectorXd row_abs = Eigen::VectorXd::Zero(n);
    for (int c = 0; c < K.outerSize(); ++c)
      for (Eigen::SparseMatrix<double>::InnerIterator it(K, c); it; ++it)
        if (it.row() != it.col()) row_abs(it.row()) += std::abs(it.value());
    const double mean_abs = n ? row_abs.sum() / double(n) : 0;
    std::vector<Eigen::Triplet<double>> t;
    bool any = false;
    for (int c = 0; c < L.outerSize(); ++c)
      for (Eigen::SparseMatrix<double>::InnerIterator it(L, c); it; ++it)
        if (!(row_abs(it.row()) <= 1e-9 * mean_abs && deg(it.row()) > 0)) t.emplace_back(int(it.row()), int(it.col()), it.value());
    for (int c = 0; c < U.outerSize(); ++c)
      for (Eigen::SparseMatrix<double>::InnerIterator it(U, c); it; ++it)
        if (row_abs(it.row()) <= 1e-9 * mean_abs && deg(it.row()) > 0) {
          t.emplace_back(int(it.row()), int(it.col()), it.value() / deg(it.row()));
          any = true;
        }
    if (any) {
      L.setZero();
      L.setFromTriplets(t.begin(), t.end());
    }
  }
  return L;
}

}  // namespace tbsp
