// Depth images and recordings from ../shared/data -> organized clouds.
#include <gtest/gtest.h>

#include <signal.h>

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <vector>

#include <Eigen/Geometry>
#include <opencv2/imgcodecs.hpp>
#include <pcl/io/pcd_io.h>

#include "test_util.h"
#include "tbsp/core/error.h"
#include "tbsp/io/depth_io.h"
#include "tbsp/mesh/point_search.h"

using namespace tbsp;

TEST(DepthReal, PclGrabberTiffMatchesTheGrabbersOwnCloud) {
  const std::string dir = test::shared("capture/PointCloudLibrary__pcl/test/grabber_sequences");
  const std::string stem = "frame_20121214T142255.814212";
  TBSP_REQUIRE_FILE(dir + "/tiff/" + stem + "_depth.tiff");
  const cv::Mat depth = read_depth_image(dir + "/tiff/" + stem + "_depth.tiff");
  ASSERT_EQ(depth.cols, 640);
  // Intrinsics from the sequence's XML: fx = fy = 525, (320, 240), z factor 0.001.
  const auto ours = depth_to_cloud(depth, DepthIntrinsics{525, 525, 320, 240}, 0.001);
  pcl::PointCloud<pcl::PointXYZRGBA> ref;
  ASSERT_EQ(pcl::io::loadPCDFile(dir + "/pcd/" + stem + ".pcd", ref), 0);
  ASSERT_EQ(ref.width, ours.width);
  ASSERT_EQ(ref.height, ours.height);
  int both = 0, mismatch_valid = 0;
  double worst = 0;
  for (std::size_t i = 0; i < ref.size(); ++i) {
    const bool a = std::isfinite(ours[i].z), b = std::isfinite(ref[i].z);
    mismatch_valid += a != b;
    if (!a || !b) continue;
    ++both;
    worst = std::max(worst, double((ours[i].getVector3fMap() - ref[i].getVector3fMap()).norm() / ref[i].z));
  }
  std::printf("  %d points in both, %d validity mismatches, worst relative difference %.2e\n", both, mismatch_valid, worst);
  EXPECT_GT(both, 100000);
  EXPECT_LT(mismatch_valid, ref.size() / 1000);
  EXPECT_LT(worst, 5e-3);  // same pixels, same depth; PCL's grabber uses (u - 319.5)-style centres
}

TEST(DepthReal, IclNuimFramesFuseWithTheirPoses) {
  const std::string dir = test::shared("capture/gaoxiang12__slambook2/ch12/dense_RGBD/data");
  TBSP_REQUIRE_FILE(dir + "/pose.txt");
  std::ifstream poses(dir + "/pose.txt");
  std::vector<Eigen::Isometry3d> T;
  for (int i = 0; i < 2; ++i) {
    double tx, ty, tz, qx, qy, qz, qw;
    poses >> tx >> ty >> tz >> qx >> qy >> qz >> qw;
    Eigen::Isometry3d t = Eigen::Isometry3d::Identity();
    t.linear() = Eigen::Quaterniond(qw, qx, qy, qz).normalized().toRotationMatrix();
    t.translation() = Eigen::Vector3d(tx, ty, tz);
    T.push_back(t);
  }
  // Frame 2 in world coordinates against frame 1 (all pixels): the overlapping part of the room
  // coincides. Negative control: the wrong sign of fy breaks it.
  auto quantile10 = [&](double fy) {
    const DepthIntrinsics K{481.2, fy, 319.5, 239.5};
    std::vector<Eigen::MatrixX3d> world;
    for (int i = 0; i < 2; ++i) {
      const cv::Mat d = read_depth_image(dir + "/depth/" + std::to_string(i + 1) + ".png");
      const auto c = depth_to_cloud(d, K, 1.0 / 5000.0);
      std::vector<Eigen::Vector3d> pts;
      for (std::size_t k = 0; k < c.size(); k += (i == 0 ? 1 : 37))
        if (std::isfinite(c[k].z)) pts.push_back(T[i] * c[k].getVector3fMap().cast<double>());
      Eigen::MatrixX3d M(pts.size(), 3);
      for (std::size_t k = 0; k < pts.size(); ++k) M.row(k) = pts[k].transpose();
      world.push_back(M);
    }
    PointSearch search(world[0]);
    std::vector<double> dist;
    for (Eigen::Index k = 0; k < world[1].rows(); ++k) {
      double d2 = 0;
      search.nearest(world[1].row(k).transpose(), &d2);
      dist.push_back(std::sqrt(d2));
    }
    std::sort(dist.begin(), dist.end());
    return dist[dist.size() / 10];
  };
  const double good = quantile10(-480.0), flipped = quantile10(480.0);  // ICL-NUIM: negative fy
  std::printf("  frame 2 -> frame 1 (world): 10%% of points within %.4f m; with fy flipped %.4f m\n", good, flipped);
  EXPECT_LT(good, 0.02);  // the views are ~45 degrees apart and overlap little: the 10% quantile lies in the overlap
  EXPECT_GT(flipped, 5 * good);
}

