#pragma once
/// \file cloth_observations.h
/// \brief What the cloth parameter estimation (thesis §10.7) compares a simulation with: for
/// every frame n of a studio recording and every camera k, the boundary of the measured
/// silhouette (for E_sil, eq. 10.7) and SIFT correspondences between frames n − 1 and n (for
/// E_sift, eq. 10.8). Built once, frame by frame; images are not kept (memory: the boundary
/// pixels and the correspondences only, as the thesis stresses).
///
/// Boundary: the foreground pixels (silhouette ≥ 128) with a background 4-neighbour, stored
/// with a 2-D k-d tree (nanoflann) per view and frame, so the distance from any image point to
/// the nearest boundary pixel is exact and O(log m).
/// Correspondences: SIFT keypoints (OpenCV) on the silhouette of every frame, matched from
/// frame n − 1 to frame n per view by descriptor (Lowe's ratio test), mutual best, within
/// `max_motion_px`. Views are processed in parallel (OpenMP). Library: tbsp::multiview.

#include <cstddef>
#include <memory>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "tbsp/multiview/camera.h"

namespace tbsp {

struct ClothObservationOptions {
  int max_features = 1000;      ///< SIFT keypoints per view and frame (the strongest), 1..100000
  double ratio = 0.75;          ///< Lowe's ratio test for a correspondence, (0, 1]
  double max_motion_px = 30;    ///< a feature moves at most this far between two frames, pixels, > 0

  bool isValid(std::string* why = nullptr) const;
};

/// One feature seen at `from` in frame n − 1 and at `to` in frame n (pixels).
struct FeaturePair {
  Eigen::Vector2f from, to;
};

class ClothObservations {
public:
  /// \throws InvalidInput on no camera or invalid options.
  explicit ClothObservations(std::vector<Camera> cameras, ClothObservationOptions options = {});
  ~ClothObservations();
  ClothObservations(ClothObservations&&) noexcept;
  ClothObservations& operator=(ClothObservations&&) noexcept;

  /// \brief Adds the next frame: one image (CV_8UC3 BGR or CV_8U) and one silhouette (CV_8U,
  /// ≥ 128 foreground) per camera, in camera order, of the calibrated size.
  /// \throws InvalidInput naming the camera and frame on a count or size mismatch, a missing
  /// image or an empty silhouette (the cloth estimation needs the performer in every view).
  void addFrame(const std::vector<cv::Mat>& images, const std::vector<cv::Mat>& silhouettes);

  /// \brief Parts of a recording computed apart (several processes: `tbsp cloth estimate` under
  /// mpirun): the frame just before this object's first one, of which only the features are
  /// kept, so that the first addFrame() gets its correspondences as in one pass over the whole
  /// recording. Only before the first addFrame(). Same checks as addFrame().
  void primeFrame(const std::vector<cv::Mat>& images, const std::vector<cv::Mat>& silhouettes);
  /// \brief This object's frames as bytes (boundary pixels and correspondences of every view),
  /// for append() on another process. Little-endian binary; O(boundary pixels + correspondences).
  std::string serialize() const;
  /// \brief Appends the frames another object of the same cameras serialized: the parts of a
  /// recording, appended in frame order, give what one pass over it gives (the same distances and
  /// correspondences, bit for bit). addFrame() cannot follow (the features of the last frame are
  /// not in the bytes). \throws InvalidInput on bytes that are not such a serialization (wrong
  /// header, another view count, truncated, counts beyond the data).
  void append(const std::string& bytes);

  int numFrames() const;
  int numViews() const { return static_cast<int>(cameras_.size()); }
  const std::vector<Camera>& cameras() const { return cameras_; }
  const ClothObservationOptions& options() const { return options_; }

  /// Distance (pixels) from `p` to the nearest silhouette boundary pixel of view `view` at frame
  /// `frame`. Thread-safe. Indices are not checked beyond an assertion.
  double boundaryDistance(int frame, int view, const Eigen::Vector2d& p) const;
  /// Correspondences from frame − 1 to `frame` in view `view` (empty for frame 0).
  const std::vector<FeaturePair>& correspondences(int frame, int view) const;

  std::size_t numBoundaryPixels() const;
  std::size_t numCorrespondences() const;
  std::size_t memoryBytes() const;

private:
  void checkFrame(const std::vector<cv::Mat>& images, const std::vector<cv::Mat>& silhouettes, const std::string& where) const;
  struct Impl;
  std::vector<Camera> cameras_;
  ClothObservationOptions options_;
  std::unique_ptr<Impl> impl_;
};

}  // namespace tbsp
