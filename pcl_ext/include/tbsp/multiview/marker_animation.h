#pragma once
/// \file marker_animation.h
/// \brief Marker-driven animation of a template (thesis §6.2, §9.1): motion-capture marker
/// trajectories move handles of a tetrahedral version of the template (TetDeformer, ch. 7), and
/// the full-resolution surface follows by DeformationTransfer (§7.3).
///
/// Setup (start()):
/// 1. the marker map names, for each marker used, the template vertex it sits on (or a point
///    inside the template: a joint centre);
/// 2. the template is aligned to the first frame by a similarity fit (Umeyama: rotation,
///    uniform scale, translation) of the mapped vertices with `align` set to their markers
///    (markers on parts whose pose differs from the template's — a raised arm — are left out
///    of the alignment by the map); the output lives in the markers' frame and units;
/// 3. the aligned template is tetrahedralized to about `tets` tetrahedra (QEM decimation +
///    TetGen, tetrahedralize_to_size) unless a tet mesh is given — a surface TetGen rejects
///    (open, self-intersecting) gets one tetrahedron per triangle instead (surface_to_tets,
///    reported) —, and the transfer
///    coefficients of the surface against it are precomputed.
///
/// Per frame (next()): every marker present becomes a point handle (§7.2.3) at its mapped
/// vertex's rest position with the marker as target; `iterations` TetDeformer iterations,
/// warm-started from the previous frame's rotations; transfer to the surface. A marker missing
/// in a frame (a gap: NaN) is dropped for that frame, not zeroed: the deformer for that set of
/// present markers is built (one sparse Cholesky; up to 8 sets are kept) and iterated
/// `start_iterations` times from the rest state the first time the set occurs. Residual =
/// distance of each used marker to its vertex on the output surface (to its point carried by the
/// transfer, for interior points).
///
/// Units: those of the markers (C3D is usually mm). Errors (InvalidInput): a map entry naming a
/// marker the trajectories do not have or a vertex the template does not have (or, for
/// vertex -1, a non-finite point), fewer than 3
/// alignment markers present in the first frame, a rigid region naming a missing vertex or
/// covering no tetrahedron, an invalid template or options.

#include <Eigen/Core>
#include <limits>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "tbsp/core/progress.h"
#include "tbsp/mesh/tet_mesh.h"
#include "tbsp/mesh/tri_mesh.h"
#include "tbsp/multiview/camera.h"

namespace tbsp {

/// One marker of the map: the template vertex it sits on, or a point of the template's volume
/// (a joint centre, for markers triangulated from image clicks: triangulate_image_markers).
struct MarkerMapEntry {
  std::string marker;  ///< name in the trajectories (C3D/TRC label)
  int vertex = -1;     ///< template surface vertex, 0..#V-1; -1: the marker sits at `point`
  bool align = true;   ///< used by the first-frame similarity alignment
  /// Used when vertex = -1: template rest coordinates of a point inside the closed template (a
  /// TetDeformer point handle, §7.2.3); carried to the output by the transfer.
  Eigen::Vector3d point = Eigen::Vector3d::Constant(std::numeric_limits<double>::quiet_NaN());
};

/// One marker observed in calibrated images (hand-placed clicks, detections): the pixels per
/// camera name. triangulate_image_markers() turns a set of them into marker positions.
struct ImageMarker {
  std::string marker;
  std::map<std::string, Eigen::Vector2d> pixels;  ///< camera name -> pixel (x right, y down)
};
/// A triangulated image marker.
struct TriangulatedMarker {
  std::string marker;
  Eigen::Vector3d position = Eigen::Vector3d::Zero();  ///< world units of the cameras
  int views = 0;                                       ///< observations used
  double rms_px = 0;                                   ///< reprojection error over them, pixels
};
/// Triangulates each marker from its pixels (DLT + Gauss-Newton on the reprojection error,
/// distortion respected: tbsp::triangulate). \throws InvalidInput naming the marker when it has
/// fewer than 2 views, names a camera not in `cameras` (listing them), has a non-finite pixel, or
/// triangulates behind a camera that sees it.
std::vector<TriangulatedMarker> triangulate_image_markers(const std::vector<Camera>& cameras,
                                                          const std::vector<ImageMarker>& markers);

struct MarkerAnimationOptions {
  /// Target tetrahedron count of the control mesh when no tet mesh is given, >= 100 or 0 (=
  /// tetrahedralize the template at full resolution). Default 5000.
  Eigen::Index tets = 5000;
  int iterations = 3;         ///< TetDeformer iterations per frame (warm-started), 1..100
  int start_iterations = 40;  ///< iterations the first time a set of present markers occurs, 1..1000
  double transfer_radius = 0; ///< DeformationTransfer radius (marker units); 0 = 5 % of the tet mesh's diagonal
  bool align = true;          ///< similarity-align the template to the first frame (else: already in place)

