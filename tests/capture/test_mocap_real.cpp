// Real mocap files from ../shared/data parse to their documented counts (capture/MANIFEST.md).
#include <gtest/gtest.h>

#include "test_util.h"
#include "tbsp/core/error.h"
#include "tbsp/io/mocap_io.h"

using namespace tbsp;

TEST(MocapReal, TrcGait2354) {
  const std::string f = test::shared("capture/LecolLeng__BipedWalkingCode/subject01_walk1.trc");
  TBSP_REQUIRE_FILE(f);
  const MarkerTrajectories m = read_trc(f);
  EXPECT_EQ(m.numMarkers(), 41);
  EXPECT_EQ(m.numFrames(), 151);
  EXPECT_DOUBLE_EQ(m.frame_rate, 60);
  EXPECT_EQ(m.units, "mm");
  EXPECT_EQ(m.names[0], "R.ASIS");
  EXPECT_EQ(m.markerIndex("V.Sacral"), 2);
  EXPECT_NEAR(m.position(0, 0).x(), 617.24762, 1e-9);
  // Y up: the pelvis is about 1 m above the floor.
  EXPECT_GT(m.position(0, 0).y(), 900);
}

TEST(MocapReal, C3dFilesFromFourVendors) {
  struct C { const char* file; int markers, frames, first; double rate; int analog; };
  const C cases[] = {{"capture/surenkum__c3d_to_xyz/01_01.c3d", 42, 2751, 40, 120, 0},
                     {"capture/pyomeca__ezc3d/test/c3dFiles/Vicon.c3d", 51, 580, -1, 100, 760},
                     {"capture/pyomeca__ezc3d/test/c3dFiles/Qualisys.c3d", 55, 340, 705, 200, 690},
                     {"capture/pyomeca__ezc3d/test/c3dFiles/Optotrak.c3d", 54, 29, -1, 30, -1}};
  for (const C& c : cases) {
    const std::string f = test::shared(c.file);
    TBSP_REQUIRE_FILE(f);
    // Optotrak.c3d declares 1149 frames but its data section holds 29 complete frames: strict
    // reading refuses it, allow_truncated reads what is there.
    const bool cut = std::string(c.file).find("Optotrak") != std::string::npos;
    if (cut) {
      try {
        read_c3d(f);
        ADD_FAILURE() << "truncated C3D accepted";
      } catch (const FileError& e) {
        EXPECT_NE(std::string(e.what()).find("truncated"), std::string::npos) << e.what();
        EXPECT_NE(std::string(e.what()).find("1149 frames"), std::string::npos) << e.what();
      }
    }
    const MarkerTrajectories m = read_c3d(f, cut);
    EXPECT_EQ(m.numMarkers(), c.markers) << c.file;
    EXPECT_EQ(m.numFrames(), c.frames) << c.file;
    if (c.first >= 0) { EXPECT_EQ(m.first_frame, c.first) << c.file; }
    EXPECT_NEAR(m.frame_rate, c.rate, 1e-3) << c.file;
    if (c.analog >= 0) { EXPECT_EQ(m.analog_per_frame, c.analog) << c.file; }
    int valid = 0;
    for (int k = 0; k < m.numMarkers(); ++k) valid += m.valid(0, k);
    std::printf("  %s: %d markers, %d frames from %d at %.0f Hz, units '%s', %d valid at frame 1, first label '%s'\n", c.file,
                m.numMarkers(), m.numFrames(), m.first_frame, m.frame_rate, m.units.c_str(), valid, m.names[0].c_str());
    EXPECT_GT(valid, 0) << c.file;
  }
  const MarkerTrajectories cmu = read_c3d(test::shared("capture/surenkum__c3d_to_xyz/01_01.c3d"));
  int valid = 0;
  for (int k = 0; k < cmu.numMarkers(); ++k) valid += cmu.valid(0, k);
  EXPECT_EQ(valid, 41);  // manifest: 41 of 42 valid at frame 1
  EXPECT_EQ(cmu.names[0], "LBWT");
  EXPECT_EQ(cmu.units, "mm");
}

TEST(MocapReal, BvhFilesParseAndBonesStayRigid) {
  struct B { const char* file; int joints, frames; double fps; };
  const B cases[] = {{"capture/dopomoc__BVH/01_01.bvh", 43, 2752, 120},
                     {"capture/dopomoc__BVH/02_05.bvh", -1, 1855, 120},
                     {"capture/dopomoc__Skinning/skeleton_motion_jump.bvh", 35, 148, -1},
                     {"capture/BandaiNamcoResearchInc__Bandai-Namco-Research-Motiondataset/dataset/Bandai-Namco-Research-Motiondataset-1/data/dataset-1_walk_normal_001.bvh", 22, 195, 30},
                     {"capture/20tab__bvh-python/tests/test_freebvh.bvh", -1, 69, 30},
                     {"capture/20tab__bvh-python/tests/test_mocapbank.bvh", 19, 455, -1}};  // mocapbank: 1 ROOT + 18 JOINT
  for (const B& c : cases) {
    const std::string f = test::shared(c.file);
    TBSP_REQUIRE_FILE(f);
    const BvhMotion m = read_bvh(f);
    if (c.joints > 0) { EXPECT_EQ(m.numJoints(), c.joints) << c.file; }
    EXPECT_EQ(m.numFrames(), c.frames) << c.file;
    if (c.fps > 0) { EXPECT_NEAR(1.0 / m.frame_time, c.fps, 0.5) << c.file; }
    // Forward kinematics: every bone keeps its rest length in every frame (sampled).
    const auto rest = m.jointPositions(0);
    double worst = 0;
    for (int fr = 0; fr < m.numFrames(); fr += std::max(1, m.numFrames() / 50)) {
      const auto P = m.jointPositions(fr);
      for (std::size_t j = 0; j < m.joints.size(); ++j) {
        const int p = m.joints[j].parent;
        if (p < 0) continue;
        bool translated = false;
        for (auto ch : m.joints[j].channels) translated |= ch <= BvhJoint::Zposition;
        if (translated) continue;  // bones with translation channels may stretch
        const double L = m.joints[j].offset.norm();
        worst = std::max(worst, std::abs((P.row(j) - P.row(p)).norm() - L) / std::max(L, 1e-9));
      }
    }
    EXPECT_LT(worst, 1e-9) << c.file;
    std::printf("  %s: %d joints (+%zu end sites), %d frames at %.1f fps, %d channels\n", c.file, m.numJoints(),
                m.joints.size() - m.numJoints(), m.numFrames(), 1.0 / m.frame_time, m.numChannels());
  }
}
