// Depth images and recordings from ../shared/data -> organized clouds.
#include <gtest/gtest.h>

#include <algorithm>
#include <fstream>

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
