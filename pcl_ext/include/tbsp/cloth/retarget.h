#pragma once
/// \file retarget.h
/// \brief Drives a skeleton with a motion recorded on another skeleton (other joint names, bone
/// lengths, rest pose and local axes): a new animation of a model from any clip.
///
/// Method (position-based retargeting): a joint map names, for some model joints, the clip joint
/// that plays its part. Per frame and model joint j (parents first), the rotation R_j takes the
/// model's rest directions from j to its nearest mapped descendants onto the clip's directions
/// between the mapped joints: with two or more non-parallel directions the best rotation of
/// unit vectors (Kabsch; e.g. the hip: spine and both thighs), with one the smallest rotation
/// after the parent's (the twist about a single bone is the parent's: a clip's bone twist is not
/// observable from positions), with none the parent's. Bones keep the model's lengths (forward
/// kinematics); the root follows the clip root's motion since the first frame, scaled by ρ = the
/// summed length of the mapped model bones over the clip's (unit conversion and body size at once).
/// So the result does not depend on the clip's local axes or its zero pose, only on where its
/// joints are.
///
/// Complexity O(#joints) per frame. Deterministic.

#include <string>
#include <vector>

#include <Eigen/Core>

#include "tbsp/cloth/skeleton.h"

namespace tbsp {

/// \brief Parses a joint map "model=clip,model=clip,…" (spaces ignored) against the two joint
/// name lists. Returns, per model joint, the clip joint index or -1.
/// \throws InvalidInput naming the entry and the fix: an entry without '=', an empty name, a name
/// that is in neither list (with the names each side has), a model joint mapped twice, a clip
/// joint used twice, a model root left unmapped, an empty map.
std::vector<int> parse_joint_map(const std::string& spec, const std::vector<std::string>& model_joints,
                                 const std::vector<std::string>& clip_joints);

class PoseRetargeter {
public:
  /// \param model the skeleton to drive (rest pose = the bind pose).
  /// \param source per model joint, the clip joint index or -1 (parse_joint_map); every root mapped.
  /// \param clip_first #clip joints by 3: the clip's joint positions at the first frame driven
  ///        (the root's motion is taken relative to it; ρ is measured on it).
  /// \throws InvalidInput for sizes that do not match, an unmapped root, no mapped bone, or a
  ///         source index out of range.
  PoseRetargeter(const Skeleton& model, std::vector<int> source, const Eigen::MatrixX3d& clip_first);

  /// Global joint transforms of the model for one clip frame (#clip joints by 3 positions).
  SkeletonPose retarget(const Eigen::MatrixX3d& clip_positions) const;

  /// ρ: model length units per clip length unit.
  double scale() const { return rho_; }

private:
  Skeleton model_;
  std::vector<int> source_;
  std::vector<std::vector<int>> targets_;  ///< per model joint: its nearest mapped descendants
  Eigen::MatrixX3d first_;
  double rho_ = 1;
};

}  // namespace tbsp