TEST(OniReal, RecordingReplaysToClouds) {
  const std::string f = test::shared("capture/3DJ__3DJ_Test/bin/data/test.oni");
  TBSP_REQUIRE_FILE(f);
  if (!OniReader::available()) GTEST_SKIP() << "built without OpenNI2";
  OniReader r(f);
  const OniInfo& in = r.info();
  EXPECT_TRUE(in.has_depth);
  EXPECT_EQ(in.depth_frames, 12);
  EXPECT_EQ(in.depth_width, 640);
  EXPECT_EQ(in.depth_height, 480);
  EXPECT_EQ(in.fps, 30);
  EXPECT_NEAR(in.depth_intrinsics.fx, 575, 15);  // Kinect v1 class: ~58 deg horizontal field of view
  OniFrame fr;
  int n = 0;
  while (r.next(fr)) {
    EXPECT_EQ(fr.index, n);
    ASSERT_EQ(fr.depth.type(), CV_16UC1);
    const auto cloud = depth_to_cloud(fr.depth, in.depth_intrinsics, in.depth_scale);
    std::vector<float> z;
    for (const auto& p : cloud) if (std::isfinite(p.z)) z.push_back(p.z);
    ASSERT_GT(z.size(), cloud.size() / 3) << "frame " << n;
    std::nth_element(z.begin(), z.begin() + z.size() / 2, z.end());
    EXPECT_GT(z[z.size() / 2], 0.5f);
    EXPECT_LT(z[z.size() / 2], 8.0f);
    if (in.has_color && n < in.color_frames) {
      EXPECT_EQ(fr.color.type(), CV_8UC3);
      EXPECT_EQ(fr.color.cols, 640);
    }
    if (n == 0) std::printf("  frame 0: %zu valid depth points, median depth %.2f m, colour %s\n", z.size(), z[z.size() / 2], fr.color.empty() ? "no" : "yes");
    ++n;
  }
  EXPECT_EQ(n, 12);
}

TEST(OniReal, EmptyAndMissingRecordingsGiveClearErrors) {
  if (!OniReader::available()) GTEST_SKIP() << "built without OpenNI2";
  const std::string empty = test::shared("capture/bloyot__Kinect-Gesture-Recognition/recording.oni");
  TBSP_REQUIRE_FILE(empty);
  try {
    OniReader r(empty);
    FAIL() << "an .oni with 0 frames was accepted";
  } catch (const FileError& e) {
    EXPECT_NE(std::string(e.what()).find("recording.oni"), std::string::npos) << e.what();
  }
  EXPECT_THROW(OniReader("/nonexistent/x.oni"), FileError);
  const auto dir = test::temp_dir("oni");
  std::ofstream(dir / "garbage.oni") << "this is not an oni file";
  EXPECT_THROW(OniReader((dir / "garbage.oni").string()), FileError);
  // Truncated real recording: header intact, data cut.
  std::ifstream in(test::shared("capture/3DJ__3DJ_Test/bin/data/test.oni"), std::ios::binary);
  std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  std::ofstream(dir / "cut.oni", std::ios::binary) << bytes.substr(0, 4000);
  try {
    OniReader r((dir / "cut.oni").string());
    OniFrame f;
    while (r.next(f)) {}
  } catch (const FileError& e) {
    EXPECT_NE(std::string(e.what()).find("cut.oni"), std::string::npos);
  }
}

