#pragma once
/// \file silhouette_refinement.h
/// \brief Silhouette refinement of a posed mesh (thesis §6.3.1 and §6.3.2): rim vertices of
/// each view are pulled towards the input silhouette's contour, and the Laplacian deformer
/// (ch. 3) carries the rest of the surface along.
///
/// One iteration:
/// 1. render the mesh in every view (Rasterizer) and find its rim vertices (rim_vertices,
///    Fig. 6.2);
/// 2. per rim vertex, search along the image-space normal of the rendered contour (both ways,
///    up to `search_px`) for the nearest contour pixel of the input silhouette whose gradient
///    points the same way (angle < `max_gradient_angle_deg`: the orientation test of §6.3.1);
/// 3. constraint: either the contour point back-projected at the vertex's depth (§6.3.1,
///    position, used when closer than `max_distance_px`), or the ray through it (§6.3.2, eq.
///    6.1, a line constraint weighted to cost 1 per pixel at the vertex's depth); weight
///    `weight` (thesis: 0.25–0.5);
/// 4. solve the Laplacian system of the *current* mesh (L and δ recomputed every iteration, as
///    the thesis does) with those constraints and a tiny anchor to the current positions.
/// Iterates up to `max_iterations` times or until the silhouette mismatch (XOR pixels over all
/// views) stops improving; the best iterate is returned.
///
/// Units: pixels for image distances, world units for the mesh. Errors: InvalidInput naming the
/// camera/frame and the fix (no silhouettes, size mismatch, an empty silhouette, empty mesh, mesh
/// outside every view);
/// Cancelled. The output is untouched on error.

#include <memory>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "tbsp/core/progress.h"
#include "tbsp/mesh/tri_mesh.h"
#include "tbsp/multiview/camera.h"
#include "tbsp/multiview/rasterizer.h"

namespace tbsp {

struct SilhouetteRefinementOptions {
  bool line_constraints = false;       ///< §6.3.2 rays (true) or §6.3.1 back-projected points (false)
  double weight = 0.35;                ///< constraint weight, (0, 10]; thesis 0.25–0.5
  double search_px = 25;               ///< search along the contour normal, pixels, > 0
  double max_distance_px = 20;         ///< ε: farther contour points are not used, pixels, > 0
  double max_gradient_angle_deg = 60;  ///< orientation test, degrees, (0, 180]
  int max_iterations = 20;             ///< 1..100
  double anchor = 1e-6;                ///< tiny pull to the current positions (keeps parts without rims determined), >= 0

  bool isValid(std::string* why = nullptr) const;
};

struct SilhouetteViewReport {
  std::string camera;
  double iou_before = 0, iou_after = 0;  ///< intersection over union of rendered vs input silhouette
  long xor_before = 0, xor_after = 0;    ///< pixels where they differ
  int constraints = 0;                   ///< in the last iteration
};

struct SilhouetteRefinementReport {
  std::vector<SilhouetteViewReport> views;
  int iterations = 0;                    ///< run
  int best_iteration = 0;                ///< the one returned (0 = the input)
  long xor_before = 0, xor_after = 0;    ///< all views
  double seconds = 0;
};

class SilhouetteRefinement {
public:
  using Ptr = std::shared_ptr<SilhouetteRefinement>;
  using ConstPtr = std::shared_ptr<const SilhouetteRefinement>;
  using Options = SilhouetteRefinementOptions;

  void setOptions(const SilhouetteRefinementOptions& o);
  const SilhouetteRefinementOptions& options() const { return options_; }
  void setProgressCallback(ProgressCallback cb) { progress_ = std::move(cb); }
  /// silhouettes: CV_8U per camera (>= 128 foreground), the calibrated size.
  void setInputFrame(std::vector<Camera> cameras, std::vector<cv::Mat> silhouettes, int frame = 0);
  void setInputMesh(const TriMesh& posed) { mesh_ = posed; }
  /// Refines; `refined` keeps the input's connectivity; untouched on error.
  void refine(TriMesh& refined);
  const SilhouetteRefinementReport& report() const { return report_; }

private:
  SilhouetteRefinementOptions options_;
  ProgressCallback progress_;
  std::vector<Camera> cameras_;
  std::vector<cv::Mat> silhouettes_;
  int frame_ = 0;
  TriMesh mesh_;
  SilhouetteRefinementReport report_;
  std::vector<RenderBuffers> buffers_;  // kept between refine() calls: re-used, not re-filled
};

}  // namespace tbsp
