#pragma once
/// \file studio.h
/// \brief Multi-view studio datasets (`studio.yaml`, format in docs/studio_format.md): k
/// calibrated, synchronised cameras (thesis §6.1: k = 8, 1004x1004, silhouettes, 3x4 P),
/// per-camera image sequences or videos, silhouettes, and optional template mesh, marker
/// trajectories (TRC/C3D), skeleton motion (BVH) and ground-truth meshes.
///
/// read_studio() parses and validates the file (every error names the file, the line and
/// the fix); check_studio() checks the data on disk (missing frames listed by name, image
/// sizes); StudioFrameStream reads one frame of all cameras at a time, so a 1000-frame,
/// 8-camera sequence never sits in memory.

#include <memory>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "tbsp/multiview/camera.h"

namespace tbsp {

struct StudioCamera {
  Camera camera;
  std::string images;       ///< image file pattern with one %d / %0Nd for the frame number, or empty
  std::string video;        ///< video file (OpenCV VideoCapture); frame i of the video = first_frame + i
  std::string silhouettes;  ///< silhouette file pattern, or empty
};

struct Studio {
  std::string path;  ///< the studio.yaml this was read from (relative paths resolve against its folder)
  std::string name;
  double frame_rate = 25.0;
  int first_frame = 0, last_frame = 0;  ///< inclusive
  std::vector<StudioCamera> cameras;
  std::string template_mesh;  ///< optional: template mesh file
  std::string markers;        ///< optional: TRC or C3D marker trajectories
  std::string skeleton;       ///< optional: BVH skeleton + motion
  std::string ground_truth;   ///< optional: ground-truth mesh pattern with %d / %0Nd

  int numFrames() const { return last_frame - first_frame + 1; }
  std::vector<Camera> cameraList() const;
  /// Path relative to the studio file's folder (absolute paths are returned as they are).
  std::string resolve(const std::string& relative) const;
  std::string imagePath(int camera, int frame) const;
  std::string silhouettePath(int camera, int frame) const;
  std::string groundTruthPath(int frame) const;
};

/// Expands a frame pattern with exactly one %d or %0Nd (N <= 9); "%%" is a literal '%'.
/// Throws InvalidInput for any other pattern.
std::string expand_frame_pattern(const std::string& pattern, int frame);

/// Reads and validates studio.yaml. Throws FileError ("FILE:LINE: ...") on YAML syntax errors,
/// missing or mistyped keys, bad calibration (non-rotation R, rank-deficient P, bad K),
/// duplicate camera names, bad frame patterns or an empty frame range.
Studio read_studio(const std::string& path);
/// Writes studio.yaml atomically (K, distortion, R, t per camera).
void write_studio(const std::string& path, const Studio& studio);

/// Result of checking a studio's files on disk.
struct StudioCheck {
  int files_checked = 0;
  int files_missing = 0;
  std::vector<std::string> missing;   ///< the first missing files, by name
  std::vector<std::string> problems;  ///< size mismatches, unreadable files, ...
  bool ok() const { return files_missing == 0 && problems.empty(); }
  std::string summary() const;
};
/// Checks that every image / silhouette / ground-truth file of every frame exists (listing up
/// to `max_listed` missing names), and that the first image and silhouette of each camera
/// decode with the calibrated size. Videos: opened, frame count and size checked.
StudioCheck check_studio(const Studio& studio, int max_listed = 20);

/// One synchronised frame of all cameras.
struct StudioFrame {
  int frame = 0;
  std::vector<cv::Mat> images;       ///< CV_8UC3 BGR per camera (empty Mat when the camera has no images)
  std::vector<cv::Mat> silhouettes;  ///< CV_8UC1, 0 = background, 255 = foreground (threshold 128)
};

/// Streams a studio frame by frame. Memory: one frame of all cameras (buffers are reused).
class StudioFrameStream {
public:
  struct Options {
    bool images = true;
    bool silhouettes = true;
    int first = -1, last = -1;  ///< sub-range (inclusive); -1 = the studio's range
    int step = 1;
  };
  StudioFrameStream(const Studio& studio, Options options);
  ~StudioFrameStream();
  /// Reads the next frame into `out`; false after the last. Throws FileError naming the file
  /// (camera and frame) that is missing or cannot be decoded, or whose size is not the
  /// calibrated size.
  bool next(StudioFrame& out);

private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace tbsp
