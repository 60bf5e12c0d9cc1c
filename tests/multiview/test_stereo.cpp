// Unit tests of the stereo matcher and the fusion engine's input checks (analytic cases).
#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include <opencv2/imgproc.hpp>

#include "tbsp/core/error.h"
#include "tbsp/multiview/stereo_depth_fusion.h"
#include "tbsp/multiview/stereo_matcher.h"

using namespace tbsp;

namespace {
// A random-texture left image and the right image of a scene whose disparity is d(x, y):
// right(x - d, y) = left(x, y), built by sampling the left image at x + d(x', y) (inverse warp
// of a smooth field, exact up to interpolation).
cv::Mat texture(int w, int h, unsigned seed) {
  std::mt19937 rng(seed);
  cv::Mat small(h / 4 + 1, w / 4 + 1, CV_8UC3);
  std::uniform_int_distribution<int> u(0, 255);
  for (int y = 0; y < small.rows; ++y)
    for (int x = 0; x < small.cols; ++x) small.at<cv::Vec3b>(y, x) = cv::Vec3b(u(rng), u(rng), u(rng));
  cv::Mat big;
  cv::resize(small, big, cv::Size(w, h), 0, 0, cv::INTER_CUBIC);
  return big;
}
}  // namespace

TEST(StereoMatcher, SlantedPlaneDisparityIsRecoveredToSubPixel) {
  const int w = 320, h = 240;
  const cv::Mat L = texture(w, h, 7);
  // Disparity of a slanted plane: 12 + 8 x / w (12..20 px). right(xr) = left(xr + d), d ~ d(xr).
  cv::Mat mapx(h, w, CV_32F), mapy(h, w, CV_32F);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      // Solve xl = xr + 12 + 8 xl / w for xl.
      const double xl = (x + 12.0) / (1.0 - 8.0 / w);
      mapx.at<float>(y, x) = static_cast<float>(xl);
      mapy.at<float>(y, x) = static_cast<float>(y);
    }
  cv::Mat R;
  cv::remap(L, R, mapx, mapy, cv::INTER_CUBIC, cv::BORDER_REFLECT);
  StereoMatchOptions o;
  o.num_disparities = 32;
  const DisparityMap d = compute_disparity(L, R, o);
  int good = 0, checked = 0, known = 0;
  for (int y = 8; y < h - 8; ++y)
    for (int x = 30; x < w - 8; ++x) {
      ++known;
      const float v = d.disparity.at<float>(y, x);
      if (std::isnan(v)) continue;
      ++checked;
      if (std::abs(v - (12.0 + 8.0 * x / w)) <= 0.5) ++good;
    }
  EXPECT_GT(checked, 0.9 * known) << "left-right check rejected too much of an unoccluded plane";
  EXPECT_GT(good, 0.97 * checked);
  EXPECT_EQ(d.pixels, w * h);
  EXPECT_LE(d.consistent_pixels, d.matched_pixels);
  ASSERT_FALSE(d.right_disparity.empty());
}

TEST(StereoMatcher, DenseModeFillsEveryPixel) {
  const cv::Mat L = texture(200, 150, 3);
  cv::Mat R;
  const cv::Mat M = (cv::Mat_<double>(2, 3) << 1, 0, -10, 0, 1, 0);
  cv::warpAffine(L, R, M, L.size(), cv::INTER_LINEAR, cv::BORDER_REFLECT);
  StereoMatchOptions o;
  o.num_disparities = 16;
  o.fill_invalid = true;
  const DisparityMap d = compute_disparity(L, R, o);
  EXPECT_EQ(cv::countNonZero(d.disparity != d.disparity), 0) << "NaN left in dense mode";
  // The constant shift of 10 px is found on almost all pixels.
  cv::Mat err;
  cv::absdiff(d.disparity, cv::Scalar(10.0), err);
  EXPECT_GT(cv::countNonZero(err < 1.0), 0.95 * L.total());
  // The bad-pixel rate against a ground truth of 10 * 4 (scale 4) agrees.
  const cv::Mat gt(L.size(), CV_8U, cv::Scalar(40));
  EXPECT_LT(bad_pixel_rate(d.disparity, gt, 4.0), 5.0);
}

