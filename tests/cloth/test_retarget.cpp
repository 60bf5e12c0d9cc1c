// PoseRetargeter and parse_joint_map: a clip driving its own skeleton is reproduced exactly; a
// Bandai-Namco clip (other joint names, lengths, local axes) drives the CMU skeleton with every
// singly-mapped bone along the clip's bone; malformed maps are clear errors.
#include <gtest/gtest.h>

#include <cmath>
#include <string>

#include "test_util.h"
#include "tbsp/cloth/retarget.h"
#include "tbsp/core/error.h"
#include "tbsp/io/bvh_skeleton.h"
#include "tbsp/io/mocap_io.h"

using namespace tbsp;

namespace {

const char* kCmu = "capture/dopomoc__BVH/02_05.bvh";
const char* kWalk =
    "capture/BandaiNamcoResearchInc__Bandai-Namco-Research-Motiondataset/dataset/Bandai-Namco-Research-Motiondataset-1/data/"
    "dataset-1_walk_normal_001.bvh";

}  // namespace

// The joint map of docs/cloth.md: the CMU ("Daz-friendly") skeleton driven by a Bandai-Namco clip.
const char* kCmuFromBandai =
    "hip=Hips, abdomen=Spine, chest=Chest, neck=Neck, head=Head, lCollar=Shoulder_L, lShldr=UpperArm_L, lForeArm=LowerArm_L, "
    "lHand=Hand_L, rCollar=Shoulder_R, rShldr=UpperArm_R, rForeArm=LowerArm_R, rHand=Hand_R, lThigh=UpperLeg_L, lShin=LowerLeg_L, "
    "lFoot=Foot_L, rThigh=UpperLeg_R, rShin=LowerLeg_R, rFoot=Foot_R";

TEST(Retarget, AClipOnItsOwnSkeletonIsReproduced) {
  TBSP_REQUIRE_FILE(test::shared(kCmu));
  const BvhMotion clip = read_bvh(test::shared(kCmu));
  const Skeleton model = skeleton_from_bvh(clip, 0, 0.01);
  std::vector<int> identity(model.names.size());
  for (std::size_t j = 0; j < identity.size(); ++j) identity[j] = int(j);
  const PoseRetargeter rt(model, identity, joint_positions(bvh_pose(clip, 0, 0.01)));
  EXPECT_NEAR(rt.scale(), 1.0, 1e-12);
  for (int f : {0, 200, 900, 1800}) {
    const Eigen::MatrixX3d truth = joint_positions(bvh_pose(clip, f, 0.01));
    const Eigen::MatrixX3d got = joint_positions(rt.retarget(truth));
    EXPECT_LT((got - truth).rowwise().norm().maxCoeff(), 1e-9) << "frame " << f;
  }
}

