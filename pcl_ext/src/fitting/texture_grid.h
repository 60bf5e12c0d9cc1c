#pragma once
// Internal: the image grid, its normal equations and helpers of inverse texture mapping (ch. 4),
// kept apart from the five stages of InverseTextureMapping::compute().
#include <Eigen/Dense>
#include <nanoflann.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <string>
#include <vector>

#include "tbsp/core/error.h"
#include "tbsp/fitting/inverse_texture_mapping.h"
#include "tbsp/solve/sparse_cholesky.h"

namespace tbsp::detail {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

inline std::string px(const Eigen::Vector2d& p) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "(%.1f, %.1f)", p.x(), p.y());
  return buf;
}

/// A regular grid of nodes over the image, some of them active (inside the mask).
struct Grid {
  int w = 0, h = 0;          // nodes
  double sx = 1, sy = 1;     // pixels between nodes
  std::vector<int> index;    // w*h -> active id or -1
  std::vector<int> node_x, node_y;  // per active node: grid coordinates

  int at(int i, int j) const { return (i < 0 || j < 0 || i >= w || j >= h) ? -1 : index[static_cast<std::size_t>(j) * w + i]; }
  long active() const { return static_cast<long>(node_x.size()); }
  Eigen::Vector2d pixel(int a) const { return {node_x[a] * sx, node_y[a] * sy}; }
  bool cellActive(int i, int j) const { return at(i, j) >= 0 && at(i + 1, j) >= 0 && at(i, j + 1) >= 0 && at(i + 1, j + 1) >= 0; }

  /// Keeps only nodes that belong to at least one active cell, then numbers them.
  void finalize(const std::vector<char>& on) {
    index.assign(static_cast<std::size_t>(w) * h, -1);
    auto is_on = [&](int i, int j) { return i >= 0 && j >= 0 && i < w && j < h && on[static_cast<std::size_t>(j) * w + i]; };
    node_x.clear();
    node_y.clear();
    for (int j = 0; j < h; ++j)
      for (int i = 0; i < w; ++i) {
        if (!is_on(i, j)) continue;
        bool in_cell = false;
        for (int di = -1; di <= 0 && !in_cell; ++di)
          for (int dj = -1; dj <= 0 && !in_cell; ++dj)
            in_cell = is_on(i + di, j + dj) && is_on(i + di + 1, j + dj) && is_on(i + di, j + dj + 1) && is_on(i + di + 1, j + dj + 1);
        if (!in_cell) continue;
        index[static_cast<std::size_t>(j) * w + i] = static_cast<int>(node_x.size());
        node_x.push_back(i);
        node_y.push_back(j);
      }
  }

  /// Bilinear weights of a pixel position over the active nodes; false if the pixel is outside
  /// the active region. Falls back to the nearest active corner when the cell is partly active.
  bool weights(const Eigen::Vector2d& p, std::vector<std::pair<int, double>>& out) const {
    out.clear();
    const double u = p.x() / sx, v = p.y() / sy;
    if (!(u >= -1e-9 && v >= -1e-9 && u <= w - 1 + 1e-9 && v <= h - 1 + 1e-9)) return false;
    const int i = std::clamp(static_cast<int>(std::floor(u)), 0, w - 2), j = std::clamp(static_cast<int>(std::floor(v)), 0, h - 2);
    const double fu = std::clamp(u - i, 0.0, 1.0), fv = std::clamp(v - j, 0.0, 1.0);
    if (cellActive(i, j)) {
      const double wt[4] = {(1 - fu) * (1 - fv), fu * (1 - fv), (1 - fu) * fv, fu * fv};
      const int id[4] = {at(i, j), at(i + 1, j), at(i, j + 1), at(i + 1, j + 1)};
      for (int c = 0; c < 4; ++c)
        if (wt[c] > 0) out.emplace_back(id[c], wt[c]);
      return true;
    }
    const int ci = fu < 0.5 ? i : i + 1, cj = fv < 0.5 ? j : j + 1;
    if (at(ci, cj) < 0) return false;
    out.emplace_back(at(ci, cj), 1.0);
    return true;
  }

