#pragma once
/// \file rasterizer.h
/// \brief CPU z-buffer rasterizer for calibrated cameras: depth, triangle-id and barycentric
/// buffers, silhouette masks, vertex-coloured or textured colour images and rim vertices
/// (thesis §6.3.1, Fig. 6.2). Written by hand because no Debian library offers an offscreen,
/// GPU-free rasterizer with triangle-id / barycentric output and arbitrary K[R|t] cameras (VTK
/// and OpenGL need a display or EGL and do not give exact ids); it is a few hundred lines.
///
/// Sampling: one sample per pixel at the pixel centre (integer coordinates, see camera.h), the
/// top-left fill rule (no gaps or double coverage on shared edges), perspective-correct depth
/// and barycentrics. Lens distortion moves the vertices; edges stay straight in the distorted
/// image (exact for undistorted cameras, a good approximation for small triangles).
/// Triangles with a vertex behind the near plane are skipped and counted (the studio case
/// has the subject in front of every camera).
///
/// Complexity: O(#faces + covered bounding-box pixels) per view when the buffers are re-used
/// (fresh buffers are first filled: O(pixels)); views run in parallel (OpenMP) in renderViews.
/// Memory: 17 bytes per pixel with barycentrics, 9 without.

#include <cstdint>
#include <vector>

#include <Eigen/Core>

#include "tbsp/mesh/tri_mesh.h"
#include "tbsp/multiview/camera.h"

namespace tbsp {

struct RasterOptions {
  /// Skip triangles facing away from the camera (faster; only for closed, consistently
  /// oriented meshes — an open surface seen from behind would disappear).
  bool cull_backfaces = false;
  /// Fill the barycentric buffer (perspective-correct weights of vertices 1 and 2).
  bool barycentrics = true;
  /// Near plane (camera z); triangles with a vertex at z <= near are skipped.
  double near_plane = 1e-6;
};

/// The buffers of one view. Row-major, index = y * width + x.
struct RenderBuffers {
  int width = 0, height = 0;
  std::vector<float> depth;        ///< camera z of the visible surface; +inf where empty
  std::vector<std::int32_t> face;  ///< visible triangle index; -1 where empty
  std::vector<float> bary;         ///< 2 per pixel: (b1, b2), b0 = 1 - b1 - b2; 0 where empty (empty vector if not requested)
  std::vector<std::uint8_t> mask;  ///< 255 where the mesh covers the pixel centre, else 0
  int skipped_near = 0;            ///< triangles skipped because they cross the near plane
  /// Bounding box of the covered pixels, inclusive; empty (box_x1 < box_x0) when none is.
  /// A render into buffers that already have the camera's size resets only this box, since
  /// the renderer wrote nothing outside it (for a performer filling a tenth of a 1004² view,
  /// 9 MB less to write per view and render). Code that writes into the buffers itself must
  /// call markAllDirty() before rendering into them again.
  int box_x0 = 0, box_y0 = 0, box_x1 = -1, box_y1 = -1;
  void markAllDirty() {
    box_x0 = 0;
    box_y0 = 0;
    box_x1 = width - 1;
    box_y1 = height - 1;
  }

  bool covered(int x, int y) const { return face[static_cast<std::size_t>(y) * width + x] >= 0; }
  // As OpenCV images (mask, depth, shaded colour): tbsp/io/render_images.h (tbsp_capture_io),
  // which keeps OpenCV out of this library's headers.
};

class Rasterizer {
public:
  explicit Rasterizer(RasterOptions options = {}) : options_(options) {}
  const RasterOptions& options() const { return options_; }

  /// Renders one view. Throws tbsp::InvalidInput on an empty mesh or bad face indices.
  void render(const TriMesh& mesh, const Camera& camera, RenderBuffers& out) const;
  /// Renders all views in parallel (one view per thread).
  std::vector<RenderBuffers> renderViews(const TriMesh& mesh, const std::vector<Camera>& cameras) const;
  /// Same, re-using `out`'s buffers (no allocation when the sizes are unchanged): the form for
  /// per-frame loops (tracking, silhouette refinement).
  void renderViews(const TriMesh& mesh, const std::vector<Camera>& cameras, std::vector<RenderBuffers>& out) const;

private:
  void renderChecked(const TriMesh& mesh, const Camera& camera, RenderBuffers& out) const;
  RasterOptions options_;
};

/// Perspective-correct barycentrics (b0, b1, b2) of triangle `face` at the centre of pixel (x, y)
/// of `camera`: what a render with `RasterOptions::barycentrics` stores there when that triangle
/// is the visible one (the same projection and formula, b1 and b2 rounded to float as stored,
/// b0 = 1 − b1 − b2). For callers that need them at a few pixels (keypoint lifting) and so can
/// render without the buffer's 8 bytes per pixel. O(1).
/// \throws InvalidInput for a face index outside the mesh or a vertex of it not in front of the
/// camera (such a triangle is never rendered).
Eigen::Vector3d pixel_barycentrics(const TriMesh& mesh, const Camera& camera, int face, int x, int y);

/// Perspective-correct barycentrics (b0, b1, b2) of triangle `face` at the sub-pixel image point
/// `p` of `camera` (pixel centres at integer coordinates, as Camera::project): the point of the
/// triangle's plane that projects to `p`. Outside the triangle some coordinates are negative (the
/// plane extended). For lifting a keypoint at its exact position rather than at the centre of
/// its pixel (up to half a pixel apart). O(1). \throws InvalidInput as pixel_barycentrics.
Eigen::Vector3d point_barycentrics(const TriMesh& mesh, const Camera& camera, int face, const Eigen::Vector2d& p);

/// Rim vertices of one view (§6.3.1, Fig. 6.2): vertices on the contour generator (incident to
/// a front- and a back-facing triangle) that are visible and project within `tolerance_px`
/// pixels of the outer border of the rendered silhouette (a covered pixel with an uncovered
/// 4-neighbour). Sorted vertex indices.
std::vector<int> rim_vertices(const TriMesh& mesh, const Camera& camera, const RenderBuffers& buffers,
                              double tolerance_px = 1.0);

}  // namespace tbsp