// Same input, same output: the dense mode's weighted median is ours because OpenCV ximgproc's
// changed ~5 % of the pixels from one call to the next on the Middlebury pairs.
TEST(StereoMatcher, DenseModeIsDeterministic) {
  const cv::Mat L = texture(200, 150, 3);
  cv::Mat R1, R2, R;
  // Two depths: the left half shifted by 12 px, the right half by 4 (occlusion at the step).
  const cv::Mat M1 = (cv::Mat_<double>(2, 3) << 1, 0, -12, 0, 1, 0), M2 = (cv::Mat_<double>(2, 3) << 1, 0, -4, 0, 1, 0);
  cv::warpAffine(L, R1, M1, L.size(), cv::INTER_LINEAR, cv::BORDER_REFLECT);
  cv::warpAffine(L, R2, M2, L.size(), cv::INTER_LINEAR, cv::BORDER_REFLECT);
  R = R2.clone();
  R1(cv::Rect(0, 0, 88, L.rows)).copyTo(R(cv::Rect(0, 0, 88, L.rows)));
  StereoMatchOptions o;
  o.num_disparities = 16;
  o.fill_invalid = true;
  const DisparityMap a = compute_disparity(L, R, o);
  for (int k = 0; k < 3; ++k) {
    const DisparityMap b = compute_disparity(L, R, o);
    EXPECT_EQ(cv::countNonZero(a.disparity != b.disparity), 0) << "call " << k + 2 << " differs from the first";
  }
  // And the two depths are there.
  EXPECT_NEAR(a.disparity.at<float>(75, 40), 12.0f, 1.0f);
  EXPECT_NEAR(a.disparity.at<float>(75, 160), 4.0f, 1.0f);
}

TEST(StereoMatcher, BadInputGivesClearErrors) {
  const cv::Mat a = texture(64, 48, 1), b = texture(60, 48, 2);
  EXPECT_THROW(compute_disparity(cv::Mat(), a), InvalidInput);
  try {
    compute_disparity(a, b);
    FAIL() << "size mismatch accepted";
  } catch (const InvalidInput& e) {
    EXPECT_NE(std::string(e.what()).find("differ in size"), std::string::npos) << e.what();
  }
  cv::Mat f;
  a.convertTo(f, CV_32F);
  EXPECT_THROW(compute_disparity(f, f), InvalidInput);
  StereoMatchOptions o;
  o.num_disparities = 20;  // not a multiple of 16
  std::string why;
  EXPECT_FALSE(o.isValid(&why));
  EXPECT_NE(why.find("multiple of 16"), std::string::npos);
  EXPECT_THROW(compute_disparity(a, a, o), InvalidInput);
  o = {};
  o.block_size = 4;
  EXPECT_FALSE(o.isValid());
  const cv::Mat gt0(a.size(), CV_8U, cv::Scalar(0));
  EXPECT_THROW(bad_pixel_rate(cv::Mat(a.size(), CV_32F, cv::Scalar(1)), gt0, 1.0), InvalidInput);
}

