#pragma once
/// \file stereo_matcher.h
/// \brief Dense disparity for one rectified stereo pair (thesis §6.3.3 uses stereo depth to
/// recover what silhouettes cannot see). OpenCV's StereoSGBM (semi-global matching,
/// Hirschmüller 2008) is the engine; tbsp adds what raw SGBM lacks:
/// - a border pad, so the left band of `num_disparities` columns gets disparities too (raw
///   SGBM leaves it invalid: 14 % of a 450-pixel-wide Middlebury image at 64 disparities);
/// - a left-right consistency check against a second SGBM run with the images swapped;
/// - optionally (dense mode) background filling of the pixels that failed the check
///   (occlusions take the farther of the two neighbouring disparities on their row) and a
///   weighted median filter guided by the left image (written here: OpenCV ximgproc's is not deterministic) that removes streaks.
/// Library: tbsp_multiview (links OpenCV calib3d + features2d; libtbsp itself stays OpenCV-free).
///
/// Measured on Middlebury 2001/2003 (docs/stereo.md, `bench_stereo`): bad pixels (> 1 px) on
/// all pixels with ground truth, tsukuba / venus / teddy / cones, far below raw StereoSGBM and
/// PCL's AdaptiveCostSOStereoMatching in the same run.
///
/// Complexity: O(W H D) time and O(W H D) bytes (SGBM 3-way: about W·D·2 bytes per row band),
/// twice (left and right). Errors: tbsp::InvalidInput naming the problem (empty or differently
/// sized images, unsupported types, invalid options).

#include <string>

#include <opencv2/core.hpp>

namespace tbsp {

struct StereoMatchOptions {
  /// Smallest disparity searched, pixels (any integer; may be negative for verging cameras).
  int min_disparity = 0;
  /// Number of disparities searched, pixels: > 0 and a multiple of 16 (OpenCV's requirement).
  int num_disparities = 64;
  /// Matching block size, pixels: odd, 1..11. 5 is best on average on the Middlebury pairs.
  int block_size = 5;
  /// SGM smoothness penalties as multiples of channels·block_size² (OpenCV's convention):
  /// P1 for ±1 disparity steps, P2 > P1 for larger jumps. Defaults 8 and 32 (OpenCV sample).
  double p1_factor = 8.0;
  double p2_factor = 32.0;
  /// Uniqueness margin in percent (0..100): the best cost must beat the second best by this.
  int uniqueness_ratio = 5;
  /// Full 8-path SGM (slower, more memory) instead of OpenCV's 3-way variant (default).
  bool full_dp = false;
  /// Pad the images on the side the disparity search runs off, so border pixels get matched.
  bool pad_border = true;
  /// Check left against right disparities; pixels that disagree by more than `lr_tolerance`
  /// pixels are invalid (occlusions, mismatches).
  bool left_right_check = true;
  double lr_tolerance = 1.0;  ///< pixels, > 0
  /// Speckle filter on the raw disparities: regions of fewer than `speckle_window` pixels whose
  /// disparity differs by more than `speckle_range` from their surroundings are removed.
  /// 0 = off (default: the left-right check removes most speckles already).
  int speckle_window = 0;
  int speckle_range = 2;  ///< pixels
  /// Dense output: fill invalid pixels (background fill along rows) and smooth with a
  /// weighted median filter of radius `median_radius` guided by the left image (0 = no filter).
  /// Off for depth fusion, where only checked matches should make points.
  bool fill_invalid = false;
  int median_radius = 3;

  /// False (and the reason in *why) when a value is out of range.
  bool isValid(std::string* why = nullptr) const;
};

/// The disparities of one pair: d(x, y) such that left(x, y) matches right(x - d, y).
struct DisparityMap {
  cv::Mat disparity;  ///< CV_32F, NaN where invalid (never NaN when fill_invalid is on)
  cv::Mat matched;    ///< CV_8U, 255 where the disparity comes from a checked match, 0 where filled or invalid
  /// Right-reference disparities (right(x, y) matches left(x + d, y)), left-right checked the
  /// same way, never filled; empty when the check is off.
  cv::Mat right_disparity;
  int pixels = 0;            ///< width·height
  int matched_pixels = 0;    ///< SGBM gave a disparity
  int consistent_pixels = 0; ///< ... and it passed the left-right check (= matched when the check is off)
  double seconds = 0;
};

/// Computes the disparity of a rectified pair. `left` and `right`: CV_8UC1 or CV_8UC3 (BGR),
/// the same size and type. Throws tbsp::InvalidInput on empty, mismatched or unsupported
/// images and invalid options.
DisparityMap compute_disparity(const cv::Mat& left, const cv::Mat& right, const StereoMatchOptions& options = {});

/// Bad-pixel rate of a disparity map against ground truth, Middlebury style: among pixels whose
/// ground truth is known (gt > 0), the percentage whose disparity is invalid (NaN) or off by more
/// than `threshold` pixels. `gt`: CV_8U or CV_16U with disparity = value / `gt_scale`;
/// `disparity`: CV_32F. Optional `mask` (CV_8U): only pixels with mask > 0 count.
/// Throws InvalidInput on size mismatch or an all-unknown ground truth.
double bad_pixel_rate(const cv::Mat& disparity, const cv::Mat& gt, double gt_scale, double threshold = 1.0,
                      const cv::Mat& mask = cv::Mat());

}  // namespace tbsp
