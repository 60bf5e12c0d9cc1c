#pragma once
// Shared fixtures of the cloth tests: a two-bone skeleton along +x and a tube around it.
#include <Eigen/Geometry>
#include <cmath>

#include "tbsp/cloth/skeleton.h"
#include "tbsp/mesh/primitives.h"

namespace cloth_test {

// joints: 0 root at x=0, 1 "elbow" at x=0.5, 2 end at x=1 (all on the tube axis).
inline tbsp::Skeleton two_bone_skeleton(double length = 1.0) {
  tbsp::Skeleton s;
  s.names = {"Root", "Elbow", "End"};
  s.parents = {-1, 0, 1};
  for (int j = 0; j < 3; ++j) {
    Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
    T.translation() = Eigen::Vector3d(0.5 * length * j, 0, 0);
    s.rest.push_back(T);
  }
  return s;
}

// A pose bending the elbow by `angle` (radians) about +z: the global transforms of all joints.
inline tbsp::SkeletonPose bend_elbow(const tbsp::Skeleton& s, double angle) {
  tbsp::SkeletonPose pose = s.rest;
  Eigen::Isometry3d R = Eigen::Isometry3d::Identity();
  R.translate(s.restPosition(1)).rotate(Eigen::AngleAxisd(angle, Eigen::Vector3d::UnitZ())).translate(-s.restPosition(1));
  pose[1] = R * s.rest[1];
  pose[2] = R * s.rest[2];
  return pose;
}

}  // namespace cloth_test
