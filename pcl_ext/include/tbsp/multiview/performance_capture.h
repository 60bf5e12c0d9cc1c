#pragma once
/// \file performance_capture.h
/// \brief Mesh-based performance capture from multi-view video (thesis §9.2, de Aguiar et al.
/// 2008): a template of the performer, posed like the first frame, is tracked through a
/// calibrated multi-view recording (images + silhouettes); the output is one mesh per frame with
/// the template's connectivity.
///
/// Per frame (an analysis-by-synthesis loop on a tetrahedral version of the template, ch. 7):
/// 1. **features** — SIFT (OpenCV) in every view, inside the silhouette's box; the previous
///    frame's keypoints were lifted onto the previous mesh (the rasterizer's triangle id and
///    barycentrics: a surface point each); matched to this frame's keypoints over time (ratio
///    test, flow gate) and, against drift, to the first frame's lifted keypoints. Every match is a
///    *ray constraint*: the surface point must lie on the camera ray through the matched pixel.
///    Several views see each body part, so the rays of all views together fix it in 3D; there
///    is no explicit cross-view matching (it would add ambiguity, not information).
///    A keypoint matched over time keeps the surface point its track was first lifted to, so the
///    identification does not drift with the mesh; matches whose image motion disagrees with
///    their neighbours' are dropped.
/// 2. **silhouette rims** — rim vertices of the template at its current pose matched to the input
///    contour (§6.3.1: along the contour normal, gradient orientation test) give *plane*
///    constraints (the plane through the camera centre and the contour's tangent: only the
///    contour's normal direction is known, the rim slides along the contour).
/// 3. **pose** — the handle targets (`handles` vertices of the control surface) that best satisfy
///    all constraints, through the TetDeformer's exact linear response to its handles carried to
///    the template by the transfer (TetDeformer::handleResponse), by robust least squares in
///    pixels (Huber, then outliers dropped) with a stiffness term (the membrane energy of the
///    motion the handles cause); then TetDeformer iterations (as-rigid-as-possible, warm-started
///    from the last frame). Repeated `pose_rounds` times, re-linearized each round.
/// 4. **handle optimization** (optional) — the thesis' black-box step: `key_handles` handles
///    are moved by NLopt's BOBYQA to maximize the silhouette overlap, with E_nonrigid (eq. 7.5)
///    and the handle distance as penalties.
/// 5. **transfer** to the full-resolution template (DeformationTransfer, §7.3), then
///    **SilhouetteRefinement** (§6.3) for detail the tetrahedral model cannot carry.
/// The first frame registers the given pose to the silhouettes (rims, 2 × pose_rounds); with
/// `register_to_hull` a similarity to the first frame's visual hull comes before it.
/// Tracking failures (smallest per-view silhouette IoU below `failure_iou`) are reported per
/// frame; a failed frame gets a second, silhouette-only pose pass, and the tracker goes on.
///
/// Units: pixels for image quantities, the cameras' world units for meshes. Errors:
/// InvalidInput naming the frame, camera and fix (no cameras, wrong image/silhouette sizes, empty
/// silhouettes, a template outside every view, bad options); Cancelled via the progress callback.
/// Deterministic: no random choice (SIFT and the optimizer are deterministic; views run in
/// parallel, each on its own data).

#include <memory>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "tbsp/core/progress.h"
#include "tbsp/mesh/tet_mesh.h"
#include "tbsp/mesh/tri_mesh.h"
#include "tbsp/multiview/camera.h"
#include "tbsp/multiview/visual_hull.h"