TEST(StereoDepthFusion, BadFramesAreRejectedNamingTheCamera) {
  const Camera c0 = Camera::lookAt("left", 80, 60, 1.0, {-0.2, 0, -2}, {0, 0, 0}, {0, -1, 0});
  const Camera c1 = Camera::lookAt("right", 80, 60, 1.0, {0.2, 0, -2}, {0, 0, 0}, {0, -1, 0});
  const cv::Mat img = texture(80, 60, 5);
  StereoDepthFusion<pcl::PointXYZ> s;
  pcl::PointCloud<pcl::PointXYZ> out;
  out.push_back({1, 2, 3});
  // One camera only.
  s.setInputFrame({c0}, {img});
  EXPECT_THROW(s.compute(out), InvalidInput);
  // Image size differs from the calibration: the message names the camera and both sizes.
  s.setInputFrame({c0, c1}, {img, texture(64, 48, 6)});
  try {
    s.compute(out);
    FAIL();
  } catch (const InvalidInput& e) {
    const std::string m = e.what();
    EXPECT_NE(m.find("'right'"), std::string::npos) << m;
    EXPECT_NE(m.find("64x48"), std::string::npos) << m;
  }
  // Empty silhouette.
  s.setInputFrame({c0, c1}, {img, img}, {cv::Mat(60, 80, CV_8U, cv::Scalar(255)), cv::Mat(60, 80, CV_8U, cv::Scalar(0))});
  try {
    s.compute(out);
    FAIL();
  } catch (const InvalidInput& e) {
    EXPECT_NE(std::string(e.what()).find("silhouette is empty"), std::string::npos) << e.what();
  }
  // Cameras looking in opposite directions: no pair.
  const Camera back = Camera::lookAt("back", 80, 60, 1.0, {0, 0, 2}, {0, 0, 4}, {0, -1, 0});
  s.setInputFrame({c0, back}, {img, img});
  try {
    s.compute(out);
    FAIL();
  } catch (const InvalidInput& e) {
    EXPECT_NE(std::string(e.what()).find("do not overlap"), std::string::npos) << e.what();
  }
  // Output untouched by all of the failures.
  ASSERT_EQ(out.size(), 1u);
  EXPECT_EQ(out[0].z, 3.f);
  // Invalid options are refused by the setter.
  StereoFusionOptions o;
  o.image_scale = 0;
  EXPECT_THROW(s.setOptions(o), InvalidInput);
  o = {};
  o.near = 2;
  EXPECT_THROW(s.setOptions(o), InvalidInput);
}

#include "tbsp/mesh/primitives.h"
#include "tbsp/multiview/model_guided_stereo.h"

TEST(ModelGuidedStereo, BadInputIsRejectedAndOutputUntouched) {
  const Camera c0 = Camera::lookAt("left", 80, 60, 1.0, {-0.2, 0, -2}, {0, 0, 0}, {0, -1, 0});
  const Camera c1 = Camera::lookAt("right", 80, 60, 1.0, {0.2, 0, -2}, {0, 0, 0}, {0, -1, 0});
  const cv::Mat img = texture(80, 60, 5);
  ModelGuidedStereo m;
  TriMesh out;
  out.V = Eigen::MatrixX3d::Ones(1, 3);
  auto message = [&] {
    try {
      m.refine(out);
    } catch (const InvalidInput& e) {
      return std::string(e.what());
    }
    return std::string();
  };
  m.setInputFrame({c0, c1}, {img, img});
  EXPECT_NE(message().find("mesh is empty"), std::string::npos);
  TriMesh sphere = make_icosphere(2);
  sphere.V *= 0.3;
  m.setInputMesh(sphere);
  m.setInputFrame({c0}, {img});
  EXPECT_NE(message().find("at least 2"), std::string::npos);
  m.setInputFrame({c0, c1}, {img, texture(40, 30, 1)});
  EXPECT_NE(message().find("'right'"), std::string::npos);
  TriMesh far = sphere;
  far.V.col(2).array() -= 50.0;  // behind both cameras
  m.setInputMesh(far);
  m.setInputFrame({c0, c1}, {img, img});
  EXPECT_NE(message().find("outside every view"), std::string::npos);
  EXPECT_EQ(out.V.rows(), 1);
  ModelGuidedStereoOptions o;
  o.patch_size = 4;
  EXPECT_THROW(m.setOptions(o), InvalidInput);
  o = {};
  o.search_range = 0;
  EXPECT_THROW(m.setOptions(o), InvalidInput);
}