  Eigen::MatrixX3i faces() const {
    std::vector<Eigen::Vector3i> f;
    for (int j = 0; j + 1 < h; ++j)
      for (int i = 0; i + 1 < w; ++i)
        if (cellActive(i, j)) {
          const int a = at(i, j), b = at(i + 1, j), c = at(i + 1, j + 1), d = at(i, j + 1);
          f.emplace_back(a, c, b);
          f.emplace_back(a, d, c);
        }
    Eigen::MatrixX3i F(f.size(), 3);
    for (std::size_t r = 0; r < f.size(); ++r) F.row(r) = f[r].transpose();
    return F;
  }
};

/// Normal equations Σ_rows w²·(row)ᵀ(row) of least-squares rows that couple grid nodes at most
/// one cell apart diagonally or two nodes apart along a grid line (second differences, bilinear
/// cells). Accumulated straight into the 7 lower-triangle slots per node and assembled as CSC
/// without triplets: the rows of a column are the node itself and its neighbours at grid offsets
/// (+1,0) (+2,0) (−1,+1) (0,+1) (+1,+1) (0,+2), ascending in the row-major numbering. The pattern
/// depends on the grid only, so all systems on one grid share it.
struct NormalEquations {
  static constexpr int kSlots = 7;
  static constexpr int kOff[kSlots][2] = {{0, 0}, {1, 0}, {2, 0}, {-1, 1}, {0, 1}, {1, 1}, {0, 2}};
  const Grid& g;
  std::vector<double> val;  // node * kSlots + slot
  Eigen::MatrixX3d rhs;
  explicit NormalEquations(const Grid& grid) : g(grid), val(static_cast<std::size_t>(grid.active()) * kSlots, 0.0), rhs(Eigen::MatrixX3d::Zero(grid.active(), 3)) {}
  static int slot(int di, int dj) {
    for (int t = 0; t < kSlots; ++t)
      if (kOff[t][0] == di && kOff[t][1] == dj) return t;
    return -1;
  }
  void addRow(const std::pair<int, double>* e, int m, double weight2, const Eigen::Vector3d& target = Eigen::Vector3d::Zero()) {
    for (int a = 0; a < m; ++a) {
      for (int b = 0; b < m; ++b) {
        const int p = e[a].first, q = e[b].first;  // entry (row p, column q), p >= q
        if (p < q) continue;
        const int t = slot(g.node_x[p] - g.node_x[q], g.node_y[p] - g.node_y[q]);
        assert(t >= 0);
        if (t >= 0) val[static_cast<std::size_t>(q) * kSlots + t] += weight2 * e[a].second * e[b].second;
      }
      rhs.row(e[a].first) += weight2 * e[a].second * target.transpose();
    }
  }
  Eigen::SparseMatrix<double> matrix() const {
    const long n = g.active();
    Eigen::SparseMatrix<double> A(n, n);
    std::vector<int> outer(static_cast<std::size_t>(n) + 1, 0), inner;
    std::vector<double> v;
    inner.reserve(static_cast<std::size_t>(n) * kSlots);
    v.reserve(static_cast<std::size_t>(n) * kSlots);
    for (long q = 0; q < n; ++q) {
      for (int t = 0; t < kSlots; ++t) {
        const int p = g.at(g.node_x[q] + kOff[t][0], g.node_y[q] + kOff[t][1]);
        if (p < 0) continue;
        inner.push_back(p);
        v.push_back(val[static_cast<std::size_t>(q) * kSlots + t]);
      }
      outer[static_cast<std::size_t>(q) + 1] = static_cast<int>(inner.size());
    }
    A.resizeNonZeros(static_cast<Eigen::Index>(inner.size()));
    std::copy(outer.begin(), outer.end(), A.outerIndexPtr());
    std::copy(inner.begin(), inner.end(), A.innerIndexPtr());
    std::copy(v.begin(), v.end(), A.valuePtr());
    return A;
  }
};

