#pragma once
/// \file bvh_skeleton.h
/// \brief A BVH file as a tbsp::Skeleton (cloth, skinning) and its frames as skeleton poses.

#include <string>
#include <vector>

#include "tbsp/cloth/skeleton.h"
#include "tbsp/io/mocap_io.h"

namespace tbsp {

/// \brief The skeleton of a BVH motion: one joint per BVH joint (End Sites included, named
/// "<parent>_End"), parents as in the file. The rest pose is the BVH's zero pose (offsets only,
/// `rest_frame` = -1, default) or the pose of frame `rest_frame`. Translations are multiplied by
/// `scale` (e.g. 0.0254 for inches to metres; CMU clips are in units of ~0.056 m). O(#joints).
/// \throws InvalidInput for a motion without joints, a rest frame out of range or scale ≤ 0.
Skeleton skeleton_from_bvh(const BvhMotion& motion, int rest_frame = -1, double scale = 1.0);

/// \brief Global joint transforms of frame `frame`, translations scaled by `scale`, in the joint
/// order of skeleton_from_bvh. \throws InvalidInput for a frame out of range.
SkeletonPose bvh_pose(const BvhMotion& motion, int frame, double scale = 1.0);

/// \brief Checks that the motion has every joint in `names` (e.g. the joints a model's skinning
/// weights or proxies use). \throws InvalidInput naming the file label `what`, the missing joints
/// and the joints the motion has.
void require_bvh_joints(const BvhMotion& motion, const std::vector<std::string>& names, const std::string& what);

}  // namespace tbsp
