#pragma once
/// \file stereo_depth_fusion.h
/// \brief Multi-view stereo by depth-map fusion (thesis §6.3.3; fusion as in Goesele et al.
/// 2006 and COLMAP): k calibrated views (a studio frame) -> per-view depth maps from rectified
/// pairs -> one fused, oriented, coloured point cloud with a per-point confidence.
///
/// Pipeline (each stage reported in StereoFusionReport):
/// 1. pairs: every view is paired with its `partners` nearest views by the angle between the
///    viewing directions (within [min_pair_angle_deg, max_pair_angle_deg]); each unordered pair
///    is matched once and gives a depth map for both of its views;
/// 2. rectification with OpenCV (stereoRectify + remap, lens distortion removed; vertical pairs
///    are transposed, mirrored pairs flipped) at `image_scale` of the camera resolution;
/// 3. disparity range per pair from sparse ORB matches on the rectified images (2nd–98th
///    percentile plus a margin), or from [near, far] when given; silhouettes mask both images;
/// 4. disparities: compute_disparity() (SGBM, left-right check, no filling) -> depth in the
///    reference camera's own pixel grid (at `image_scale`);
/// 5. geometric consistency: a depth is kept when at least `min_agreeing_views` cameras of other
///    pairs have a depth map that sees the point at the same depth (relative `depth_tolerance`);
///    with silhouettes, a point must also project inside every camera's silhouette (within
///    `silhouette_margin_px`: the visual-hull test);
///    kept points are averaged with the agreeing ones and those pixels are consumed, so every
///    surface patch makes one point;
/// 6. normals from the depth map's local plane (oriented to the camera), colour from the
///    reference image, confidence = agreeing cameras / cameras that see the point in their image;
/// 7. statistical outlier removal (PCL), optional (off by default).
/// Views and pairs run in parallel (OpenMP); the result does not depend on the thread count.
///
/// Units: the world units of the cameras (metres in the studio format). Errors: InvalidInput
/// naming the camera, pair or frame and the fix (image size ≠ calibration, fewer than 2 views,
/// a silhouette that is empty, a pair whose views do not overlap when it is the only pair of a
/// view); Cancelled from the progress callback. Outputs are untouched on error.

#include <memory>
#include <string>
#include <vector>

#include <opencv2/core.hpp>
#include <pcl/point_cloud.h>
#include <pcl/point_types.h>

#include "tbsp/core/progress.h"
#include "tbsp/multiview/camera.h"
#include "tbsp/multiview/stereo_matcher.h"

namespace tbsp {

struct StereoFusionOptions {
  /// Disparity engine settings; num_disparities and min_disparity are set per pair (step 3),
  /// fill_invalid is ignored (always off: only checked matches make points).
  StereoMatchOptions match;
  /// Partner views per view (1..8). Default 2 (both ring neighbours).
  int partners = 2;
  /// Angle between the viewing directions of a pair, degrees: 0 < min < max <= 120.
  double min_pair_angle_deg = 3.0;
  double max_pair_angle_deg = 60.0;
  /// Matching resolution relative to the images, (0, 1]. 0.5 halves width and height (4x
  /// fewer pixels, 8x less SGBM work); depth maps are at this resolution.
  double image_scale = 0.5;
  /// Depth range along each camera's axis in world units; both 0 = automatic (step 3).
  double near = 0.0, far = 0.0;
  /// Largest disparity search of one pair, pixels (at image_scale); wider ranges are clamped
  /// around the sparse matches' median. Default 256.
  int max_disparities = 256;
  /// Geometric consistency: cameras outside the pair that must agree (>= 1). The two maps of
  /// one pair come from one left-right checked match, so a pair never confirms itself: 1 means
  /// a second, independent pair saw the same depth. Default 1 (synthetic studio: 2 drops
  /// completeness from 91 % to 84 % for 0.03 % of the diagonal in accuracy; docs/stereo.md).
  int min_agreeing_views = 1;
  /// Relative depth difference accepted as agreement, (0, 0.2]. Default 0.01 (1 % of depth).
  double depth_tolerance = 0.01;
  /// Use the silhouettes when the frame has them: each view's disparities are masked by its own
  /// silhouette, and fused points must project inside every silhouette (visual hull).
  bool use_silhouettes = true;
  /// Tolerance of the visual-hull test, pixels (>= 0). Default 0: the silhouettes are taken as
  /// exact (SGBM widens foreground edges by a pixel or two; a margin lets that through).
  double silhouette_margin_px = 0.0;
  /// Statistical outlier removal: neighbours and the distance threshold in standard
  /// deviations (PCL StatisticalOutlierRemoval). neighbours = 0 (default) turns it off: after
  /// the consistency and visual-hull tests it removed correct points where the cloud is sparse
  /// (thin limbs, grazing surface) — on the synthetic studio, k = 16 / 2σ took completeness
  /// from 95.1 % to 89.4 % for 0.03 % of the diagonal in accuracy (docs/stereo.md).
  int outlier_neighbours = 0;
  double outlier_stddev = 2.0;

