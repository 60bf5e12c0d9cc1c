// The light part of tbsp::Skeleton (no solver, no ray casting): joint lookup, validation, bones,
// skinning transforms. Kept apart so the parser fuzzer and capture_io's BVH conversion link it
// without the weight solver.
#include <string>

#include "tbsp/cloth/skeleton.h"
#include "tbsp/core/error.h"

namespace tbsp {

int Skeleton::jointIndex(const std::string& name) const {
  for (std::size_t j = 0; j < names.size(); ++j)
    if (names[j] == name) return int(j);
  return -1;
}

void validate_skeleton(const Skeleton& s, const char* where) {
  const std::string w = std::string("[") + where + "] ";
  if (s.names.empty()) throw InvalidInput(w + "the skeleton has no joints");
  if (s.parents.size() != s.names.size() || s.rest.size() != s.names.size())
    throw InvalidInput(w + "names (" + std::to_string(s.names.size()) + "), parents (" + std::to_string(s.parents.size()) +
                       ") and rest transforms (" + std::to_string(s.rest.size()) + ") must have one entry per joint");
  for (int j = 0; j < s.numJoints(); ++j) {
    const int p = s.parents[std::size_t(j)];
    if (p < -1 || p >= j)
      throw InvalidInput(w + "joint " + std::to_string(j) + " ('" + s.names[std::size_t(j)] + "') has parent " +
                         std::to_string(p) + ": parents must precede their children (-1 for a root)");
    const Eigen::Matrix4d m = s.rest[std::size_t(j)].matrix();
    if (!m.allFinite()) throw InvalidInput(w + "joint '" + s.names[std::size_t(j)] + "' has a non-finite rest transform");
    const Eigen::Matrix3d r = m.topLeftCorner<3, 3>();
    if ((r.transpose() * r - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff() > 1e-6 || r.determinant() < 0)
      throw InvalidInput(w + "joint '" + s.names[std::size_t(j)] + "' has a rest transform that is not a rotation + translation");
  }
}

std::vector<Bone> skeleton_bones(const Skeleton& s, double min_length) {
  std::vector<Bone> bones;
  for (int c = 0; c < s.numJoints(); ++c) {
    const int p = s.parents[std::size_t(c)];
    if (p < 0) continue;
    if ((s.restPosition(c) - s.restPosition(p)).norm() < min_length) continue;
    bones.push_back({p, c});
  }
  return bones;
}

std::vector<Eigen::Isometry3d> skinning_transforms(const Skeleton& s, const SkeletonPose& pose) {
  if (pose.size() != s.rest.size())
    throw InvalidInput("[tbsp::skinning_transforms] the pose has " + std::to_string(pose.size()) +
                       " joint transforms, the skeleton " + std::to_string(s.rest.size()) + " joints");
  std::vector<Eigen::Isometry3d> T(pose.size());
  for (std::size_t j = 0; j < pose.size(); ++j) T[j] = pose[j] * s.rest[j].inverse();
  return T;
}

Eigen::MatrixX3d joint_positions(const SkeletonPose& pose) {
  Eigen::MatrixX3d X(Eigen::Index(pose.size()), 3);
  for (std::size_t j = 0; j < pose.size(); ++j) X.row(Eigen::Index(j)) = pose[j].translation().transpose();
  return X;
}

}  // namespace tbsp