TEST(Retarget, BandaiWalkDrivesTheCmuSkeleton) {
  TBSP_REQUIRE_FILE(test::shared(kCmu));
  TBSP_REQUIRE_FILE(test::shared(kWalk));
  const Skeleton model = skeleton_from_bvh(read_bvh(test::shared(kCmu)), 0, 0.01);
  const BvhMotion walk = read_bvh(test::shared(kWalk));
  const Skeleton clip = skeleton_from_bvh(walk, -1, 0.01);
  const std::vector<int> src = parse_joint_map(kCmuFromBandai, model.names, clip.names);
  const PoseRetargeter rt(model, src, joint_positions(bvh_pose(walk, 0, 0.01)));
  double worst_angle = 0, worst_length = 0;
  for (int f = 0; f < walk.numFrames(); f += 5) {
    const Eigen::MatrixX3d Q = joint_positions(bvh_pose(walk, f, 0.01));
    const Eigen::MatrixX3d X = joint_positions(rt.retarget(Q));
    ASSERT_TRUE(X.allFinite());
    // bones of a single mapped child (shin: thigh -> knee, forearm, ...) follow the clip's bone
    for (const auto& [m, d] : {std::pair<const char*, const char*>{"lThigh", "lShin"}, {"lShin", "lFoot"}, {"rThigh", "rShin"}, {"rShin", "rFoot"},
                               {"lShldr", "lForeArm"}, {"lForeArm", "lHand"}, {"rShldr", "rForeArm"}, {"rForeArm", "rHand"}}) {
      const int j = model.jointIndex(m), c = model.jointIndex(d);
      const Eigen::Vector3d a = (X.row(c) - X.row(j)).transpose(), b = (Q.row(src[std::size_t(c)]) - Q.row(src[std::size_t(j)])).transpose();
      worst_angle = std::max(worst_angle, std::acos(std::clamp(a.normalized().dot(b.normalized()), -1.0, 1.0)));
      const double rest = (model.restPosition(c) - model.restPosition(j)).norm();
      worst_length = std::max(worst_length, std::abs(a.norm() - rest));
    }
  }
  const Eigen::MatrixX3d last = joint_positions(rt.retarget(joint_positions(bvh_pose(walk, walk.numFrames() - 1, 0.01))));
  const int hip = model.jointIndex("hip");
  const double travel = (last.row(hip) - model.restPosition(hip).transpose()).norm();
  std::printf("Bandai walk on the CMU skeleton: rho %.3f, worst single-bone angle %.2e rad, worst bone length change %.2e m, hip travel %.2f m\n",
              rt.scale(), worst_angle, worst_length, travel);
  EXPECT_LT(worst_angle, 1e-6);
  EXPECT_LT(worst_length, 1e-9);  // the model's bone lengths are kept
  EXPECT_GT(travel, 1.0);         // 195 frames of walking at 30 fps
  EXPECT_GT(rt.scale(), 0.5);
  EXPECT_LT(rt.scale(), 2.0);
}

TEST(Retarget, BadJointMapsAreClearErrors) {
  const std::vector<std::string> model = {"hip", "thigh", "knee"}, clip = {"Hips", "UpperLeg", "LowerLeg"};
  auto message = [&](const std::string& spec) -> std::string {
    try {
      parse_joint_map(spec, model, clip);
    } catch (const InvalidInput& e) {
      return e.what();
    }
    return "";
  };
  EXPECT_NE(message("").find("empty"), std::string::npos);
  EXPECT_NE(message("hip=Hips,").find("entry 2"), std::string::npos);
  EXPECT_NE(message("hip=Hips,,thigh=UpperLeg").find("empty"), std::string::npos);
  EXPECT_NE(message("hip").find("model=clip"), std::string::npos);
  EXPECT_NE(message("hip=Hips=x").find("model=clip"), std::string::npos);
  EXPECT_NE(message("=Hips").find("empty"), std::string::npos);
  EXPECT_NE(message("hip=Hips,foot=LowerLeg").find("no joint 'foot'"), std::string::npos);
  EXPECT_NE(message("hip=Hips,foot=LowerLeg").find("hip, thigh, knee"), std::string::npos);  // names listed
  EXPECT_NE(message("hip=Pelvis").find("clip has no joint 'Pelvis'"), std::string::npos);
  EXPECT_NE(message("hip=Hips,hip=UpperLeg").find("mapped twice"), std::string::npos);
  EXPECT_NE(message("hip=Hips,thigh=Hips").find("used twice"), std::string::npos);
  const std::vector<int> ok = parse_joint_map(" hip = Hips , knee=LowerLeg ", model, clip);
  EXPECT_EQ(ok, (std::vector<int>{0, -1, 2}));
  // the retargeter: an unmapped root, no bone
  Skeleton s;
  s.names = model;
  s.parents = {-1, 0, 1};
  for (int k = 0; k < 3; ++k) {
    Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
    T.translation() = Eigen::Vector3d(0, -0.4 * k, 0);
    s.rest.push_back(T);
  }
  const Eigen::MatrixX3d Q = Eigen::MatrixX3d::Random(3, 3);
  EXPECT_THROW(PoseRetargeter(s, {-1, 1, 2}, Q), InvalidInput);
  EXPECT_THROW(PoseRetargeter(s, {0, -1, -1}, Q), InvalidInput);  // no mapped bone
  EXPECT_THROW(PoseRetargeter(s, {0, 1}, Q), InvalidInput);       // size
  const PoseRetargeter rt(s, {0, -1, 2}, Q);
  EXPECT_THROW(rt.retarget(Q.topRows(2)), InvalidInput);
}