  bool isValid(std::string* why = nullptr) const;
};

/// One view's depth map (camera z, world units), at image_scale of the camera resolution.
struct ViewDepth {
  int camera = -1;       ///< index in the camera list
  int partner = -1;      ///< the other camera of the pair that produced it
  cv::Mat depth;         ///< CV_32F, NaN where there is no depth
  double scale = 1.0;    ///< depth-map pixel (x, y) = camera pixel (x / scale, y / scale)
  int disparity_min = 0, disparity_count = 0;  ///< the search range used (rectified pixels)
  int valid_pixels = 0;
};

struct StereoFusionReport {
  int views = 0;
  int pairs = 0;
  std::vector<std::string> pair_names;       ///< "camA-camB"
  std::vector<std::string> skipped_pairs;    ///< pairs without overlap, with the reason
  long depth_points = 0;        ///< pixels with a depth over all depth maps
  long consistent_points = 0;   ///< ... that passed the consistency test (before merging)
  long fused_points = 0;        ///< points after merging
  long output_points = 0;       ///< after outlier removal
  double seconds_rectify = 0, seconds_match = 0, seconds_fusion = 0, seconds_outliers = 0, seconds_total = 0;
};

/// Non-template core: views -> fused XYZRGBNormal cloud + confidence. See the class below.
class StereoFusionEngine {
public:
  using Options = StereoFusionOptions;
  void setOptions(const StereoFusionOptions& o);
  const StereoFusionOptions& options() const { return options_; }
  void setProgressCallback(ProgressCallback cb) { progress_ = std::move(cb); }

  /// images: CV_8UC3 (or CV_8UC1) per camera, sizes = calibrated sizes; silhouettes: empty or
  /// CV_8U per camera (empty Mat = none for that camera). `frame` names the frame in errors.
  void compute(const std::vector<Camera>& cameras, const std::vector<cv::Mat>& images, const std::vector<cv::Mat>& silhouettes,
               pcl::PointCloud<pcl::PointXYZRGBNormal>& cloud, std::vector<float>& confidence, int frame = 0);

  const StereoFusionReport& report() const { return report_; }
  /// The depth maps of the last compute() (two per matched pair).
  const std::vector<ViewDepth>& depthMaps() const { return depth_; }

private:
  StereoFusionOptions options_;
  ProgressCallback progress_;
  StereoFusionReport report_;
  std::vector<ViewDepth> depth_;
};

/// PCL-style front end. PointT must have x, y, z; normals and rgb are copied when it has them
/// (pcl::copyPointCloud field matching). Instantiated for PointXYZ, PointNormal, PointXYZRGB,
/// PointXYZRGBNormal.
/// \code
/// tbsp::StereoDepthFusion<pcl::PointXYZRGBNormal> stereo;
/// stereo.setInputFrame(studio.cameraList(), frame.images, frame.silhouettes);
/// pcl::PointCloud<pcl::PointXYZRGBNormal> cloud;
/// stereo.compute(cloud);               // stereo.getConfidence()[i] per point, stereo.report()
/// \endcode
template <typename PointT>
class StereoDepthFusion {
public:
  using Ptr = std::shared_ptr<StereoDepthFusion<PointT>>;
  using ConstPtr = std::shared_ptr<const StereoDepthFusion<PointT>>;
  using Options = StereoFusionOptions;

  void setOptions(const StereoFusionOptions& o) { engine_.setOptions(o); }
  const StereoFusionOptions& options() const { return engine_.options(); }
  void setProgressCallback(ProgressCallback cb) { engine_.setProgressCallback(std::move(cb)); }
  void setInputFrame(std::vector<Camera> cameras, std::vector<cv::Mat> images, std::vector<cv::Mat> silhouettes = {},
                     int frame = 0) {
    cameras_ = std::move(cameras);
    images_ = std::move(images);
    silhouettes_ = std::move(silhouettes);
    frame_ = frame;
  }
  /// Runs the pipeline; on any exception `output` is untouched.
  void compute(pcl::PointCloud<PointT>& output);
  const std::vector<float>& getConfidence() const { return confidence_; }
  const std::vector<ViewDepth>& getDepthMaps() const { return engine_.depthMaps(); }
  const StereoFusionReport& report() const { return engine_.report(); }

private:
  StereoFusionEngine engine_;
  std::vector<Camera> cameras_;
  std::vector<cv::Mat> images_, silhouettes_;
  int frame_ = 0;
  std::vector<float> confidence_;
};

}  // namespace tbsp
