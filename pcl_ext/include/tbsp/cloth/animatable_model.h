#pragma once
/// \file animatable_model.h
/// \brief The animatable performance model of thesis §10.6: a template with a skeleton,
/// skinning weights, clothness, cloth regions with their materials and collision proxies. New
/// poses: vertices with δ = 0 follow dual-quaternion skinning, δ = 1 the PBD simulation, the
/// others the simulation pulled towards the skinned position with stiffness 1 − δ.
///
/// Saved and loaded as one file by the plugins library (`tbsp/plugins/cloth_model_json.h`).

#include <vector>

#include "tbsp/cloth/collision_proxies.h"
#include "tbsp/cloth/pbd_cloth_simulator.h"
#include "tbsp/cloth/skeleton.h"
#include "tbsp/mesh/tri_mesh.h"

namespace tbsp {

struct AnimatableModel {
  TriMesh mesh;                          ///< the template in the skeleton's rest pose
  Skeleton skeleton;
  SkinningWeights weights;               ///< #V by #joints
  Eigen::VectorXd clothness;             ///< δ per vertex, [0, 1]
  Eigen::VectorXi region;                ///< cloth region per vertex (0..k−1); empty = all 0
  std::vector<ClothMaterial> materials;  ///< one per region (at least one)
  std::vector<CollisionProxy> proxies;   ///< in the rest pose
  PbdSettings settings;                  ///< the settings the materials were estimated for

  /// \throws InvalidInput naming the first inconsistency (sizes, ranges, indices, non-finite
  /// values) and how to fix it.
  void validate(const char* where = "tbsp::AnimatableModel") const;
};

/// \brief Plays an AnimatableModel: skinning + simulation, one pose at a time.
class ModelAnimator {
public:
  /// \throws InvalidInput when the model is not valid.
  explicit ModelAnimator(const AnimatableModel& model);
  /// \brief Starts at `pose` (global joint transforms): the cloth starts at the skinned shape and
  /// settles for `settle_frames` frames in that pose. Returns the first frame.
  const Eigen::MatrixX3d& start(const SkeletonPose& pose, int settle_frames = 40);
  /// \brief Starts from a known state at `pose`: simulated vertices (δ > 0) at `positions` with
  /// `velocities` (m/s), kinematic ones at their skinned position; no settling. Returns it.
  /// \throws InvalidInput on size mismatches or non-finite values.
  const Eigen::MatrixX3d& startFrom(const SkeletonPose& pose, const Eigen::MatrixX3d& positions, const Eigen::MatrixX3d& velocities);
  /// \brief The next frame at `pose`. \throws InvalidInput before start() or on a pose size mismatch.
  const Eigen::MatrixX3d& step(const SkeletonPose& pose);
  const Eigen::MatrixX3d& positions() const { return V_; }
  const PbdClothSimulator& simulator() const { return sim_; }

private:
  void posed(const SkeletonPose& pose, Eigen::MatrixX3d& skinned, std::vector<RoundCone>& cones) const;
  const AnimatableModel& model_;
  PbdClothSimulator sim_;
  Eigen::MatrixX3d V_;
  bool started_ = false;
};

}  // namespace tbsp
