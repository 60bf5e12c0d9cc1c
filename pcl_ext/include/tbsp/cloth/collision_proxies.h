#pragma once
/// \file collision_proxies.h
/// \brief Collision proxies for the hidden body under loose clothing (thesis §10.4): one capped
/// cone per bone, fitted to the first pose of the reference sequence by the 1-D procedure of
/// Fig. 10.3, moved with the skeleton, and tested against the cloth by the simulator.

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <string>
#include <vector>

#include "tbsp/cloth/skeleton.h"

namespace tbsp {

/// \brief A capped cone with spherical caps (the convex hull of two spheres; a capsule when
/// r0 = r1). Exact signed distance; cheap enough to test every cloth vertex every iteration.
struct RoundCone {
  Eigen::Vector3d a = Eigen::Vector3d::Zero();  ///< centre of the first cap
  Eigen::Vector3d b = Eigen::Vector3d::Zero();  ///< centre of the second cap
  double ra = 0;                                ///< radius at a (≥ 0)
  double rb = 0;                                ///< radius at b (≥ 0)

  /// Signed distance of p (negative inside) and, if `normal` is given, the outward unit normal
  /// of the closest surface point. Exact (Quílez' round-cone distance). A sphere contains the
  /// other (|a−b| ≤ |ra−rb|): the larger sphere.
  double signedDistance(const Eigen::Vector3d& p, Eigen::Vector3d* normal = nullptr) const;
  /// The cone moved by a rigid transform.
  RoundCone transformed(const Eigen::Isometry3d& T) const;
};

/// A proxy attached to a bone: its cone in the bone joint's rest frame (world rest pose).
struct CollisionProxy {
  Bone bone;       ///< the bone whose joint moves it
  RoundCone cone;  ///< in the rest pose (world coordinates)
  int vertices = 0;       ///< mesh vertices used for the fit
  /// Largest depth of a body vertex (clothness < 0.5) of this bone inside the cone side, rest
  /// pose, units of V (radial, in the 1-D model of the fit, over 0.05 ≤ t ≤ 0.95; the caps are not tested).
  double penetration = 0;
};

/// Parameters of fit_collision_proxies.
struct ProxyFitOptions {
  /// Bones whose joint names contain one of these (case-insensitive) get proxies; empty = every
  /// bone. Default: limbs and spine, the bones the thesis' skirts collide with.
  std::vector<std::string> joints = {};
  /// Keep proxies inside the surface: 99 % of the body vertices (clothness < 0.5) may lie at most
  /// this far inside the cone, as a fraction of the cone's mean radius. Default 0.02, range [0, 1].
  double max_penetration = 0.02;
  /// Average the radii at joints shared by consecutive bones and of left/right bone pairs
  /// (names equal after swapping Left/Right or L/R prefixes). Default true (thesis).
  bool symmetrize = true;
  /// Minimum vertices assigned to a bone to fit its cone; bones with fewer get none. Default 12.
  int min_vertices = 12;
};

/// \brief Fits one capped cone per bone (§10.4, Fig. 10.3): every vertex is assigned to its
/// nearest bone and written in cylindrical coordinates (t along the bone, r around it); those with
/// 0.05 ≤ t ≤ 0.95 (the limb, not the joint ends) are used;
/// r is reduced by the vertex's σ (the deviation that gave its clothness); a weighted linear
/// regression r(t) = ra + (rb − ra) t with weights 1/(σ + ε), made robust by iterative
/// reweighting (Tukey biweight; vertices of other parts nearest the bone are outliers), gives the
/// radii; radii are then averaged at joints joining exactly two fitted bones and over left/right
/// pairs, and finally shrunk until 99 % of the bone's body vertices (clothness < 0.5) lie at most
/// `max_penetration` inside (the largest depth is reported in CollisionProxy::penetration).
/// \param V, F first pose of the reference (rest pose of the skeleton).
/// \param sigma per-vertex deviation (ClothSegmentation), same units as V; empty = zeros.
/// \param clothness per-vertex δ in [0,1]; empty = zeros.
/// \throws InvalidInput on size mismatches, non-finite input or a skeleton without bones.
std::vector<CollisionProxy> fit_collision_proxies(const Eigen::MatrixX3d& V, const Eigen::MatrixX3i& F, const Skeleton& skeleton,
                                                  const Eigen::VectorXd& sigma, const Eigen::VectorXd& clothness,
                                                  const ProxyFitOptions& options = {});

/// \brief The proxies in a pose: each cone moved by its joint's skinning transform.
std::vector<RoundCone> posed_proxies(const std::vector<CollisionProxy>& proxies, const std::vector<Eigen::Isometry3d>& skinning);

}  // namespace tbsp
