#pragma once
/// \file texture_preview.h
/// \brief Preview renders of inverse-texture-mapping results (tbsp::InverseTextureMapping):
/// the mesh textured through its per-vertex UVs next to the deformed image surface, looked at
/// head-on. Used by `tbsp texture --render` and the tests.

#include <cstdint>
#include <string>
#include <vector>

#include "tbsp/fitting/inverse_texture_mapping.h"
#include "tbsp/mesh/tri_mesh.h"

namespace tbsp {

/// An 8-bit RGB image, row-major, 3 bytes per pixel.
struct RgbImage {
  int width = 0, height = 0;
  std::vector<std::uint8_t> rgb;
  /// Bilinear colour in [0,1] at a pixel position (x right, y down, centres at integers),
  /// clamped to the image.
  Eigen::RowVector3d at(double x, double y) const;
};

/// Reads a PNG/JPEG (OpenCV). \throws FileError naming the file when it cannot be decoded.
RgbImage read_rgb_image(const std::string& path);

/// A coloured checkerboard (cells of `cell` pixels; red grows to the right, blue downwards,
/// dark cells darker) — a test texture that shows stretch, shear and flips at a glance.
RgbImage checkerboard_image(int width, int height, int cell);

/// The mesh cut into small triangles — each face with three finite UVs split n×n, positions and
/// UVs interpolated, n chosen so that about `max_faces` faces result — coloured from the image.
/// Faces without UVs stay whole and grey. For flat-shaded previews.
TriMesh textured_preview_mesh(const TriMesh& mesh, const Eigen::MatrixX2d& uv_pixels, const RgbImage& image, long max_faces = 400000);

/// Writes a two-panel PNG (atomically): the textured mesh and the deformed image surface
/// coloured by its pixels, seen along the mean normal of the textured faces with the image's
/// "up" (decreasing pixel y) pointing up. \throws FileError.
void render_texture_result_png(const std::string& path, const TriMesh& mesh, const TextureMappingResult& result, const RgbImage& image,
                               int panel_size = 560);

}  // namespace tbsp
