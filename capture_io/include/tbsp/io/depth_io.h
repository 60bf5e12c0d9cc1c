#pragma once
/// \file depth_io.h
/// \brief Depth images + pinhole intrinsics -> organized pcl::PointCloud, and OpenNI2 `.oni`
/// recording replay (libOpenNI2 playback device, frame by frame).

#include <memory>
#include <string>

#include <opencv2/core.hpp>
#include <pcl/point_cloud.h>
#include <pcl/point_types.h>

namespace tbsp {

/// Pinhole intrinsics of a depth camera (pixels). fy may be negative (e.g. the ICL-NUIM
/// convention of a y-up camera); fx and fy must be non-zero and finite.
struct DepthIntrinsics {
  double fx = 0, fy = 0, cx = 0, cy = 0;
};

/// Reads a 16-bit single-channel depth image (PNG, PGM/P5, TIFF). Throws FileError naming the
/// file when it is missing, unreadable, or not 16-bit single-channel.
cv::Mat read_depth_image(const std::string& path);

/// Depth (CV_16UC1 raw units, or CV_32FC1) -> organized cloud of depth.cols x depth.rows points:
/// z = raw * scale, x = (u - cx) z / fx, y = (v - cy) z / fy. Pixels with raw 0 or non-finite
/// depth are NaN points (is_dense = false). Throws InvalidInput on bad intrinsics or image type.
pcl::PointCloud<pcl::PointXYZ> depth_to_cloud(const cv::Mat& depth, const DepthIntrinsics& K, double scale);
/// Same with colour (CV_8UC3 BGR, same size as the depth image; registered to it).
pcl::PointCloud<pcl::PointXYZRGB> depth_to_cloud(const cv::Mat& depth, const cv::Mat& color_bgr,
                                                 const DepthIntrinsics& K, double scale);

/// What an .oni recording holds.
struct OniInfo {
  bool has_depth = false, has_color = false;
  int depth_frames = 0, color_frames = 0;
  int depth_width = 0, depth_height = 0, color_width = 0, color_height = 0;
  int fps = 0;
  DepthIntrinsics depth_intrinsics;  ///< from the stream's field of view
  double depth_scale = 0.001;        ///< metres per raw unit (1 mm or 100 um formats)
};

/// One frame of a recording.
struct OniFrame {
  int index = 0;   ///< 0-based frame number in the depth stream
  cv::Mat depth;   ///< CV_16UC1 raw depth (see OniInfo::depth_scale); empty if no depth stream
  cv::Mat color;   ///< CV_8UC3 BGR; empty when the recording has no colour or it ran out
};

/// Replays an OpenNI2 (or OpenNI 1.x "NI10") .oni file frame by frame, as fast as frames are
/// read (playback speed -1, no repeat). Only one frame is held in memory at a time.
/// Throws FileError naming the file when it is missing, OpenNI2 cannot open it (with
/// OpenNI2's own error text) or it holds no depth stream with frames.
class OniReader {
public:
  explicit OniReader(const std::string& path);
  ~OniReader();
  OniReader(const OniReader&) = delete;
  OniReader& operator=(const OniReader&) = delete;
  const OniInfo& info() const;
  /// Next frame; false after the last one.
  bool next(OniFrame& frame);
  /// True when tbsp was built with OpenNI2 support.
  static bool available();

private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace tbsp
