#include "tbsp/io/depth_io.h"

#include <cmath>
#include <filesystem>
#include <limits>

#include <opencv2/imgcodecs.hpp>

#include "tbsp/core/error.h"

namespace tbsp {

cv::Mat read_depth_image(const std::string& path) {
  std::error_code ec;
  if (!std::filesystem::exists(path, ec)) throw FileError("'" + path + "': no such file; check the path");
  cv::Mat d = cv::imread(path, cv::IMREAD_ANYDEPTH | cv::IMREAD_ANYCOLOR);
  if (d.empty()) throw FileError("'" + path + "': cannot be decoded as an image (corrupt, truncated or unsupported format)");
  if (d.type() != CV_16UC1)
    throw FileError("'" + path + "': a depth image must be 16-bit single-channel, this one is " + std::to_string(d.channels()) +
                    " channel(s) of " + (d.depth() == CV_8U ? "8-bit" : d.depth() == CV_16U ? "16-bit" : "other") +
                    " data; save depth as 16-bit PNG/PGM/TIFF");
  return d;
}

namespace {
void check(const cv::Mat& depth, const DepthIntrinsics& K, double scale, const char* who) {
  if (depth.empty() || (depth.type() != CV_16UC1 && depth.type() != CV_32FC1))
    throw InvalidInput(std::string("[tbsp::") + who + "] depth must be a non-empty CV_16UC1 or CV_32FC1 image");
  if (!std::isfinite(K.fx) || !std::isfinite(K.fy) || K.fx == 0 || K.fy == 0 || !std::isfinite(K.cx) || !std::isfinite(K.cy))
    throw InvalidInput(std::string("[tbsp::") + who + "] intrinsics need finite, non-zero fx and fy and finite cx, cy");
  if (!(scale > 0) || !std::isfinite(scale)) throw InvalidInput(std::string("[tbsp::") + who + "] depth scale must be positive");
}
template <typename PointT>
void fill_xyz(PointT& p, const cv::Mat& depth, int u, int v, const DepthIntrinsics& K, double scale) {
  const double raw = depth.type() == CV_16UC1 ? static_cast<double>(depth.at<std::uint16_t>(v, u)) : static_cast<double>(depth.at<float>(v, u));
  if (!(raw > 0) || !std::isfinite(raw)) {
    p.x = p.y = p.z = std::numeric_limits<float>::quiet_NaN();
    return;
  }
  const double z = raw * scale;
  p.x = static_cast<float>((u - K.cx) * z / K.fx);
  p.y = static_cast<float>((v - K.cy) * z / K.fy);
  p.z = static_cast<float>(z);
}
}  // namespace

pcl::PointCloud<pcl::PointXYZ> depth_to_cloud(const cv::Mat& depth, const DepthIntrinsics& K, double scale) {
  check(depth, K, scale, "depth_to_cloud");
  pcl::PointCloud<pcl::PointXYZ> c(static_cast<std::uint32_t>(depth.cols), static_cast<std::uint32_t>(depth.rows));
  c.is_dense = false;
  for (int v = 0; v < depth.rows; ++v)
    for (int u = 0; u < depth.cols; ++u) fill_xyz(c.at(u, v), depth, u, v, K, scale);
  return c;
}

pcl::PointCloud<pcl::PointXYZRGB> depth_to_cloud(const cv::Mat& depth, const cv::Mat& color, const DepthIntrinsics& K, double scale) {
  check(depth, K, scale, "depth_to_cloud");
  if (color.type() != CV_8UC3 || color.size() != depth.size())
    throw InvalidInput("[tbsp::depth_to_cloud] colour must be CV_8UC3 of the depth image's size (" + std::to_string(depth.cols) + "x" +
                       std::to_string(depth.rows) + "), got " + std::to_string(color.cols) + "x" + std::to_string(color.rows));
  pcl::PointCloud<pcl::PointXYZRGB> c(static_cast<std::uint32_t>(depth.cols), static_cast<std::uint32_t>(depth.rows));
  c.is_dense = false;
  for (int v = 0; v < depth.rows; ++v)
    for (int u = 0; u < depth.cols; ++u) {
      auto& p = c.at(u, v);
      fill_xyz(p, depth, u, v, K, scale);
      const cv::Vec3b& bgr = color.at<cv::Vec3b>(v, u);
      p.b = bgr[0];
      p.g = bgr[1];
      p.r = bgr[2];
    }
  return c;
}

}  // namespace tbsp
