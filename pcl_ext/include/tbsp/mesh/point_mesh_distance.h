#pragma once
/// \file point_mesh_distance.h
/// \brief Exact point-to-triangle-mesh distances with CGAL's AABB tree (closest point, face).

#include <Eigen/Core>
#include <memory>

namespace tbsp {

/// \brief Closest point to p on the triangle abc, as barycentric weights (wa, wb, wc) ≥ 0 that sum
/// to 1 (Ericson, Real-Time Collision Detection §5.1.5: Voronoi regions of vertices, edges and
/// face). O(1). A degenerate triangle (collinear or coincident corners) gives the closest point
/// of its longest edge. Written by hand for the fitter's per-iteration closest-point updates of
/// every cloud point among a few faces, where building CGAL's AABB tree again would dominate.
Eigen::Vector3d closest_point_barycentric(const Eigen::Vector3d& p, const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                                          const Eigen::Vector3d& c);

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
