#include "tbsp/mesh/cotan_laplacian.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <limits>
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

// Relative margin of the intrinsic mollification (Sharp & Crane 2020, "A Laplacian for
// nonmanifold triangle meshes", §4.5): a face whose triangle inequality holds with less than
// kMollifyMargin x the mean edge length gets that margin by lengthening its three edges by
// the same amount, and its cotangents and area come from those lengths. The three corner
// cotangents then belong to one real triangle (cot a cot b + cot b cot c + cot c cot a = 1), so
// the face's stiffness block stays positive semi-definite. Clamping each corner on its own does
// not (a zero-area face gives cots near (+1e4, +1e4, -1e4): an indefinite block, and a solver
// that stops with "not positive definite"). Faces above the margin are computed as before.
constexpr double kMollifyMargin = 1e-4;

double mean_edge_length(const Eigen::MatrixX3d& V, const Eigen::MatrixX3i& F) {
  double sum = 0;
  for (Eigen::Index f = 0; f < F.rows(); ++f)
    for (int k = 0; k < 3; ++k) sum += (V.row(F(f, k)) - V.row(F(f, (k + 1) % 3))).norm();
  return F.rows() ? sum / double(3 * F.rows()) : 0.0;
}

// Geometry of a face for the Laplacian: corner cotangents, area and squared edge lengths
// (l2[k]: the edge opposite corner k). `delta`: the mollification margin in model units.
struct FaceGeometry {
  double cot[3];
  double area;
  double l2[3];
  bool mollified;
};

FaceGeometry face_geometry(const Eigen::Vector3d p[3], double delta) {
  FaceGeometry g;
  double l[3];
  for (int k = 0; k < 3; ++k) {
    g.l2[k] = (p[(k + 2) % 3] - p[(k + 1) % 3]).squaredNorm();
    l[k] = std::sqrt(g.l2[k]);
  }
  double margin = std::numeric_limits<double>::infinity();
  for (int k = 0; k < 3; ++k) margin = std::min(margin, l[(k + 1) % 3] + l[(k + 2) % 3] - l[k]);
  g.mollified = delta > 0 && margin < delta;
  if (!g.mollified) {
    for (int k = 0; k < 3; ++k) g.cot[k] = robust_cot(p[(k + 1) % 3] - p[k], p[(k + 2) % 3] - p[k]);
    g.area = 0.5 * (p[1] - p[0]).cross(p[2] - p[0]).norm();
    return g;
  }
  const double eps = delta - margin;
  for (int k = 0; k < 3; ++k) {
    l[k] += eps;
    g.l2[k] = l[k] * l[k];
  }
  // Heron's formula in Kahan's stable form (a >= b >= c)
  double s[3] = {l[0], l[1], l[2]};
  std::sort(s, s + 3, [](double x, double y) { return x > y; });
  const double a = s[0], b = s[1], c = s[2];
  const double q = (a + (b + c)) * (c - (a - b)) * (c + (a - b)) * (a + (b - c));
  g.area = 0.25 * std::sqrt(std::max(q, 0.0));
  for (int k = 0; k < 3; ++k) {
    const double num = g.l2[(k + 1) % 3] + g.l2[(k + 2) % 3] - g.l2[k];
    g.cot[k] = g.area > 0 ? std::clamp(num / (4 * g.area), -kMaxCotangent, kMaxCotangent) : 0.0;
  }
  return g;
}

}  // namespace

