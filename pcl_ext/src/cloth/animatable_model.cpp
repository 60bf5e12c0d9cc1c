#include "tbsp/cloth/animatable_model.h"

#include <cmath>
#include <string>

#include "tbsp/core/error.h"

namespace tbsp {

ModelAnimator::ModelAnimator(const AnimatableModel& model) : model_(model) {
  model.validate("tbsp::ModelAnimator");
  sim_.setMesh(model.mesh.V, model.mesh.F);
  sim_.setSettings(model.settings);
  for (std::size_t r = 0; r < model.materials.size(); ++r) sim_.setMaterial(model.materials[r], int(r));
  if (model.region.size()) sim_.setRegions(model.region);
  sim_.setClothness(model.clothness);
}

void ModelAnimator::posed(const SkeletonPose& pose, Eigen::MatrixX3d& skinned, std::vector<RoundCone>& cones) const {
  const auto T = skinning_transforms(model_.skeleton, pose);
  skinned = dual_quaternion_skinning(model_.mesh.V, model_.weights, T);
  cones = posed_proxies(model_.proxies, T);
}

const Eigen::MatrixX3d& ModelAnimator::start(const SkeletonPose& pose, int settle_frames) {
  if (settle_frames < 0) throw InvalidInput("[tbsp::ModelAnimator::start] settle_frames must be ≥ 0");
  Eigen::MatrixX3d skinned;
  std::vector<RoundCone> cones;
  posed(pose, skinned, cones);
  sim_.reset(skinned);
  for (int i = 0; i < settle_frames; ++i) sim_.step(skinned, cones);
  V_ = sim_.positions();
  started_ = true;
  return V_;
}

const Eigen::MatrixX3d& ModelAnimator::startFrom(const SkeletonPose& pose, const Eigen::MatrixX3d& positions, const Eigen::MatrixX3d& velocities) {
  if (positions.rows() != model_.mesh.V.rows())
    throw InvalidInput("[tbsp::ModelAnimator::startFrom] " + std::to_string(positions.rows()) + " positions for " + std::to_string(model_.mesh.V.rows()) +
                       " vertices");
  Eigen::MatrixX3d skinned;
  std::vector<RoundCone> cones;
  posed(pose, skinned, cones);
  Eigen::MatrixX3d P = skinned;
  for (Eigen::Index i = 0; i < P.rows(); ++i)
    if (model_.clothness(i) > 0) P.row(i) = positions.row(i);
  sim_.reset(P, velocities, skinned, cones);
  V_ = sim_.positions();
  started_ = true;
  return V_;
}

const Eigen::MatrixX3d& ModelAnimator::step(const SkeletonPose& pose) {
  if (!started_) throw InvalidInput("[tbsp::ModelAnimator::step] call start() first");
  Eigen::MatrixX3d skinned;
  std::vector<RoundCone> cones;
  posed(pose, skinned, cones);
  sim_.step(skinned, cones);
  V_ = sim_.positions();
  return V_;
}

}  // namespace tbsp
