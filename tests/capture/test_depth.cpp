#include <gtest/gtest.h>

#include <fstream>

#include <opencv2/imgcodecs.hpp>

#include "test_util.h"
#include "tbsp/core/error.h"
#include "tbsp/io/depth_io.h"

using namespace tbsp;

TEST(Depth, AnalyticPlaneBackProjects) {
  // A fronto-parallel plane at 2 m (raw 2000 at 1 mm) and a hole.
  cv::Mat d(48, 64, CV_16UC1, cv::Scalar(2000));
  d.at<std::uint16_t>(10, 20) = 0;
  const DepthIntrinsics K{100, 100, 31.5, 23.5};
  const auto c = depth_to_cloud(d, K, 0.001);
  EXPECT_EQ(c.width, 64u);
  EXPECT_EQ(c.height, 48u);
  EXPECT_FALSE(c.is_dense);
  EXPECT_FALSE(std::isfinite(c.at(20, 10).z));
  EXPECT_FLOAT_EQ(c.at(63, 47).z, 2.0f);
  EXPECT_NEAR(c.at(63, 47).x, (63 - 31.5) * 2.0 / 100, 1e-6);
  EXPECT_NEAR(c.at(0, 0).y, (0 - 23.5) * 2.0 / 100, 1e-6);
  cv::Mat col(48, 64, CV_8UC3, cv::Scalar(10, 20, 30));
  const auto cc = depth_to_cloud(d, col, K, 0.001);
  EXPECT_EQ(cc.at(5, 5).r, 30);
  EXPECT_EQ(cc.at(5, 5).b, 10);
  EXPECT_THROW(depth_to_cloud(d, DepthIntrinsics{0, 1, 0, 0}, 0.001), InvalidInput);
  EXPECT_THROW(depth_to_cloud(d, K, -1), InvalidInput);
  EXPECT_THROW(depth_to_cloud(cv::Mat(4, 4, CV_8UC1), K, 1), InvalidInput);
  EXPECT_THROW(depth_to_cloud(d, cv::Mat(4, 4, CV_8UC3), K, 1), InvalidInput);
}

TEST(Depth, BadDepthFilesGiveClearErrors) {
  const auto dir = test::temp_dir("depth");
  cv::imwrite((dir / "rgb.png").string(), cv::Mat(4, 4, CV_8UC3, cv::Scalar(1, 2, 3)));
  std::ofstream(dir / "junk.png") << "not a png";
  cv::Mat good(4, 4, CV_16UC1, cv::Scalar(1000));
  cv::imwrite((dir / "good.png").string(), good);
  std::ifstream in(dir / "good.png", std::ios::binary);
  std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  std::ofstream(dir / "cut.png", std::ios::binary) << bytes.substr(0, bytes.size() / 2);
  EXPECT_EQ(read_depth_image((dir / "good.png").string()).at<std::uint16_t>(1, 1), 1000);
  for (const char* f : {"rgb.png", "junk.png", "cut.png", "missing.png"}) {
    try {
      read_depth_image((dir / f).string());
      FAIL() << f;
    } catch (const FileError& e) {
      EXPECT_NE(std::string(e.what()).find(f), std::string::npos) << e.what();
    }
  }
}
