#pragma once
// Internal (not installed): the feature side of PerformanceCapture — SIFT keypoints per view,
// lifted onto a mesh (surface points) and matched to another frame's keypoints.

#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "tbsp/mesh/tri_mesh.h"
#include "tbsp/multiview/camera.h"
#include "tbsp/multiview/rasterizer.h"

namespace tbsp::detail {

/// Keypoint positions (pixels) and SIFT descriptors (CV_32F, one row each) of one view.
struct ViewFeatures {
  std::vector<Eigen::Vector2d> pixel;
  cv::Mat desc;
};

/// SIFT (OpenCV) inside the bounding box of the silhouette grown by 8 pixels, keypoints on the
/// silhouette only; at most `max_features` (the strongest). `image` CV_8UC3 (BGR) or CV_8U.
ViewFeatures detect_features(const cv::Mat& image, const cv::Mat& silhouette, int max_features);

/// A surface point (face, barycentrics) seen at `pixel` (keypoint `keypoint` of the view).
struct FeatureMatch {
  int face = -1;
  Eigen::Vector3d bary;
  Eigen::Vector2d pixel;
  int keypoint = -1;
};

/// Keypoints lifted onto a mesh: the visible surface point under each (triangle + barycentrics
/// from the rasterizer), away from depth discontinuities (a keypoint near an occluding contour
/// is ambiguous and dropped).
struct LiftedFeatures {
  std::vector<int> face;
  std::vector<Eigen::Vector3d> bary;
  cv::Mat desc;
};
/// `inherit` (optional, may be empty): matches of this view's keypoints to earlier lifted ones;
/// such a keypoint keeps the surface point it was first lifted to (a feature track keeps its
/// identity, so the identification does not drift with the mesh) when that point still projects
/// within `inherit_px` of it on `mesh`; otherwise it is lifted afresh. The visible triangle is the
/// buffers' at the keypoint's pixel; with `mesh` and `cam` the barycentrics are those of the
/// keypoint's exact sub-pixel position on that triangle (point_barycentrics; the buffers may then
/// be rendered without barycentrics), otherwise the buffers' at the pixel centre (up to half a
/// pixel off). Without `mesh` and `cam` the buffers must hold barycentrics.
LiftedFeatures lift_features(const ViewFeatures& f, const RenderBuffers& buffers, const std::vector<FeatureMatch>& inherit = {},
                             const TriMesh* mesh = nullptr, const Camera* cam = nullptr, double inherit_px = 2.0);


/// Matches lifted keypoints to a view's keypoints: Lowe's ratio test, a flow gate (the surface
/// point's projection on `mesh` — the current estimate — within `max_flow_px` of the match) and
/// one-to-one (a keypoint matched twice keeps its closest descriptor) and local consistency (a
/// match whose image motion differs from the median motion of its 8 nearest matches by more
/// than 3 px + 25 % is dropped). Appends to `out`.
int match_features(const LiftedFeatures& from, const ViewFeatures& to, const TriMesh& mesh, const Camera& cam, double ratio,
                   double max_flow_px, std::vector<FeatureMatch>& out);

/// The lifted keypoints of all `sets` whose surface point on `mesh` faces `cam` (the angle
/// between the face normal and the direction to the camera below acos(min_cos)), pooled.
LiftedFeatures facing_features(const std::vector<LiftedFeatures>& sets, const TriMesh& mesh, const Camera& cam, double min_cos);

/// No depth discontinuity within 2 pixels of (x, y) (depths within 1 % of the centre's, all
/// covered; false within 2 pixels of the border): a keypoint next to an occluding contour may
/// belong to either side.
bool smooth_depth(const RenderBuffers& b, int x, int y);

/// Position of a surface point on the mesh.
inline Eigen::Vector3d surface_point(const TriMesh& m, int face, const Eigen::Vector3d& b) {
  return b(0) * m.V.row(m.F(face, 0)).transpose() + b(1) * m.V.row(m.F(face, 1)).transpose() + b(2) * m.V.row(m.F(face, 2)).transpose();
}

}  // namespace tbsp::detail
