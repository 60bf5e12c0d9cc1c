#pragma once
/// \file visual_hull.h
/// \brief Visual hull of calibrated silhouettes by voxel carving (Laurentini 1994), with surface
/// samples placed on the silhouette cones, and the registration of a template to it by ICP (the
/// first frame of performance capture, thesis §9.2, when the template is only roughly placed).
///
/// The hull is the set of points that project inside the silhouette of every view. It contains
/// the object and is larger in concavities no view sees into (between the legs of a person seen
/// only from the side, the hollow of a bowl). Computed in two passes:
/// 1. **bounding box**: unless one is given, the box spanned by the camera centres (made cubic:
///    a ring of cameras at one height spans no height) is carved at 48³ with a conservative test
///    — a cell is kept when, in every view, its bounding sphere's image comes within reach of the
///    silhouette (a distance transform of the background); the box of the kept cells is then
///    carved again more finely. When the kept cells touch the box, the box is doubled (at most
///    three times): the object may stick out of it.
/// 2. **voxels**: `resolution` voxels along the longest side of that box; a voxel is occupied
///    when its centre projects inside every silhouette (lens distortion respected). A point that
///    projects outside a camera's image or lies behind it is outside the hull: every camera must
///    see the whole object (or pass a box and crop the silhouettes accordingly).
/// 3. **surface samples**: one per face between an occupied and a free voxel, placed by bisection
///    (10 steps) on the segment between the two voxel centres where the point leaves the hull, so
///    it lies on a silhouette cone to ~1/1000 of a voxel; normal from the gradient of the smoothed
///    occupancy (outward).
///
/// Units: the cameras' world units. Complexity: O(voxels · views) projections (128³ box ~ 0.2 s
/// for 8 views on 2 cores), parallel over slices; deterministic.
/// Errors (tbsp::InvalidInput naming the camera and the fix): no cameras, a silhouette count or
/// size that does not match the cameras, an empty silhouette, silhouettes whose cones do not
/// intersect (calibration or mask error), invalid options.

#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <opencv2/core.hpp>

#include "tbsp/mesh/similarity_icp.h"
#include "tbsp/mesh/tri_mesh.h"
#include "tbsp/multiview/camera.h"

namespace tbsp {

/// Options of compute_visual_hull().
struct VisualHullOptions {
  /// Voxels along the longest side of the hull's bounding box, 16..1024. Memory: one byte per voxel.
  int resolution = 128;
  /// Silhouettes are dilated by this many pixels first (calibration error, anti-aliased masks),
  /// 0..50. 0 = the masks as they are.
  int margin_px = 0;
  /// The box to carve, world units; empty (the default) = found automatically (see the file).
  Eigen::AlignedBox3d box;

  bool isValid(std::string* why = nullptr) const;
};

/// A carved voxel grid and samples of its surface.
struct VisualHull {
  Eigen::Vector3d origin = Eigen::Vector3d::Zero();  ///< centre of voxel (0, 0, 0), world units
  double voxel = 0;                                  ///< voxel edge, world units
  Eigen::Vector3i dims = Eigen::Vector3i::Zero();    ///< voxels per axis
  std::vector<std::uint8_t> occupied;                ///< x fastest, then y, then z; 1 = inside
  Eigen::MatrixX3d points;   ///< surface samples on the silhouette cones
  Eigen::MatrixX3d normals;  ///< outward unit normals of the samples
  int box_doublings = 0;     ///< automatic box: how often it had to grow

  std::size_t index(int x, int y, int z) const { return std::size_t(x) + std::size_t(dims.x()) * (std::size_t(y) + std::size_t(dims.y()) * std::size_t(z)); }
  Eigen::Vector3d center(int x, int y, int z) const { return origin + voxel * Eigen::Vector3d(x, y, z); }
  std::size_t occupiedCount() const;
  /// Occupied volume, world units³.
  double volume() const { return double(occupiedCount()) * voxel * voxel * voxel; }
};

/// \brief Carves the visual hull of `silhouettes` (CV_8U, >= 128 foreground, one per camera, of
/// the calibrated size). See the file comment for the method and errors.
VisualHull compute_visual_hull(const std::vector<Camera>& cameras, const std::vector<cv::Mat>& silhouettes,
                               const VisualHullOptions& options = {});

/// The ICP options register_to_visual_hull uses by default: symmetric, trim 0.2, scale estimated.
SimilarityIcpOptions default_hull_icp_options();

/// Result of register_to_visual_hull().
struct HullRegistration {
  SimilarityIcpResult icp;  ///< template -> world (applied by the caller)
  double iou_before = 0;    ///< mean over views of the silhouette IoU of the template before
  double iou_after = 0;     ///< ... and after the registration
  int hull_points = 0;      ///< surface samples of the hull
  double voxel = 0;         ///< voxel edge of the hull, world units
  double seconds = 0;
};

/// \brief Registers a template roughly in the performer's pose to the visual hull of the
/// silhouettes: symmetric trimmed ICP with scale (similarity_icp, `icp`; default trim 0.2,
/// symmetric — the hull has volume the template lacks and the template has concavities the hull
/// fills) between the template's vertices and the hull's surface samples. Returns the similarity;
/// `mesh` is not changed. The IoU fields compare the template's rendered silhouettes with the
/// input before and after. Starting pose: within ~25° and ~15 % of size of the performer's
/// (measured in docs/performance_capture.md); a performer in another articulation is only
/// brought into place, not re-posed (that is the tracker's first frame).
/// \throws InvalidInput as compute_visual_hull, or for an empty mesh.
HullRegistration register_to_visual_hull(const TriMesh& mesh, const std::vector<Camera>& cameras,
                                         const std::vector<cv::Mat>& silhouettes, const VisualHullOptions& hull_options = {},
                                         const SimilarityIcpOptions& icp = default_hull_icp_options());

}  // namespace tbsp
