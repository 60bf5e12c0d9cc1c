// Skeletons and poses from real BVH clips (CMU 01_01, 02_05) drive dual-quaternion skinning.
#include <gtest/gtest.h>

#include <filesystem>

#include "test_util.h"
#include "tbsp/cloth/skeleton.h"
#include "tbsp/core/error.h"
#include "tbsp/io/bvh_skeleton.h"

using namespace tbsp;

TEST(BvhSkeleton, PosesOfARealClipMoveSkinnedPointsWithTheirJoints) {
  const std::string path = std::string(TBSP_SHARED_DATA_DIR) + "/capture/dopomoc__BVH/02_05.bvh";
  TBSP_REQUIRE_FILE(path);
  const BvhMotion m = read_bvh(path);
  const double scale = 0.056444;  // CMU units to metres
  const Skeleton s = skeleton_from_bvh(m, -1, scale);
  ASSERT_EQ(s.numJoints(), int(m.joints.size()));
  const auto bones = skeleton_bones(s);
  EXPECT_GT(bones.size(), 20u);
  // a point rigidly attached to each joint follows the BVH joint positions of any frame
  for (int frame : {0, m.numFrames() / 2, m.numFrames() - 1}) {
    const SkeletonPose pose = bvh_pose(m, frame, scale);
    const auto T = skinning_transforms(s, pose);
    Eigen::MatrixX3d V(s.numJoints(), 3);
    std::vector<Eigen::Triplet<double>> t;
    for (int j = 0; j < s.numJoints(); ++j) {
      V.row(j) = s.restPosition(j).transpose();
      t.emplace_back(j, j, 1.0);
    }
    SkinningWeights W(s.numJoints(), s.numJoints());
    W.setFromTriplets(t.begin(), t.end());
    const Eigen::MatrixX3d P = dual_quaternion_skinning(V, W, T);
    const Eigen::MatrixX3d expect = m.jointPositions(frame) * scale;
    EXPECT_LT((P - expect).cwiseAbs().maxCoeff(), 1e-9) << "frame " << frame;
  }
}

TEST(BvhSkeleton, MissingJointsAndBadFramesAreClearErrors) {
  const std::string path = std::string(TBSP_SHARED_DATA_DIR) + "/capture/dopomoc__BVH/01_01.bvh";
  TBSP_REQUIRE_FILE(path);
  const BvhMotion m = read_bvh(path);
  EXPECT_NO_THROW(require_bvh_joints(m, {"lThigh", "rThigh"}, "01_01.bvh"));
  try {
    require_bvh_joints(m, {"lThigh", "Tail3"}, "01_01.bvh");
    FAIL();
  } catch (const InvalidInput& e) {
    EXPECT_NE(std::string(e.what()).find("Tail3"), std::string::npos);
    EXPECT_NE(std::string(e.what()).find("01_01.bvh"), std::string::npos);
  }
  EXPECT_THROW(skeleton_from_bvh(m, m.numFrames()), InvalidInput);
  EXPECT_THROW(bvh_pose(m, -1), InvalidInput);
  EXPECT_THROW(skeleton_from_bvh(BvhMotion{}), InvalidInput);
}
