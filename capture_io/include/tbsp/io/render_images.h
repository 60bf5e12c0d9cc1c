#pragma once
/// \file render_images.h
/// \brief The rasterizer's buffers (tbsp/multiview/rasterizer.h) as OpenCV images: silhouette
/// mask, depth, vertex-coloured and textured colour images. In tbsp_capture_io so that the
/// library tbsp itself has no OpenCV in its headers.

#include <opencv2/core.hpp>

#include "tbsp/multiview/rasterizer.h"

namespace tbsp {

/// The silhouette as an 8-bit single-channel image (255 covered, 0 empty; a copy).
cv::Mat mask_image(const RenderBuffers& buffers);
/// Depth as a 32-bit float image (camera z; +inf where empty; a copy).
cv::Mat depth_image(const RenderBuffers& buffers);

/// Colour image (CV_8UC3, BGR) from per-vertex colours (mesh.C, 0..1 RGB, n x 3) interpolated
/// with the barycentrics; background colour elsewhere. Needs buffers with barycentrics.
cv::Mat shade_vertex_colors(const TriMesh& mesh, const RenderBuffers& buffers,
                            const cv::Vec3b& background = {0, 0, 0});

/// Textured colour image (CV_8UC3, BGR): per-vertex texture coordinates uv (n x 2, OBJ
/// convention: u right, v up, [0,1]) interpolated perspective-correctly, bilinear lookup in
/// `texture` (CV_8UC3), wrapping outside [0,1]. Needs buffers with barycentrics.
cv::Mat shade_texture(const TriMesh& mesh, const Eigen::MatrixX2d& uv, const cv::Mat& texture,
                      const RenderBuffers& buffers, const cv::Vec3b& background = {0, 0, 0});

}  // namespace tbsp