  bool isValid(std::string* why = nullptr) const;
};

/// What one frame did.
struct MarkerFrameReport {
  int frame = 0;                        ///< index into the trajectories (0-based)
  int markers_used = 0;
  std::vector<std::string> missing;     ///< mapped markers with a gap in this frame
  double median_residual = 0, max_residual = 0;  ///< marker to its vertex on the output surface
  bool rebuilt = false;                 ///< a deformer was built for this set of present markers
  double seconds_deform = 0, seconds_transfer = 0;
};

struct MarkerAnimationReport {
  Eigen::Matrix4d alignment = Eigen::Matrix4d::Identity();  ///< template -> marker frame (similarity)
  double scale = 1.0;                   ///< its uniform scale
  double alignment_rms = 0;             ///< rms distance of the alignment markers after it
  int alignment_frame = 0;              ///< frame whose markers were used
  Eigen::Index tet_vertices = 0, tets = 0, surface_vertices = 0;
  /// The template could not be tetrahedralized (open, non-manifold or self-intersecting): the
  /// control mesh is one tetrahedron per triangle (surface_to_tets, §10.8); the reason.
  bool shell_tets = false;
  std::string tetrahedralize_error;
  int deformers_built = 0;
  std::vector<int> rigid_region_tets;   ///< tetrahedra per rigid region
  double seconds_setup = 0;
  std::vector<MarkerFrameReport> frames;
};

class MarkerAnimation {
public:
  using Ptr = std::shared_ptr<MarkerAnimation>;
  using ConstPtr = std::shared_ptr<const MarkerAnimation>;
  using Options = MarkerAnimationOptions;

  MarkerAnimation();
  ~MarkerAnimation();
  MarkerAnimation(const MarkerAnimation&) = delete;
  MarkerAnimation& operator=(const MarkerAnimation&) = delete;

  /// \throws InvalidInput when !o.isValid().
  void setOptions(const MarkerAnimationOptions& o);
  const MarkerAnimationOptions& options() const { return options_; }
  void setProgressCallback(ProgressCallback cb) { progress_ = std::move(cb); }

  /// The template surface (rest pose, any units); tetrahedralized by start().
  void setTemplate(const TriMesh& surface);
  /// The template surface and its control tet mesh (same rest pose and units).
  void setTemplate(const TriMesh& surface, const TetMesh& tets);
  void setMarkerMap(std::vector<MarkerMapEntry> map) { map_ = std::move(map); started_ = false; }
  /// Trajectories: names (one per marker) and data (#frames x 3·#markers, NaN = gap).
  void setMarkers(std::vector<std::string> names, Eigen::MatrixXd data);
  /// Optional rigid regions (§7.2: TetDeformer rigid regions), each a set of template vertices;
  /// the control mesh's tetrahedra nearest to them move as one rigid body (e.g. the head, whose
  /// markers then cannot squash it).
  void setRigidRegions(std::vector<std::vector<int>> vertex_sets) { rigid_sets_ = std::move(vertex_sets); started_ = false; }
  /// Points to follow besides the surface (template rest coordinates; e.g. joint centres inside
  /// the body): carried by the tet deformation through the same transfer. Optional.
  void setTrackedPoints(const Eigen::MatrixX3d& rest_points) { tracked_rest_ = rest_points; started_ = false; }
  /// Positions of the tracked points at the last frame next() produced (marker units).
  const Eigen::MatrixX3d& trackedPoints() const { return tracked_; }

  /// Validates, aligns, tetrahedralizes, precomputes the transfer. Called by the first next().
  void start();
  int numFrames() const { return static_cast<int>(data_.rows()); }
  /// Deforms the next frame into `surface` (the template's connectivity); false after the last.
  bool next(TriMesh& surface);
  /// The aligned template (valid after start()).
  const TriMesh& alignedTemplate() const { return surface_; }
  const MarkerAnimationReport& report() const { return report_; }

private:
  struct Deformer;
  Deformer& deformerFor(const std::vector<int>& present, bool& built);

  MarkerAnimationOptions options_;
  ProgressCallback progress_;
  TriMesh template_, surface_;  ///< as given; aligned (working copy)
  TetMesh template_tets_, tets_;
  bool tets_given_ = false, started_ = false;
  std::vector<MarkerMapEntry> map_;
  std::vector<std::string> names_;
  Eigen::MatrixXd data_;
  std::vector<int> column_;  ///< per map entry: marker index in the trajectories
  Eigen::MatrixX3d tracked_rest_, tracked_;
  std::vector<std::vector<int>> rigid_sets_, rigid_tets_;
  int next_frame_ = 0;
  struct Impl;
  std::unique_ptr<Impl> impl_;
  MarkerAnimationReport report_;
};

/// What pose_template_to_image_markers did.
struct ImagePoseReport {
  std::vector<TriangulatedMarker> markers;  ///< triangulated, in the order of `image_markers`
  MarkerAnimationReport animation;          ///< alignment (scale, rms), control mesh, one frame (residuals, times)
};

/// Poses a template by markers placed in calibrated images (hand clicks, detections; thesis §6.2
/// with markers from images): triangulates `image_markers` (triangulate_image_markers), then one
/// MarkerAnimation frame — similarity alignment on the `align` entries, `o.start_iterations`
/// TetDeformer iterations with a point handle per marker, transfer to the surface. `map` holds
/// the template side of every image marker (by name: a vertex or an interior point); entries
/// without pixels are ignored. `rigid`: optional rigid regions (template vertex sets).
/// \returns the posed surface (the template's connectivity, the cameras' world frame and units).
/// \throws InvalidInput (naming the marker) from the triangulation, for an image marker the map
/// does not name, for fewer than 3 image markers, and from MarkerAnimation.
TriMesh pose_template_to_image_markers(const TriMesh& tmpl, const std::vector<MarkerMapEntry>& map,
                                       const std::vector<ImageMarker>& image_markers, const std::vector<Camera>& cameras,
                                       const MarkerAnimationOptions& o = {}, const std::vector<std::vector<int>>& rigid = {},
                                       ImagePoseReport* report = nullptr);

}  // namespace tbsp