namespace tbsp {

/// Options of PerformanceCapture. Defaults are what the measurements in
/// docs/performance_capture.md used; none is tuned per sequence.
struct PerformanceCaptureOptions {
  // control model
  int tets = 10000;                ///< tetrahedra of the control mesh (QEM + TetGen), >= 100; 0 = the template as is
  int handles = 150;               ///< handle vertices on the control surface (farthest-point sampled), 4..5000
  double transfer_radius = 0;      ///< DeformationTransfer radius, world units; 0 = automatic
  // pose
  int pose_rounds = 3;             ///< constraint → displacement → deformer rounds per frame, 1..20
  int deformer_iterations = 4;     ///< TetDeformer iterations per round, 1..100
  double smoothness = 0.2;         ///< weight of the handle stiffness (membrane energy of the motion, per template edge, in pixels²), > 0
  double robust_px = 2.0;          ///< Huber scale of the ray residuals, pixels, > 0
  /// Residuals above this after the first solve are outliers (weight 0), pixels, > robust_px.
  /// The matches were already gated (ratio test, flow gate, agreement with their neighbours'
  /// motion), so this only drops what is far off: a low threshold (8 px, measured) drops correct
  /// matches exactly where the model is furthest off and keeps the error there
  /// (docs/dev/performance_capture_experiments.md).
  double reject_px = 40.0;
  // features
  bool features = true;            ///< SIFT feature constraints (false: silhouettes only)
  int max_features = 4000;         ///< SIFT keypoints per view and frame, 100..100000
  double ratio = 0.8;              ///< Lowe's ratio test, (0, 1]
  double max_flow_px = 60;         ///< largest image motion of a feature between frames, pixels, > 0
  bool anchor_first_frame = true;  ///< also match against the first frame's features (limits drift)
  /// Anchors of every view: each view is matched against the first-frame features of all views
  /// whose surface point faces it now (the body turns: a point one camera saw in the first frame
  /// is seen by another later). false: only the same camera's.
  bool anchor_all_views = true;
  /// Weight of a first-frame anchor match relative to a frame-to-frame match, (0, 100]: anchors
  /// are identified on the first frame's model and cannot drift; frame-to-frame tracks start on
  /// the current model and inherit its error.
  double anchor_weight = 4.0;
  /// Keyframe anchors: every this many frames at most, a frame whose worst view IoU reaches
  /// keyframe_iou adds its lifted keypoints to the anchors (with anchor_all_views), so sides of
  /// the performer the first frame did not show get anchors too. 0 = off; 0..10000.
  int keyframe_interval = 0;
  double keyframe_iou = 0.98;      ///< worst view IoU a keyframe needs, (0, 1]
  // silhouettes
  bool silhouettes = true;         ///< rim constraints in the pose step
  double silhouette_weight = 0.5;  ///< weight of a rim constraint relative to a feature, (0, 10]; thesis 0.25–0.5
  double search_px = 25;           ///< rim search along the contour normal, pixels, > 0
  // handle optimization (thesis' black-box step)
  bool optimize_handles = false;   ///< run it (see docs: measured, off by default)
  int key_handles = 20;            ///< handles it moves, 1..100 (thesis: 15–25)
  int max_evaluations = 200;       ///< objective evaluations per frame, >= 10
  double optimize_image_scale = 0.25;  ///< silhouettes are compared at this scale, (0, 1]
  // detail and failure handling
  int refine_iterations = 5;       ///< SilhouetteRefinement iterations per frame (0 = none), 0..100
  /// Model-guided stereo (ModelGuidedStereo, §6.3.3) after the silhouette refinement: detail the
  /// silhouettes cannot see (folds, concavities); needs the images; ~1–2 s per frame. Measured in
  /// docs/performance_capture.md; off by default.
  bool stereo_refine = false;
  double stereo_search_range = 0;  ///< its ± search along each ray, world units, >= 0; 0 = 1 % of the template's bounding-box diagonal
  double failure_iou = 0.85;       ///< a frame whose smallest view IoU is below this is a tracking failure, [0, 1)
  // first frame
  /// Register the template to the first frame's visual hull first (register_to_visual_hull:
  /// symmetric trimmed point-to-plane ICP with scale), so that a template placed only roughly
  /// (within ~25° and ~15 % of size) starts in place. The similarity is applied only when it
  /// raises the mean silhouette IoU of the template by hull_min_iou_gain (a template already in
  /// place is left as given) and the template overlaps the silhouettes at all (one outside every view stays an
  /// error); a hull that cannot be carved (a camera that does not see the whole performer) is
  /// reported and the given pose used. Off: the template is taken as posed.
  bool register_to_hull = true;
  int hull_resolution = 128;       ///< voxels along the longest side of the hull's box, 16..1024
  /// The hull registration is applied only when it raises the template's mean silhouette IoU by
  /// at least this, [0, 1]. Measured: misplaced templates gain 0.2–0.6, templates already in
  /// place -0.03..+0.002 (a 300² studio: +0.002 with a spurious 10° turn).
  double hull_min_iou_gain = 0.02;

