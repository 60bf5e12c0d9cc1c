#pragma once
/// \file model_guided_stereo.h
/// \brief Model-guided multi-view stereo refinement of a posed mesh (thesis §6.3.3, after
/// Goesele et al. 2006): the mesh gives each pixel an initial depth and a normal; the depth is
/// searched within ±`search_range` along the pixel's ray for the best photo-consistency of a
/// small patch tangent to the mesh, seen by the other cameras; distinct maxima become a point
/// cloud, and the cloud becomes low-weight position constraints of the template fit (§5.3 — the
/// fitting code's matching and solver, fit_template, with the mesh's connectivity kept).
///
/// Per view (views in parallel), at `image_scale` of the images:
/// 1. render the mesh (Rasterizer): depth d0 and face normal n per pixel; every
///    `pixel_stride`-th covered pixel (inside the silhouette when given) is a sample;
/// 2. for depths d0 + t, t in [-search_range, +search_range] (`depth_samples` steps), a
///    `patch_size`² patch on the plane through the point with normal n (one reference pixel per
///    patch step) is projected into the reference view and into every other view where the
///    patch faces the camera (angle < `max_view_angle_deg`) and the mesh does not hide it;
///    score = mean normalised cross-correlation (grey levels, bilinear) over those views;
/// 3. the best t is kept when its score is >= `min_ncc`, at least `min_views` other views took
///    part, and it beats the best score outside ±2 steps by `distinct_margin` (a distinct
///    maximum); then the patch normal is also tried tilted by `normal_tilt_deg` in 8 directions
///    at that depth, the best-correlating orientation kept (the point's normal) and the depth
///    searched again ±2 steps with it; parabolic sub-step refinement;
/// 4. a depth is kept when `min_agreeing_views` other views' searches found the same surface.
/// Then fit_template(mesh, cloud, no markers, no alignment) with match_weight =
/// `constraint_weight`, max_match_distance = search_range and no scale estimation refines the
/// mesh, and `detail_rounds` detail rounds bring back the folds the low-weight fit smooths over
/// (one search, one fit: alternating them measured worse, docs/stereo.md).
///
/// Units: world units of the cameras (search_range default 0.02 = 2 cm for metres). Errors:
/// InvalidInput naming the frame/camera and the fix (image size ≠ calibration, fewer than 2
/// views, an empty mesh, a mesh outside every view); Cancelled from the progress callback.

#include <memory>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "tbsp/core/progress.h"
#include "tbsp/fitting/template_fitter.h"
#include "tbsp/mesh/tri_mesh.h"
#include "tbsp/multiview/camera.h"

namespace tbsp {

struct ModelGuidedStereoOptions {
  double search_range = 0.02;      ///< ± search along each ray, world units, > 0 (thesis: 2 cm)
  int depth_samples = 21;          ///< samples over the range, 5..201
  int patch_size = 5;              ///< l of the l×l patch, odd, 3..15
  double image_scale = 0.5;        ///< matching resolution relative to the images, (0, 1]
  int pixel_stride = 2;            ///< every n-th pixel (at image_scale) is searched, 1..16
  double min_ncc = 0.6;            ///< mean NCC of an accepted depth, (-1, 1)
  double distinct_margin = 0.05;   ///< the maximum must beat the rest of the range by this, >= 0
  int min_views = 2;               ///< other views that must see the patch, >= 1
  double max_view_angle_deg = 70;  ///< patch normal vs direction to a camera, (0, 90)
  /// Patch orientation search: at the depth maximum the mesh normal is also tried tilted by this
  /// angle in 8 directions, and the best-correlating orientation is kept (it becomes the point's
  /// normal); degrees, [0, 60), 0 = the mesh normal only.
  double normal_tilt_deg = 20;
  bool use_silhouettes = true;     ///< search only pixels inside the view's silhouette (when given)
  /// Cross-view consistency: other views whose own search found the same depth (within two
  /// depth steps) near the point's projection, >= 0 (0 = off). Default 1.
  int min_agreeing_views = 1;
  /// Weight of the stereo constraints in the fit (§6.3.3: lower than data of a scan), (0, 10].
  double constraint_weight = 0.3;
  int fit_iterations = 10;         ///< iterations of the §5.3 fit, 1..100
  /// Detail rounds after the fit (FitParameters::detail_rounds: residual matching with the
  /// Laplacian re-based on the fitted surface), 0..10. They bring back folds the low-weight fit
  /// smooths over (docs/stereo.md); 0 = the fit alone.
  int detail_rounds = 1;

  bool isValid(std::string* why = nullptr) const;
};

struct ModelGuidedStereoReport {
  int views = 0;
  std::vector<int> samples_per_view, points_per_view;
  long samples = 0, points = 0;
  double mean_score = 0;                ///< mean NCC of the accepted depths
  double mean_vertex_move = 0, max_vertex_move = 0;
  FitReport fit;                        ///< the refinement fit
  double seconds_stereo = 0, seconds_fit = 0, seconds_total = 0;
};

class ModelGuidedStereo {
public:
  using Ptr = std::shared_ptr<ModelGuidedStereo>;
  using ConstPtr = std::shared_ptr<const ModelGuidedStereo>;
  using Options = ModelGuidedStereoOptions;

  void setOptions(const ModelGuidedStereoOptions& o);
  const ModelGuidedStereoOptions& options() const { return options_; }
  void setProgressCallback(ProgressCallback cb) { progress_ = std::move(cb); }
  /// images: 8-bit BGR or grey per camera (calibrated size); silhouettes: empty or one CV_8U per
  /// camera (empty Mat = none). `frame` names the frame in errors.
  void setInputFrame(std::vector<Camera> cameras, std::vector<cv::Mat> images, std::vector<cv::Mat> silhouettes = {}, int frame = 0);
  void setInputMesh(const TriMesh& posed) { mesh_ = posed; }

  /// Stereo points (the photo-consistency maxima) and their normals (the best patch orientation), without
  /// refining: the first half of refine().
  void computeCloud(Eigen::MatrixX3d& points, Eigen::MatrixX3d& normals);
  /// Stereo points, then the fit. `refined` has the input mesh's connectivity; untouched on error.
  void refine(TriMesh& refined);

  const ModelGuidedStereoReport& report() const { return report_; }

private:
  void computeCloud(Eigen::MatrixX3d& points, Eigen::MatrixX3d& normals, const ProgressCallback& progress);
  ModelGuidedStereoOptions options_;
  ProgressCallback progress_;
  std::vector<Camera> cameras_;
  std::vector<cv::Mat> images_, silhouettes_;
  int frame_ = 0;
  TriMesh mesh_;
  ModelGuidedStereoReport report_;
};

/// Refines a posed mesh towards a point cloud with the §5.3 fit as low-weight constraints (no
/// markers, no scale, connectivity kept), then `detail_rounds` detail rounds: the step
/// ModelGuidedStereo::refine ends with, usable with any cloud (e.g. StereoDepthFusion's). Uses
/// the options' constraint_weight, search_range (as the match distance), fit_iterations and
/// detail_rounds. Returns the fit's report. Throws InvalidInput on an empty cloud.
FitReport refine_mesh_to_cloud(const TriMesh& mesh, const Eigen::MatrixX3d& points, const Eigen::MatrixX3d& normals,
                               const ModelGuidedStereoOptions& options, TriMesh& refined, const ProgressCallback& progress = {});

}  // namespace tbsp
