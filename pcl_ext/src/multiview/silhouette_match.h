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

/// Smoothed gradient of a 0/255 CV_8U mask at pixel (x, y) (points from background into the
/// foreground): a 5x5 Gaussian (σ 1.2) then a 3x3 Sobel, both with OpenCV's default border
/// (reflect-101), evaluated at that one pixel from its 7x7 neighbourhood — the value of
/// GaussianBlur + Sobel of the whole image there (to float rounding; computed in double), at a
/// cost independent of the image size. (0, 0) outside the image.
Eigen::Vector2d mask_gradient_at(const cv::Mat& mask, int x, int y);

struct SilhouetteOverlap {
  long xor_px = 0;
  double iou = 0;
};
/// Overlap of a rendered mask (255/0, row-major, the silhouette's size) and an input silhouette (>= 128 foreground).
SilhouetteOverlap silhouette_overlap(const std::vector<std::uint8_t>& rendered, const cv::Mat& input);

/// One view's input silhouette, ready for rim matching and overlap measures.
struct SilhouetteView {
  cv::Mat mask;         ///< CV_8U, 255 foreground
  long foreground = 0;  ///< foreground pixels of `mask`
  void set(const cv::Mat& silhouette);
};

/// The same overlap from a render (its mask and covered box) and a prepared input: only the
/// render's covered box is read (the input's pixels outside it are all in the XOR and the
/// union), so the cost follows the rendered area rather than the image size. Same result.
SilhouetteOverlap silhouette_overlap(const RenderBuffers& rendered, const SilhouetteView& input);

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
