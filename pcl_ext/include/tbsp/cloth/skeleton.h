#pragma once
/// \file skeleton.h
/// \brief A joint hierarchy with a bind (rest) pose, skinning weights (bone heat, Baran & Popović
/// 2007) and dual-quaternion skinning (Kavan et al. 2007), thesis §10.1. Poses come from BVH
/// files through capture_io (`tbsp/io/bvh_skeleton.h`) or from any other source as global joint
/// transforms.

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <Eigen/SparseCore>
#include <string>
#include <vector>

namespace tbsp {

/// Global joint transforms (one per joint, in Skeleton::joints order), world ← joint.
using SkeletonPose = std::vector<Eigen::Isometry3d>;

/// \brief A kinematic tree. Joint j's transform moves every bone that starts at j (the segments
/// from j to each of its children), as in BVH: a child's position is its parent's global transform
/// applied to the child's offset.
struct Skeleton {
  std::vector<std::string> names;  ///< one per joint (end sites included, e.g. "LeftFoot_end")
  std::vector<int> parents;        ///< parent joint index, -1 for a root; parents precede children
  SkeletonPose rest;               ///< global transforms of the bind pose (the template's pose)

  int numJoints() const { return static_cast<int>(names.size()); }
  Eigen::Vector3d restPosition(int j) const { return rest[std::size_t(j)].translation(); }
  /// Index of a joint by name, -1 when absent.
  int jointIndex(const std::string& name) const;
};

/// A bone: the segment from joint `joint` to its child joint `child` (rest positions), moved by
/// `joint`'s transform.
struct Bone {
  int joint = -1;
  int child = -1;
};

/// \brief Every parent→child segment of the skeleton, in child order, skipping segments shorter
/// than `min_length` (same units as the rest pose; coincident joints carry no geometry).
std::vector<Bone> skeleton_bones(const Skeleton& skeleton, double min_length = 1e-9);

/// \brief Checks sizes, parent order (parent < child, one or more roots) and finite, rigid rest
/// transforms. \throws InvalidInput naming the joint and what is wrong.
void validate_skeleton(const Skeleton& skeleton, const char* where = "tbsp::Skeleton");

/// \brief Per-joint skinning transforms T_j = pose_j · rest_j⁻¹ (world rest → world posed).
/// \throws InvalidInput when pose.size() differs from the joint count.
std::vector<Eigen::Isometry3d> skinning_transforms(const Skeleton& skeleton, const SkeletonPose& pose);

/// \brief Joint positions of a pose: #J by 3, row j = the translation of pose[j] (same units).
/// Complexity O(#J).
Eigen::MatrixX3d joint_positions(const SkeletonPose& pose);

/// Skinning weights: #V by #J, row-major sparse, each row non-negative and summing to 1.
using SkinningWeights = Eigen::SparseMatrix<double, Eigen::RowMajor>;

/// Parameters of bone_heat_weights.
struct BoneHeatOptions {
  /// Heat constant c of Baran & Popović (H_ii = c / d_i², d_i the distance to the nearest bone).
  /// Default 1, range (0, ∞): larger makes the weights follow the nearest bone more closely.
  double heat = 1.0;
  /// Test that the segment from a vertex to its nearest bone stays inside the mesh (ray cast):
  /// a vertex that cannot "see" its bone (an arm vertex whose nearest bone is the torso's) gets
  /// no heat from it and takes its weights from its neighbours. Default true.
  bool visibility = true;
  /// Bones within this factor of the nearest distance all heat the vertex (ties at joints).
  /// Default 1.01 (Baran & Popović), range [1, 2].
  double tie_factor = 1.01;
  /// Keep at most this many joints per vertex (largest weights, renormalised), 1..8. Default 4,
  /// what real-time skinning uses.
  int max_influences = 4;
  /// Weights below this (after keeping max_influences) are dropped, [0, 0.5). Default 0.01.
  double min_weight = 0.01;
};

/// \brief Bone-heat skinning weights (Baran & Popović 2007): for each bone b, solve
/// (−Δ + H) w_b = H p_b on the surface (Δ the cotangent Laplacian with Voronoi masses, H the
/// heat of the nearest visible bone, p_b = 1 where b is nearest). The weights of the bones of a
/// joint are summed. One sparse Cholesky factorization, one back-substitution per bone.
/// \param V, F a closed (or nearly closed) triangle mesh in the skeleton's rest pose.
/// A connected component in which no vertex can see a bone (an open layer of cloth around the
/// body) is heated from its nearest bones without the visibility test.
/// \returns #V by #J weights; joints without bones (end sites) get zero columns.
/// \throws InvalidInput for an empty mesh or a skeleton without bones; NumericalFailure if the
/// system cannot be factorized.
SkinningWeights bone_heat_weights(const Eigen::MatrixX3d& V, const Eigen::MatrixX3i& F, const Skeleton& skeleton,
                                  const BoneHeatOptions& options = {});

/// \brief Dual-quaternion skinning (Kavan et al. 2007): per vertex, the weighted sum of the
/// joints' unit dual quaternions (signs aligned with the vertex's dominant joint), normalised,
/// applied to the rest position. Rigid for any single joint; no candy-wrapper collapse.
/// Parallel over vertices (OpenMP); the result does not depend on the thread count.
/// \param V_rest #V by 3 rest positions. \param W #V by #J weights. \param T #J skinning transforms.
/// \throws InvalidInput on size mismatches.
Eigen::MatrixX3d dual_quaternion_skinning(const Eigen::MatrixX3d& V_rest, const SkinningWeights& W,
                                          const std::vector<Eigen::Isometry3d>& T);

/// \brief Linear blend skinning Σ_j w_j T_j v, for comparison (volume loss at twisted joints).
Eigen::MatrixX3d linear_blend_skinning(const Eigen::MatrixX3d& V_rest, const SkinningWeights& W,
                                       const std::vector<Eigen::Isometry3d>& T);

}  // namespace tbsp
