#pragma once
/// \file point_mesh_distance.h
/// \brief Exact point-to-triangle-mesh distances with CGAL's AABB tree (closest point, face).

#include <Eigen/Core>
#include <memory>

namespace tbsp {

/// \brief AABB tree over a triangle mesh; closest-point queries are exact and thread-safe.
class MeshDistance {
public:
  MeshDistance(const Eigen::MatrixX3d& V, const Eigen::MatrixX3i& F);
  ~MeshDistance();
  /// Closest point on the mesh to q; `face` receives the triangle index. O(log #F) typical.
  Eigen::Vector3d closest(const Eigen::Vector3d& q, int* face = nullptr) const;
  /// Unsigned distances of all rows of P (#P), computed in parallel.
  Eigen::VectorXd distances(const Eigen::MatrixX3d& P, Eigen::VectorXi* faces = nullptr) const;

private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace tbsp
