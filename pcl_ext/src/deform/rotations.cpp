#include "tbsp/deform/rotations.h"

#include <Eigen/SVD>
#include <cmath>
#include <vector>

namespace tbsp {

namespace {
Eigen::Matrix3d svd_rotation(const Eigen::Matrix3d& T) {
  Eigen::JacobiSVD<Eigen::Matrix3d> svd(T, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Matrix3d U = svd.matrixU();
  const Eigen::Matrix3d V = svd.matrixV();
  if ((U * V.transpose()).determinant() < 0) U.col(2) *= -1;
  return U * V.transpose();
}

// H^{-T} = cof(H) / det(H) for a 3x3 matrix; returns det.
double inverse_transpose(const Eigen::Matrix3d& H, Eigen::Matrix3d& out) {
  const Eigen::Vector3d c0 = H.col(1).cross(H.col(2));
  const Eigen::Vector3d c1 = H.col(2).cross(H.col(0));
  const Eigen::Vector3d c2 = H.col(0).cross(H.col(1));
  const double det = H.col(0).dot(c0);
  const double inv = 1.0 / det;
  out.col(0) = c0 * inv;
  out.col(1) = c1 * inv;
  out.col(2) = c2 * inv;
  return det;
}

}  // namespace

Eigen::Matrix3d polar_rotation(const Eigen::Matrix3d& F, const Eigen::Matrix3d& R0, int* iterations) {
  if (iterations) *iterations = 0;
  if (!F.allFinite()) return R0;
  Eigen::Matrix3d H = R0.transpose() * F;
  const double scale = H.norm();
  if (!(scale > 0) || !std::isfinite(scale)) return R0;
  Eigen::Matrix3d Hit;
  double det = inverse_transpose(H, Hit);
  if (!(det > 1e-10 * scale * scale * scale)) return svd_rotation(F);
  for (int k = 0; k < 30; ++k) {
    // determinant scaling (Higham) while far from orthogonal; plain Newton near convergence
    const double gamma = std::abs(det - 1) > 1e-4 ? std::cbrt(1.0 / det) : 1.0;
    const Eigen::Matrix3d next = 0.5 * (gamma * H + Hit / gamma);
    const double change = (next - H).squaredNorm();
    H = next;
    if (iterations) *iterations = k + 1;
    // quadratic convergence: a step of size c leaves an error of about c^2 (here < 1e-14)
    if (change < 1e-14) break;
    det = inverse_transpose(H, Hit);
  }
  if (!H.allFinite()) return svd_rotation(F);
  return R0 * H;
}

Eigen::Matrix3d closest_rotation(const Eigen::Matrix3d& T, int* iterations) {
  return polar_rotation(T, Eigen::Matrix3d::Identity(), iterations);
}

void make_hemisphere_consistent(std::vector<Eigen::Quaterniond>& q, const std::vector<int>& order,
                                const std::vector<int>& parent) {
  for (int i : order) {
    const int p = parent[std::size_t(i)];
    if (p < 0) continue;
    if (q[std::size_t(i)].coeffs().dot(q[std::size_t(p)].coeffs()) < 0) q[std::size_t(i)].coeffs() *= -1;
  }
}

}  // namespace tbsp
