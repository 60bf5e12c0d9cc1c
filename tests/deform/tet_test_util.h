#pragma once
// Shared fixtures for the tet-deformation tests: a tetrahedralized bar (thesis Fig. 7.2/7.3).
#include <Eigen/Geometry>
#include <vector>

#include "tbsp/mesh/primitives.h"
#include "tbsp/mesh/tet_mesh.h"
#include "tbsp/mesh/tetrahedralize.h"

namespace tbsp::test {

/// Bar [0,L]x[0,w]x[0,w] tetrahedralized by TetGen (surface preserved).
inline TetMesh make_bar_tets(double L = 1.0, double w = 0.2, int n_long = 20, int n_cross = 4, double max_volume = 0.0) {
  const TriMesh box = make_box(n_long, n_cross, n_cross, L, w, w);
  TetgenOptions o;
  o.max_volume = max_volume > 0 ? max_volume : std::pow(L / n_long, 3) / 6.0;
  return tetrahedralize(box, o);
}

/// Vertices with x <= x0 (or x >= x1 when `upper`).
inline std::vector<int> vertices_x(const Eigen::MatrixX3d& V, double x, bool upper) {
  std::vector<int> out;
  for (Eigen::Index i = 0; i < V.rows(); ++i)
    if (upper ? V(i, 0) >= x : V(i, 0) <= x) out.push_back(int(i));
  return out;
}

/// Signed volume enclosed by a closed, outward-oriented surface (divergence theorem).
inline double enclosed_volume(const Eigen::MatrixX3d& V, const Eigen::MatrixX3i& F) {
  double v = 0;
  for (Eigen::Index f = 0; f < F.rows(); ++f)
    v += Eigen::Vector3d(V.row(F(f, 0))).dot(Eigen::Vector3d(V.row(F(f, 1))).cross(Eigen::Vector3d(V.row(F(f, 2))))) / 6.0;
  return v;
}

/// Mean |l'/l − 1| over the edges of F.
inline double edge_length_distortion(const Eigen::MatrixX3d& V0, const Eigen::MatrixX3d& V1, const Eigen::MatrixX3i& F) {
  double s = 0;
  long n = 0;
  for (Eigen::Index f = 0; f < F.rows(); ++f)
    for (int k = 0; k < 3; ++k) {
      const int a = F(f, k), b = F(f, (k + 1) % 3);
      if (a > b) continue;  // each interior edge once from one side (closed meshes: exactly once)
      const double l0 = (V0.row(a) - V0.row(b)).norm(), l1 = (V1.row(a) - V1.row(b)).norm();
      s += std::abs(l1 / l0 - 1);
      ++n;
    }
  return s / double(std::max(1L, n));
}

}  // namespace tbsp::test
