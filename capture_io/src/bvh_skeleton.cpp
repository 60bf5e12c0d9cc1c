#include "tbsp/io/bvh_skeleton.h"

#include <cmath>

#include "tbsp/core/error.h"

namespace tbsp {

namespace {
SkeletonPose scaled(std::vector<Eigen::Isometry3d> G, double scale) {
  for (auto& g : G) g.translation() *= scale;
  return G;
}
}  // namespace

SkeletonPose bvh_pose(const BvhMotion& motion, int frame, double scale) {
  if (!(scale > 0) || !std::isfinite(scale)) throw InvalidInput("[tbsp::bvh_pose] scale must be > 0");
  return scaled(motion.globalTransforms(frame), scale);
}

Skeleton skeleton_from_bvh(const BvhMotion& motion, int rest_frame, double scale) {
  if (motion.joints.empty()) throw InvalidInput("[tbsp::skeleton_from_bvh] the motion has no joints");
  if (!(scale > 0) || !std::isfinite(scale)) throw InvalidInput("[tbsp::skeleton_from_bvh] scale must be > 0");
  if (rest_frame < -1 || rest_frame >= motion.numFrames())
    throw InvalidInput("[tbsp::skeleton_from_bvh] rest frame " + std::to_string(rest_frame) + " out of range [-1, " +
                       std::to_string(motion.numFrames()) + ")");
  Skeleton s;
  for (const auto& j : motion.joints) {
    s.names.push_back(j.name);
    s.parents.push_back(j.parent);
  }
  if (rest_frame >= 0) {
    s.rest = bvh_pose(motion, rest_frame, scale);
  } else {
    s.rest.resize(motion.joints.size());
    for (std::size_t i = 0; i < motion.joints.size(); ++i) {
      Eigen::Isometry3d L = Eigen::Isometry3d::Identity();
      L.translation() = motion.joints[i].offset * scale;
      const int p = motion.joints[i].parent;
      s.rest[i] = p >= 0 ? s.rest[std::size_t(p)] * L : L;
    }
  }
  validate_skeleton(s, "tbsp::skeleton_from_bvh");
  return s;
}

void require_bvh_joints(const BvhMotion& motion, const std::vector<std::string>& names, const std::string& what) {
  std::string missing;
  for (const auto& n : names) {
    bool found = false;
    for (const auto& j : motion.joints) found = found || j.name == n;
    if (!found) missing += (missing.empty() ? "" : ", ") + n;
  }
  if (missing.empty()) return;
  std::string have;
  for (const auto& j : motion.joints)
    if (!j.end_site) have += (have.empty() ? "" : ", ") + j.name;
  throw InvalidInput(what + ": the motion lacks joint(s) " + missing + " (it has: " + have +
                     "); retarget the clip to the model's skeleton or use a clip with the same joint names");
}

}  // namespace tbsp
