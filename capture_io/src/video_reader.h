// Internal: video files read through libtbsp_video (capture_io/video_module), loaded on first use.
#pragma once

#include <string>
#include <vector>

#include <opencv2/core.hpp>

namespace tbsp {
namespace detail {

/// Where libtbsp_video.so is looked for: $TBSP_VIDEO_MODULE (a file) alone when it is set, else
/// in order ../lib/tbsp/modules next to the running program, the install and the build directory.
std::vector<std::string> video_module_candidates();

/// A video file decoded by OpenCV's VideoCapture inside libtbsp_video, which is loaded (once per
/// process) when the first video is opened: a program that reads no video never loads OpenCV's
/// video stack. Move-only.
class VideoReader {
 public:
  VideoReader() = default;
  ~VideoReader();
  VideoReader(VideoReader&& o) noexcept : h_(o.h_) { o.h_ = nullptr; }
  VideoReader& operator=(VideoReader&& o) noexcept;
  VideoReader(const VideoReader&) = delete;
  VideoReader& operator=(const VideoReader&) = delete;

  /// Opens `path` (closing any video open before); false when OpenCV cannot open it.
  /// \throws FileError when libtbsp_video cannot be loaded (the message lists where it looked
  ///         and how to fix it).
  bool open(const std::string& path);
  bool isOpened() const { return h_ != nullptr; }
  /// cv::VideoCapture::get for a cv::CAP_PROP_* id; 0 when closed.
  double get(int prop) const;
  /// Skips one frame; false at the end (or closed).
  bool grab();
  /// Decodes the next frame (BGR); false at the end (or closed).
  bool read(cv::Mat& out);

 private:
  void close();
  void* h_ = nullptr;
};

}  // namespace detail
}  // namespace tbsp
