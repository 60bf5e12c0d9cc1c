#include "tbsp/cloth/animatable_model.h"

#include <cmath>
#include <string>

#include "tbsp/core/error.h"

namespace tbsp {

void AnimatableModel::validate(const char* where) const {
  const std::string w = std::string("[") + where + "] ";
  const Eigen::Index n = mesh.V.rows();
  if (n == 0 || mesh.F.rows() == 0) throw InvalidInput(w + "the model has no mesh");
  if (!mesh.V.allFinite()) throw InvalidInput(w + "the mesh has non-finite vertex coordinates");
  if (mesh.F.minCoeff() < 0 || mesh.F.maxCoeff() >= n) throw InvalidInput(w + "a face index is out of range");
  validate_skeleton(skeleton, where);
  if (weights.rows() != n || weights.cols() != skeleton.numJoints())
    throw InvalidInput(w + "skinning weights are " + std::to_string(weights.rows()) + " x " + std::to_string(weights.cols()) +
                       ", expected #vertices (" + std::to_string(n) + ") x #joints (" + std::to_string(skeleton.numJoints()) + ")");
  for (Eigen::Index i = 0; i < n; ++i) {
    double sum = 0;
    for (SkinningWeights::InnerIterator it(weights, i); it; ++it) {
      if (!(it.value() >= 0) || !std::isfinite(it.value())) throw InvalidInput(w + "vertex " + std::to_string(i) + " has a negative or non-finite weight");
      sum += it.value();
    }
    if (std::abs(sum - 1) > 1e-6)
      throw InvalidInput(w + "the weights of vertex " + std::to_string(i) + " sum to " + std::to_string(sum) + ", not 1");
  }
  if (clothness.size() != n) throw InvalidInput(w + "clothness has " + std::to_string(clothness.size()) + " values for " + std::to_string(n) + " vertices");
  for (Eigen::Index i = 0; i < n; ++i)
    if (!(clothness(i) >= 0 && clothness(i) <= 1)) throw InvalidInput(w + "vertex " + std::to_string(i) + " has clothness outside [0, 1]");
  if (materials.empty()) throw InvalidInput(w + "no cloth material (need one per region)");
  if (region.size() && region.size() != n) throw InvalidInput(w + "region has " + std::to_string(region.size()) + " labels for " + std::to_string(n) + " vertices");
  if (region.size() && (region.minCoeff() < 0 || region.maxCoeff() >= int(materials.size())))
    throw InvalidInput(w + "a region label has no material (labels 0.." + std::to_string(materials.size() - 1) + ")");
  for (const auto& m : materials)
    if (!(m.d_n >= 0) || !(m.d_t >= 0) || !(m.k_bend >= 0 && m.k_bend <= 1)) throw InvalidInput(w + "a material is out of range (d_n, d_t ≥ 0, k_bend in [0, 1])");
  for (const auto& p : proxies)
    if (p.bone.joint < 0 || p.bone.joint >= skeleton.numJoints() || !p.cone.a.allFinite() || !p.cone.b.allFinite() || !(p.cone.ra >= 0) ||
        !(p.cone.rb >= 0))
      throw InvalidInput(w + "a collision proxy has a bad joint index or cone");
}

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
