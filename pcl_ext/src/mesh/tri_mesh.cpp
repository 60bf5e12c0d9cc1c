#include "tbsp/mesh/tri_mesh.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>

namespace tbsp {

double bbox_diagonal(const Eigen::MatrixX3d& V) {
  if (V.rows() < 2) return 0.0;
  return (V.colwise().maxCoeff() - V.colwise().minCoeff()).norm();
}

Eigen::MatrixX3d face_normals(const Eigen::MatrixX3d& V, const Eigen::MatrixX3i& F) {
  Eigen::MatrixX3d N(F.rows(), 3);
  for (Eigen::Index f = 0; f < F.rows(); ++f) {
    const Eigen::Vector3d a = V.row(F(f, 0)), b = V.row(F(f, 1)), c = V.row(F(f, 2));
    Eigen::Vector3d n = (b - a).cross(c - a);
    const double len = n.norm();
    N.row(f) = len > 0 ? Eigen::RowVector3d(n.transpose() / len) : Eigen::RowVector3d::Zero();
  }
  return N;
}

Eigen::VectorXd face_areas(const Eigen::MatrixX3d& V, const Eigen::MatrixX3i& F) {
  Eigen::VectorXd A(F.rows());
  for (Eigen::Index f = 0; f < F.rows(); ++f) {
    const Eigen::Vector3d a = V.row(F(f, 0)), b = V.row(F(f, 1)), c = V.row(F(f, 2));
    A(f) = 0.5 * (b - a).cross(c - a).norm();
  }
  return A;
}

Eigen::MatrixX3d vertex_normals(const Eigen::MatrixX3d& V, const Eigen::MatrixX3i& F) {
  Eigen::MatrixX3d N = Eigen::MatrixX3d::Zero(V.rows(), 3);
  const Eigen::MatrixX3d FN = face_normals(V, F);
  for (Eigen::Index f = 0; f < F.rows(); ++f) {
    for (int k = 0; k < 3; ++k) {
      const Eigen::Vector3d p = V.row(F(f, k));
      Eigen::Vector3d e1 = Eigen::Vector3d(V.row(F(f, (k + 1) % 3))) - p;
      Eigen::Vector3d e2 = Eigen::Vector3d(V.row(F(f, (k + 2) % 3))) - p;
      const double l1 = e1.norm(), l2 = e2.norm();
      if (l1 <= 0 || l2 <= 0) continue;
      const double angle = std::acos(std::clamp(e1.dot(e2) / (l1 * l2), -1.0, 1.0));
      N.row(F(f, k)) += angle * FN.row(f);
    }
  }
  for (Eigen::Index i = 0; i < N.rows(); ++i) {
    const double len = N.row(i).norm();
    if (len > 0) N.row(i) /= len;
  }
  return N;
}

}  // namespace tbsp
