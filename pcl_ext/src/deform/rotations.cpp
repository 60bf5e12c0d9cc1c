#include "tbsp/deform/rotations.h"

#include <Eigen/SVD>
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
}  // namespace

Eigen::Matrix3d closest_rotation(const Eigen::Matrix3d& T, int* iterations) {
  if (iterations) *iterations = 0;
  if (!T.allFinite()) return Eigen::Matrix3d::Identity();
  Eigen::JacobiSVD<Eigen::Matrix3d> svd(T);
  const auto s = svd.singularValues();
  if (T.determinant() <= 0 || !(s(2) > 1e-8 * s(0))) return svd_rotation(T);
  Eigen::Matrix3d H = T;
  for (int k = 0; k < 50; ++k) {
    const Eigen::Matrix3d next = 0.5 * (H + H.inverse().transpose());
    const double change = (next - H).norm();
    H = next;
    if (iterations) *iterations = k + 1;
    if (change < 1e-12 * std::max(1.0, H.norm())) break;
  }
  // guard against a non-converged or non-orthogonal result (should not happen for det > 0)
  if (!H.allFinite() || (H.transpose() * H - Eigen::Matrix3d::Identity()).norm() > 1e-8) return svd_rotation(T);
  return H;
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
