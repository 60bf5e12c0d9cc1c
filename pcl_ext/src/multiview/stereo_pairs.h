#pragma once
// Internal to tbsp_multiview: pair selection and pairwise depth maps of StereoFusionEngine.

#include <string>
#include <utility>
#include <vector>

#include <opencv2/core.hpp>

#include "tbsp/multiview/stereo_depth_fusion.h"

namespace tbsp::stereo_detail {

/// Unordered pairs (i < j): each view with its `partners` nearest views by viewing-direction
/// angle within the option's bounds. Sorted, deterministic.
std::vector<std::pair<int, int>> select_pairs(const std::vector<Camera>& cameras, const StereoFusionOptions& o);

/// Result of matching one pair: two depth maps (reference i, then j), or a skip reason.
struct PairDepth {
  ViewDepth first, second;
  std::string skipped;  ///< non-empty: why the pair made no depth (no overlap, ...)
  double seconds_rectify = 0, seconds_match = 0;
};

/// Rectifies, finds the disparity range, matches and converts to depth maps in each camera's
/// own pixel grid at o.image_scale. `sil_*` may be empty (no mask).
PairDepth match_pair(const Camera& ci, const Camera& cj, int i, int j, const cv::Mat& img_i, const cv::Mat& img_j,
                     const cv::Mat& sil_i, const cv::Mat& sil_j, const StereoFusionOptions& o);

}  // namespace tbsp::stereo_detail
