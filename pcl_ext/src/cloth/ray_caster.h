#pragma once
// Internal: ray casting against a triangle mesh with Embree (single-precision BVH and hit test),
// the hit refined in double precision on the face Embree reports (Möller–Trumbore), so the
// distance and barycentric coordinates are exact for that face.

#include <Eigen/Core>
#include <memory>

namespace tbsp {
namespace detail {

struct RayHit {
  int face = -1;            // -1: no hit
  double t = 0;             // distance along the (unit) direction
  Eigen::Vector3d bary{0, 0, 0};  // weights of F(face, 0..2)
};

class RayCaster {
public:
  RayCaster(const Eigen::MatrixX3d& V, const Eigen::MatrixX3i& F);
  ~RayCaster();
  RayCaster(const RayCaster&) = delete;
  RayCaster& operator=(const RayCaster&) = delete;

  // First hit of origin + t·dir (dir normalised here) with t in (t_near, t_far), ignoring faces
  // incident to vertex `skip_vertex` (-1: none). Thread-safe.
  RayHit cast(const Eigen::Vector3d& origin, const Eigen::Vector3d& dir, double t_near, double t_far,
              int skip_vertex = -1) const;
  // True when the open segment (a, b) shrunk by `margin` at both ends crosses the mesh.
  bool blocked(const Eigen::Vector3d& a, const Eigen::Vector3d& b, double margin) const;

private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace detail
}  // namespace tbsp