Eigen::SparseMatrix<double> cotangent_matrix(const Eigen::MatrixX3d& V, const Eigen::MatrixX3i& F) {
  const double delta = kMollifyMargin * mean_edge_length(V, F);
  std::vector<Eigen::Triplet<double>> t;
  t.reserve(std::size_t(F.rows()) * 12);
  for (Eigen::Index f = 0; f < F.rows(); ++f) {
    const Eigen::Vector3d p[3] = {V.row(F(f, 0)), V.row(F(f, 1)), V.row(F(f, 2))};
    const FaceGeometry g = face_geometry(p, delta);
    for (int k = 0; k < 3; ++k) {
      const int i = F(f, k), j = F(f, (k + 1) % 3);
      if (i == j) continue;
      const double w = 0.5 * g.cot[(k + 2) % 3];  // the angle at the corner opposite edge ij
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

Eigen::MatrixX3d face_cotangents(const Eigen::MatrixX3d& V, const Eigen::MatrixX3i& F) {
  const double delta = kMollifyMargin * mean_edge_length(V, F);
  Eigen::MatrixX3d C(F.rows(), 3);
  for (Eigen::Index f = 0; f < F.rows(); ++f) {
    const Eigen::Vector3d p[3] = {V.row(F(f, 0)), V.row(F(f, 1)), V.row(F(f, 2))};
    const FaceGeometry g = face_geometry(p, delta);
    C.row(f) << g.cot[0], g.cot[1], g.cot[2];
  }
  return C;
}

double mean_voronoi_area(const Eigen::MatrixX3d& V, const Eigen::MatrixX3i& F) {
  const Eigen::VectorXd A = voronoi_areas(V, F);
  double sum = 0;
  int cnt = 0;
  for (Eigen::Index i = 0; i < A.rows(); ++i)
    if (A(i) > 0) { sum += A(i); ++cnt; }
  return cnt ? sum / cnt : 0.0;
}

Eigen::VectorXd voronoi_areas(const Eigen::MatrixX3d& V, const Eigen::MatrixX3i& F) {
  const double delta = kMollifyMargin * mean_edge_length(V, F);
  Eigen::VectorXd A = Eigen::VectorXd::Zero(V.rows());
  for (Eigen::Index f = 0; f < F.rows(); ++f) {
    const int idx[3] = {F(f, 0), F(f, 1), F(f, 2)};
    const Eigen::Vector3d p[3] = {V.row(idx[0]), V.row(idx[1]), V.row(idx[2])};
    const FaceGeometry g = face_geometry(p, delta);
    const double area = g.area;
    if (!(area > 0)) continue;
    // obtuse corner: its opposite edge is longer than the other two together (squared)
    int obtuse = -1;
    for (int k = 0; k < 3 && obtuse < 0; ++k)
      if (g.mollified ? g.l2[k] > g.l2[(k + 1) % 3] + g.l2[(k + 2) % 3]
                      : (p[(k + 1) % 3] - p[k]).dot(p[(k + 2) % 3] - p[k]) < 0)
        obtuse = k;
    for (int k = 0; k < 3; ++k) {
      if (obtuse >= 0) {
        A(idx[k]) += (k == obtuse) ? area / 2 : area / 4;
        continue;
      }
      const int j = (k + 1) % 3, l = (k + 2) % 3;
      // Voronoi part: 1/8 (|e_kl|^2 cot(angle at j) + |e_kj|^2 cot(angle at l))
      A(idx[k]) += 0.125 * (g.l2[j] * g.cot[j] + g.l2[l] * g.cot[l]);
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

Eigen::SparseMatrix<double> laplacian_stiffness(const Eigen::MatrixX3d& V, const Eigen::MatrixX3i& F, LaplacianWeights weights) {
  return weights == LaplacianWeights::Cotangent ? cotangent_matrix(V, F) : uniform_graph_laplacian(F, V.rows());
}

Eigen::SparseMatrix<double> laplacian(const Eigen::MatrixX3d& V, const Eigen::MatrixX3i& F, LaplacianWeights weights,
                                      double sliver_guard, Eigen::SparseMatrix<double>* stiffness) {
  if (!(sliver_guard >= 0 && std::isfinite(sliver_guard)))
    throw InvalidInput("[tbsp::laplacian] sliver_guard must be >= 0 and finite (0: off)");
  const Eigen::Index n = V.rows();
  Eigen::SparseMatrix<double> K = laplacian_stiffness(V, F, weights);
  Eigen::VectorXd scale(n);
  if (weights == LaplacianWeights::Cotangent) {
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
  if (stiffness) *stiffness = std::move(K);
  return L;
}

}  // namespace tbsp
