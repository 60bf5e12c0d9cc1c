#pragma once
// Constraint sets for the inverse-texture-mapping tests: a reference texture layout per mesh
// (planar projection for disc-like meshes, longitude/latitude wrap for closed ones) and k
// constraints at farthest-point-sampled vertices placed by that layout.
#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <vector>

#include "test_util.h"
#include "tbsp/fitting/inverse_texture_mapping.h"

namespace tbsp::test {

/// Reference pixel positions of all vertices. Planar: PCA projection onto the two main axes,
/// fitted into the image with a 6 % margin (given the faces, oriented so that the image is not
/// mirrored seen from the front). Wrap: longitude/latitude around the main PCA axis.
inline Eigen::MatrixX2d reference_layout(const Eigen::MatrixX3d& V, int W, int H, bool wrap, const Eigen::MatrixX3i* F = nullptr) {
  const Eigen::RowVector3d c = V.colwise().mean();
  const Eigen::MatrixX3d X = V.rowwise() - c;
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(X.transpose() * X);
  const Eigen::Vector3d a0 = es.eigenvectors().col(2), a2 = es.eigenvectors().col(0);
  Eigen::Vector3d a1 = es.eigenvectors().col(1);
  if (!wrap && F != nullptr) {
    // Not mirrored: seen along the mean normal, image x runs along a0 and image "up" along a1.
    Eigen::Vector3d n = Eigen::Vector3d::Zero();
    for (Eigen::Index f = 0; f < F->rows(); ++f)
      n += (V.row((*F)(f, 1)) - V.row((*F)(f, 0))).cross(V.row((*F)(f, 2)) - V.row((*F)(f, 0))).transpose();
    if (a0.cross(a1).dot(n) < 0) a1 = -a1;
  }
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

/// A reference texture layout of part of a closed mesh: pixel positions of all vertices and the
/// region the image is meant to cover (the vertices whose layout lies in the image and is a
/// valid, fold-free map there).
struct RegionLayout {
  Eigen::MatrixX2d pixel;
  std::vector<char> region;
  long size() const { return static_cast<long>(std::count(region.begin(), region.end(), 1)); }
};

/// Cylindrical layout of a bust whose axis is y and whose face looks towards −z (the Max Planck
/// bust of libigl's decimated-max.obj): x = angle around the vertical axis through the centroid,
/// |angle| < half_angle, y = height between y_lo and y_hi; region = those vertices whose normal
/// points outwards (radial component > 0.3, no overhangs). 4 % margin in the image.
inline RegionLayout bust_face_layout(const Eigen::MatrixX3d& V, const Eigen::MatrixX3d& N, int W, int H, double half_angle_deg, double y_lo, double y_hi) {
  const double xc = V.col(0).mean(), zc = V.col(2).mean(), ha = half_angle_deg * M_PI / 180;
  RegionLayout out;
  out.pixel.resize(V.rows(), 2);
  out.region.assign(static_cast<std::size_t>(V.rows()), 0);
  for (Eigen::Index i = 0; i < V.rows(); ++i) {
    const Eigen::Vector2d radial(xc - V(i, 0), zc - V(i, 2));  // (right, towards the viewer) seen from the front
    const double u = std::atan2(radial.x(), radial.y()), y = V(i, 1);
    out.pixel(i, 0) = (W - 1) * (0.04 + 0.92 * (0.5 + 0.5 * u / ha));
    out.pixel(i, 1) = (H - 1) * (0.04 + 0.92 * (y_hi - y) / (y_hi - y_lo));
    out.region[i] = std::abs(u) < ha && y > y_lo && y < y_hi && Eigen::Vector2d(-N(i, 0), -N(i, 2)).dot(radial.normalized()) > 0.3;
  }
  return out;
}

/// Layout of an arc of one handle of the genus-2 "eight" (eight.off: in the x-y plane, holes on
/// the y axis): x = angle around the hole centre (0, hole_y), |angle| < half_angle; y = angle
/// around the tube (centre-line radius R), all the way round — the image wraps the tube and
/// meets itself along the inner side (the Fig. 4.5 situation).
inline RegionLayout eight_handle_layout(const Eigen::MatrixX3d& V, int W, int H, double half_angle_deg, double hole_y, double R) {
  const double ha = half_angle_deg * M_PI / 180;
  RegionLayout out;
  out.pixel.resize(V.rows(), 2);
  out.region.assign(static_cast<std::size_t>(V.rows()), 0);
  for (Eigen::Index i = 0; i < V.rows(); ++i) {
    const double dx = V(i, 0), dy = V(i, 1) - hole_y;
    const double u = std::atan2(dx, dy), v = std::atan2(V(i, 2), std::hypot(dx, dy) - R);
    out.pixel(i, 0) = (W - 1) * (0.04 + 0.92 * (0.5 + 0.5 * u / ha));
    out.pixel(i, 1) = (H - 1) * (0.04 + 0.92 * (0.5 + 0.5 * v / M_PI));
    out.region[i] = std::abs(u) < ha;
  }
  return out;
}

/// k constraints at farthest-point-sampled region vertices whose layout is at least 8 % of the
/// image away from the image border.
inline std::vector<TextureConstraint> region_constraints(const Eigen::MatrixX3d& V, const RegionLayout& L, int W, int H, int k) {
  std::vector<int> allowed;
  for (Eigen::Index i = 0; i < V.rows(); ++i) {
    const double fx = L.pixel(i, 0) / (W - 1), fy = L.pixel(i, 1) / (H - 1);
    if (L.region[i] && fx > 0.08 && fx < 0.92 && fy > 0.08 && fy < 0.92) allowed.push_back(static_cast<int>(i));
  }
  Eigen::MatrixX3d A(allowed.size(), 3);
  for (std::size_t i = 0; i < allowed.size(); ++i) A.row(i) = V.row(allowed[i]);
  std::vector<TextureConstraint> out;
  for (int p : farthest_points(A, k, 0)) {
    TextureConstraint c;
    c.vertex = allowed[p];
    c.pixel = L.pixel.row(c.vertex).transpose();
    out.push_back(c);
  }
  return out;
}

}  // namespace tbsp::test