  bool isValid(std::string* why = nullptr) const;
};

/// What happened in one frame. Times in seconds.
struct CaptureFrameReport {
  int frame = 0;
  int keypoints = 0;                 ///< SIFT keypoints, all views
  int temporal_matches = 0;          ///< matches to the previous frame's lifted keypoints
  int anchor_matches = 0;            ///< matches to the first frame's (and keyframes') lifted keypoints
  bool keyframe = false;             ///< this frame's keypoints became anchors (keyframe_interval)
  int inliers = 0;                   ///< feature constraints kept by the robust solve (last round)
  int rim_constraints = 0;           ///< last round
  std::vector<double> iou;           ///< per view, of the output mesh
  double iou_min = 0, iou_mean = 0;
  double iou_pose = 0;               ///< mean IoU after the pose step (before optimization/refinement)
  int evaluations = 0;               ///< handle optimization: objective evaluations
  double opt_iou_before = 0, opt_iou_after = 0;  ///< handle optimization: mean IoU of the control surface (downscaled views)
  bool failed = false;               ///< tracking failure detected (iou_min < failure_iou after the retry)
  bool retried = false;              ///< the silhouette-only retry ran
  int stereo_points = 0;             ///< model-guided stereo points used (stereo_refine)
  double t_features = 0, t_match = 0, t_pose = 0, t_optimize = 0, t_transfer = 0, t_refine = 0, t_stereo = 0, t_total = 0;
};

struct PerformanceCaptureReport {
  bool hull_tried = false;           ///< register_to_hull ran; `hull` holds its result
  bool hull_registered = false;      ///< ... and its similarity was applied to the template
  std::string hull_message;          ///< why it was not applied (IoU not raised, or the hull's error)
  HullRegistration hull;             ///< the similarity, IoU before/after, time
  Eigen::Index tet_vertices = 0, tets = 0, surface_vertices = 0, control_surface_vertices = 0;
  int handles = 0;
  bool per_component_tets = false;   ///< TetGen refused the whole template; each connected part was tetrahedralized on its own
  bool shell_tets = false;           ///< TetGen refused even the parts; one tetrahedron per triangle instead
  double t_setup = 0;
  std::vector<CaptureFrameReport> frames;
  int failed_frames = 0;
};

/// \brief The control model PerformanceCapture tracks with (its tets and handles, before any pose).
struct CaptureControlModel {
  TetMesh tets;
  Eigen::MatrixX3i surface;            ///< control surface: faces over the tet vertices
  std::vector<int> surface_vertices;   ///< tet vertices on it, in the order the faces first name them
  std::vector<int> handles;            ///< `handles` farthest-point samples of surface_vertices
  bool per_component = false;          ///< TetGen refused the whole surface: each closed part on its own
  bool shell = false;                  ///< TetGen refused the parts too: one tetrahedron per triangle
};

/// \brief The control model of a template, as PerformanceCapture builds it: `given` tets (their
/// boundary is the control surface), or TetGen to about `tets` tetrahedra (0: the template as
/// is), per closed component when TetGen refuses the whole, else a shell over the template
/// decimated to `tets` faces (a template TetGen refuses: open, or parts modelled as overlapping
/// closed bodies; the shell's apexes are inside, so the decimated surface is the control surface);
/// then `handles` farthest-point samples of the control surface's vertices.
/// \throws Error when even the shell cannot be built.
CaptureControlModel build_capture_control_model(const TriMesh& templ, int tets, int handles, const TetMesh* given = nullptr);

class PerformanceCapture {
public:
  using Ptr = std::shared_ptr<PerformanceCapture>;
  using ConstPtr = std::shared_ptr<const PerformanceCapture>;
  using Options = PerformanceCaptureOptions;

  PerformanceCapture();
  ~PerformanceCapture();
  PerformanceCapture(const PerformanceCapture&) = delete;
  PerformanceCapture& operator=(const PerformanceCapture&) = delete;

  /// Throws InvalidInput naming the field when `o` is not valid. Restarts the tracking.
  void setOptions(const PerformanceCaptureOptions& o);
  const PerformanceCaptureOptions& options() const { return options_; }
  void setProgressCallback(ProgressCallback cb) { progress_ = std::move(cb); }
  /// The calibrated cameras (all frames). Restarts the tracking.
  void setCameras(std::vector<Camera> cameras);
  /// The template, posed like the performer in the first frame that will be given (world
  /// units of the cameras); a closed surface gives a volumetric control mesh. Restarts.
  void setTemplate(const TriMesh& posed);
  /// Same, with a given control tet mesh (same frame as `posed`).
  void setTemplate(const TriMesh& posed, const TetMesh& tets);

  /// Tracks one frame: `images` CV_8UC3 (BGR) or CV_8U per camera, `silhouettes` CV_8U (>= 128
  /// foreground), both of the calibrated size. The first call registers the template to this
  /// frame (silhouettes only; first to its visual hull with `register_to_hull`); later calls
  /// track from the previous one. Frames are consecutive
  /// in time (`frame` is only a label for reports and errors). `out` gets the mesh (template
  /// connectivity); untouched on error.
  void track(const std::vector<cv::Mat>& images, const std::vector<cv::Mat>& silhouettes, int frame, TriMesh& out);

  const PerformanceCaptureReport& report() const { return report_; }
  /// The control tet mesh in its current pose (after the last frame).
  TetMesh controlMesh() const;

private:
  struct Impl;
  void start(const Eigen::Matrix4d* registration = nullptr);
  PerformanceCaptureOptions options_;
  ProgressCallback progress_;
  std::vector<Camera> cameras_;
  TriMesh template_;
  TetMesh template_tets_;
  bool tets_given_ = false;
  bool started_ = false;
  PerformanceCaptureReport report_;
  std::unique_ptr<Impl> impl_;
};

}  // namespace tbsp