namespace {
// pids of this process's children (from /proc/self/task/*/children)
std::vector<int> child_pids() {
  std::vector<int> out;
  for (const auto& t : std::filesystem::directory_iterator("/proc/self/task")) {
    std::ifstream in(t.path() / "children");
    int pid;
    while (in >> pid) out.push_back(pid);
  }
  return out;
}
}  // namespace

// Fuzz finding: 4 bytes changed inside a JPEG colour frame of test.oni (an APP0 marker with length
// 0xFFFF in the middle of the entropy-coded data) make OpenNI2's JPEG source manager skip past
// its buffer: libjpeg then reads whatever follows it on the player thread and segfaults in about
// 9 of 10 replays (measured 55 of 60; the rest decode garbage). The driver runs in a child
// process, so this process survives every replay, and a crash is a FileError naming the file and
// the frame.
TEST(OniReal, CorruptColourFrameIsAnErrorNotACrash) {
  const std::string f = test::shared("capture/3DJ__3DJ_Test/bin/data/test.oni");
  TBSP_REQUIRE_FILE(f);
  if (!OniReader::available()) GTEST_SKIP() << "built without OpenNI2";
  std::ifstream in(f, std::ios::binary);
  std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  const std::size_t soi = bytes.find("\xff\xd8\xff");
  ASSERT_NE(soi, std::string::npos);
  bytes.replace(soi + 20000, 4, "\xff\xe0\xff\xff");
  const auto dir = test::temp_dir("oni_corrupt");
  const std::string bad = (dir / "corrupt.oni").string();
  std::ofstream(bad, std::ios::binary) << bytes;
  int crashes = 0;
  for (int attempt = 0; attempt < 4; ++attempt) {
    try {
      OniReader r(bad);
      OniFrame fr;
      int frames = 0;
      while (r.next(fr)) ++frames;
      EXPECT_EQ(frames, 12);  // the garbage was decoded: every frame still comes out
    } catch (const FileError& e) {
      ++crashes;
      const std::string msg = e.what();
      EXPECT_NE(msg.find("corrupt.oni"), std::string::npos) << msg;
      EXPECT_NE(msg.find("while decoding frame 0"), std::string::npos) << msg;
      EXPECT_NE(msg.find("the recording is corrupt"), std::string::npos) << msg;
    }
  }
  std::printf("  corrupt colour frame: the driver crashed in %d of 4 replays; this process survived all\n", crashes);
  // and the intact recording still replays, also when a reader is dropped half-way
  for (int k = 0; k < 2; ++k) {
    OniReader r(f);
    OniFrame fr;
    int n = 0;
    while (n < 3 && r.next(fr)) ++n;
    EXPECT_EQ(n, 3);
  }
  std::filesystem::remove_all(dir);
}

// The crash path itself, deterministically: the driver process is killed with SIGSEGV between
// two frames; the next read is a FileError that says so.
TEST(OniReal, DriverCrashBecomesAFileError) {
  const std::string f = test::shared("capture/3DJ__3DJ_Test/bin/data/test.oni");
  TBSP_REQUIRE_FILE(f);
  if (!OniReader::available()) GTEST_SKIP() << "built without OpenNI2";
  const std::vector<int> before = child_pids();
  OniReader r(f);
  OniFrame fr;
  ASSERT_TRUE(r.next(fr));
  std::vector<int> now = child_pids();
  for (int p : before) now.erase(std::remove(now.begin(), now.end(), p), now.end());
  ASSERT_EQ(now.size(), 1u) << "the reader runs the driver in one child process";
  ASSERT_EQ(::kill(now[0], SIGSEGV), 0);
  try {
    r.next(fr);
    FAIL() << "a read after the driver died succeeded";
  } catch (const FileError& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find("test.oni"), std::string::npos) << msg;
    EXPECT_NE(msg.find("crashed with Segmentation fault"), std::string::npos) << msg;
    EXPECT_NE(msg.find("while decoding frame 1"), std::string::npos) << msg;
    EXPECT_NE(msg.find("--last 0"), std::string::npos) << msg;  // the frames before the damage
  }
  EXPECT_FALSE(r.next(fr));  // stays finished
}
