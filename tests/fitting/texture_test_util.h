#pragma once
// Constraint sets for the inverse-texture-mapping tests: a reference texture layout per mesh
// (planar projection for disc-like meshes, longitude/latitude wrap for closed ones) and k
// constraints at farthest-point-sampled vertices placed by that layout.
#include <Eigen/Dense>
#include <cmath>
#include <vector>

#include "test_util.h"
#include "tbsp/fitting/inverse_texture_mapping.h"

namespace tbsp::test {

/// Reference pixel positions of all vertices. Planar: PCA projection onto the two main axes,
/// fitted into the image with a 6 % margin. Wrap: longitude/latitude around the main PCA axis.
inline Eigen::MatrixX2d reference_layout(const Eigen::MatrixX3d& V, int W, int H, bool wrap) {
  const Eigen::RowVector3d c = V.colwise().mean();
  const Eigen::MatrixX3d X = V.rowwise() - c;
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(X.transpose() * X);
  const Eigen::Vector3d a0 = es.eigenvectors().col(2), a1 = es.eigenvectors().col(1), a2 = es.eigenvectors().col(0);
  Eigen::MatrixX2d P(V.rows(), 2);
  for (Eigen::Index i = 0; i < V.rows(); ++i) {
    const Eigen::Vector3d x = X.row(i).transpose();
    if (!wrap) {
      P(i, 0) = x.dot(a0);
      P(i, 1) = -x.dot(a1);
    } else {
      // pole along the smallest axis: longitude sweeps the two large ones
      P(i, 0) = std::atan2(x.dot(a1), x.dot(a0));
      P(i, 1) = -std::atan2(x.dot(a2), std::hypot(x.dot(a0), x.dot(a1)));
    }
  }
  const Eigen::RowVector2d lo = P.colwise().minCoeff(), hi = P.colwise().maxCoeff();
  const double m = 0.06;
  double scale = std::min((W - 1) * (1 - 2 * m) / (hi.x() - lo.x()), (H - 1) * (1 - 2 * m) / (hi.y() - lo.y()));
  Eigen::MatrixX2d out(V.rows(), 2);
  for (Eigen::Index i = 0; i < V.rows(); ++i) {
    if (wrap) {
      out(i, 0) = (W - 1) * (m + (1 - 2 * m) * (P(i, 0) - lo.x()) / (hi.x() - lo.x()));
      out(i, 1) = (H - 1) * (m + (1 - 2 * m) * (P(i, 1) - lo.y()) / (hi.y() - lo.y()));
    } else {
      out(i, 0) = (W - 1) / 2.0 + scale * (P(i, 0) - 0.5 * (lo.x() + hi.x()));
      out(i, 1) = (H - 1) / 2.0 + scale * (P(i, 1) - 0.5 * (lo.y() + hi.y()));
    }
  }
  return out;
}

/// k constraints at farthest-point-sampled vertices (seeded by vertex 0); for wraps, only
/// vertices away from the seam and the poles are used.
inline std::vector<TextureConstraint> layout_constraints(const Eigen::MatrixX3d& V, const Eigen::MatrixX2d& layout, int W, int H,
                                                         int k, bool wrap) {
  std::vector<int> allowed;
  for (Eigen::Index i = 0; i < V.rows(); ++i) {
    const double fx = layout(i, 0) / (W - 1), fy = layout(i, 1) / (H - 1);
    if (!wrap || (fx > 0.12 && fx < 0.88 && fy > 0.15 && fy < 0.85)) allowed.push_back(static_cast<int>(i));
  }
  Eigen::MatrixX3d A(allowed.size(), 3);
  for (std::size_t i = 0; i < allowed.size(); ++i) A.row(i) = V.row(allowed[i]);
  const std::vector<int> pick = farthest_points(A, k, 0);
  std::vector<TextureConstraint> out;
  for (int p : pick) {
    TextureConstraint c;
    c.vertex = allowed[p];
    c.pixel = layout.row(c.vertex).transpose();
    out.push_back(c);
  }
  return out;
}

}  // namespace tbsp::test