/// Thin-plate (+ a vanishing membrane term for definiteness) rows of the grid.
inline void add_thin_plate(const Grid& g, NormalEquations& ne) {
  const double area = g.sx * g.sy;
  const double wxx = area / std::pow(g.sx, 4), wyy = area / std::pow(g.sy, 4), wxy = 2.0 * area / (area * area);
  const double wmem = 1e-12 * (wxx + wyy);
  for (int j = 0; j < g.h; ++j)
    for (int i = 0; i < g.w; ++i) {
      const int c = g.at(i, j);
      if (c < 0) continue;
      const int l = g.at(i - 1, j), r = g.at(i + 1, j), u = g.at(i, j - 1), d = g.at(i, j + 1);
      if (l >= 0 && r >= 0) {
        const std::pair<int, double> e[3] = {{l, 1.0}, {c, -2.0}, {r, 1.0}};
        ne.addRow(e, 3, wxx);
      }
      if (u >= 0 && d >= 0) {
        const std::pair<int, double> e[3] = {{u, 1.0}, {c, -2.0}, {d, 1.0}};
        ne.addRow(e, 3, wyy);
      }
      if (g.cellActive(i, j)) {
        const std::pair<int, double> e[4] = {{c, 1.0}, {r, -1.0}, {d, -1.0}, {g.at(i + 1, j + 1), 1.0}};
        ne.addRow(e, 4, wxy);
      }
      if (r >= 0) {
        const std::pair<int, double> e[2] = {{c, 1.0}, {r, -1.0}};
        ne.addRow(e, 2, wmem);
      }
      if (d >= 0) {
        const std::pair<int, double> e[2] = {{c, 1.0}, {d, -1.0}};
        ne.addRow(e, 2, wmem);
      }
    }
}

/// RMS of the second differences of X over the grid divided by the mean edge length.
inline double roughness(const Grid& g, const Eigen::MatrixX3d& X) {
  double s2 = 0, len = 0;
  long n2 = 0, nl = 0;
  for (int j = 0; j < g.h; ++j)
    for (int i = 0; i < g.w; ++i) {
      const int c = g.at(i, j);
      if (c < 0) continue;
      const int l = g.at(i - 1, j), r = g.at(i + 1, j), u = g.at(i, j - 1), d = g.at(i, j + 1);
      if (l >= 0 && r >= 0) { s2 += (X.row(l) - 2 * X.row(c) + X.row(r)).squaredNorm(); ++n2; }
      if (u >= 0 && d >= 0) { s2 += (X.row(u) - 2 * X.row(c) + X.row(d)).squaredNorm(); ++n2; }
      if (r >= 0) { len += (X.row(r) - X.row(c)).norm(); ++nl; }
      if (d >= 0) { len += (X.row(d) - X.row(c)).norm(); ++nl; }
    }
  if (n2 == 0 || nl == 0 || !(len > 0)) return 0;
  return std::sqrt(s2 / n2) / (len / nl);
}

inline Eigen::MatrixX3d solve(const NormalEquations& ne, SparseCholesky& chol, const std::string& stage) {
  try {
    chol.compute(ne.matrix());
  } catch (const NumericalFailure& e) {
    throw InvalidInput("[tbsp::InverseTextureMapping::compute] " + stage + ": the system is singular (" + e.what() +
                       "); every pattern piece needs at least 3 constraints that are not on one line");
  }
  return chol.solve(ne.rhs);
}

inline double percentile(std::vector<double> v, double p) {
  if (v.empty()) return 0;
  const std::size_t k = std::min(v.size() - 1, static_cast<std::size_t>(p * (v.size() - 1) + 0.5));
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(k), v.end());
  return v[k];
}

using KdMatrix = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
using KdTree = nanoflann::KDTreeEigenMatrixAdaptor<KdMatrix, -1, nanoflann::metric_L2_Simple, true>;


}  // namespace tbsp::detail
