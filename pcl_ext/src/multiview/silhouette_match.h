#pragma once
// Internal (not installed): the silhouette pieces shared by SilhouetteRefinement and
// PerformanceCapture — input checks, overlap measures and the rim-to-contour matching of
// §6.3.1 (closest input contour point along the rendered contour's normal, with the gradient
// orientation test).

#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "tbsp/mesh/tri_mesh.h"
#include "tbsp/multiview/camera.h"
#include "tbsp/multiview/rasterizer.h"

namespace tbsp::detail {

/// Throws InvalidInput (prefixed by `where`) unless there is one 8-bit, calibrated-size,
/// non-empty silhouette per camera.
void check_silhouettes(const std::vector<Camera>& cameras, const std::vector<cv::Mat>& silhouettes, const std::string& where);

/// Smoothed mask gradient (points from background into the foreground), CV_32F.
void mask_gradient(const cv::Mat& mask, cv::Mat& gx, cv::Mat& gy);

struct SilhouetteOverlap {
  long xor_px = 0;
  double iou = 0;
};
/// Overlap of a rendered mask (255/0, row-major, the silhouette's size) and an input silhouette (>= 128 foreground).
SilhouetteOverlap silhouette_overlap(const std::vector<std::uint8_t>& rendered, const cv::Mat& input);

/// One view's input silhouette with its gradient, ready for rim matching.
struct SilhouetteView {
  cv::Mat mask;    ///< CV_8U, 255 foreground
  cv::Mat gx, gy;  ///< mask_gradient(mask)
  void set(const cv::Mat& silhouette);
};

struct RimMatchOptions {
  double search_px = 25;        ///< search along the contour normal, both ways
  double max_distance_px = 20;  ///< ε: farther contour points are not used
  double cos_max = 0.5;         ///< cosine of the largest gradient angle (orientation test)
};

struct RimMatch {
  int vertex = -1;
  Eigen::Vector2d pixel;  ///< the matched input contour point
  double distance_px = 0; ///< |pixel - projection of the vertex|
  Eigen::Vector2d normal; ///< unit normal of the input contour at `pixel` (its gradient direction)
};

/// Rim vertices of `mesh` in view `cam` (rendered into `buffers`) matched to the input contour.
std::vector<RimMatch> match_rims(const TriMesh& mesh, const Camera& cam, const RenderBuffers& buffers, const SilhouetteView& input,
                                 const RimMatchOptions& o);

}  // namespace tbsp::detail
