// `tbsp synth-studio` and `tbsp replay` end to end.
#include <gtest/gtest.h>

#include <sys/wait.h>

#include <fstream>
#include <sstream>

#include "cli_util.h"
#include "test_util.h"
#include "tbsp/io/studio.h"

using namespace tbsp;

namespace {
using test::CliResult;
using test::run_cli;
}  // namespace

TEST(CliCapture, SynthStudioThenReplayAndMissingFrames) {
  const auto dir = test::temp_dir("cli_studio");
  const std::string st = (dir / "studio").string();
  CliResult r = run_cli("synth-studio -q --out " + st + " --cameras 3 --width 200 --height 160 --frames 3 --range-scans --detail 0", dir);
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_TRUE(std::filesystem::exists(st + "/scans/cam1/0002.pcd"));
  r = run_cli("replay " + st, dir);
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_NE(r.out.find("3 cameras"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("3 frames streamed"), std::string::npos) << r.out;
  // A missing frame: replay lists it by name and exits 2.
  std::filesystem::remove(st + "/images/cam2/0001.png");
  r = run_cli("replay " + st + "/studio.yaml", dir);
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.out.find("images/cam2/0001.png"), std::string::npos) << r.out;
  // Bad options are refused before anything is written.
  r = run_cli("synth-studio -q --out " + (dir / "bad").string() + " --cameras 0", dir);
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.err.find("cameras must be"), std::string::npos) << r.err;
}

TEST(CliCapture, ReplayRecordingsToClouds) {
  const auto dir = test::temp_dir("cli_replay");
  const std::string oni = test::shared("capture/3DJ__3DJ_Test/bin/data/test.oni");
  TBSP_REQUIRE_FILE(oni);
  CliResult r = run_cli("replay " + oni + " --out " + (dir / "oni").string() + " --last 2", dir);
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_TRUE(std::filesystem::exists(dir / "oni" / "cloud_0002.pcd"));
  EXPECT_FALSE(std::filesystem::exists(dir / "oni" / "cloud_0003.pcd"));
  EXPECT_NE(r.out.find("12 frames"), std::string::npos) << r.out;
  // A folder of 16-bit depth images needs intrinsics.
  const std::string depth = test::shared("capture/gaoxiang12__slambook2/ch12/dense_RGBD/data/depth");
  r = run_cli("replay " + depth, dir);
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.err.find("--intrinsics"), std::string::npos) << r.err;
  r = run_cli("replay " + depth + " --intrinsics 481.2,-480,319.5,239.5 --depth-scale 0.0002 --format ply --out " + (dir / "d").string(), dir);
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_TRUE(std::filesystem::exists(dir / "d" / "cloud_0004.ply"));
  // malformed intrinsics are named as such; a frame range that selects nothing is an error, not
  // "0 frames converted" with exit 0 (found by hand 2026-12-06)
  r = run_cli("replay " + depth + " --intrinsics 481.2,480,319.5", dir);
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.err.find("--intrinsics '481.2,480,319.5': expected four numbers"), std::string::npos) << r.err;
  r = run_cli("replay " + depth + " --intrinsics 481.2,-480,319.5,239.5 --first 3 --last 1", dir);
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.err.find("--first 3 is after --last 1"), std::string::npos) << r.err;
  r = run_cli("replay " + depth + " --intrinsics 481.2,-480,319.5,239.5 --first 500", dir);
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.err.find("--first 500 is beyond the 5 depth images"), std::string::npos) << r.err;
  // Empty recording: clear error, exit 2.
  r = run_cli("replay " + test::shared("capture/bloyot__Kinect-Gesture-Recognition/recording.oni"), dir);
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.err.find("recording.oni"), std::string::npos) << r.err;
}
