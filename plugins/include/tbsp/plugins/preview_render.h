#pragma once
/// \file preview_render.h
/// \brief Quick CPU preview renders of meshes to PNG (orthographic, flat Lambert shading,
/// painter's algorithm via OpenCV). For looking at results from the CLI and in tests; the
/// studio-grade rasterizer with depth/id buffers is pcl_ext/multiview (see issue 6).

#include <string>
#include <utility>
#include <vector>

#include "tbsp/mesh/tri_mesh.h"

namespace tbsp {

struct RenderPanel {
  RenderPanel() = default;
  RenderPanel(TriMesh m, std::string t) : mesh(std::move(m)), title(std::move(t)) {}
  TriMesh mesh;                 ///< if mesh.C is set (#V by 3 in [0,1]) faces use those colours
  std::string title;
  Eigen::MatrixX3d points;      ///< optional point cloud drawn as dots (e.g. the input scan)
  Eigen::MatrixX3d point_colors;  ///< optional, one row per point in [0,1]
  /// optional colour bar under the panel: the colormap() scale from `lo` to `hi`, labelled
  /// (e.g. "distance to scan, % of diagonal"); drawn when `colorbar` is true
  bool colorbar = false;
  double colorbar_lo = 0, colorbar_hi = 1;
  std::string colorbar_label;
};

struct RenderOptions {
  int panel_width = 480, panel_height = 480;
  double azimuth_deg = 30, elevation_deg = 20;  ///< view direction
  bool shared_frame = true;                     ///< all panels use one bounding box (fair comparisons)
};

/// \brief Renders the panels side by side into one PNG, written atomically: faces shaded
/// (back faces tinted), points as dots (shaded by depth), optional colour bars. Every panel's
/// content fits its frame (8 % margin). \throws FileError.
void render_panels_png(const std::string& path, const std::vector<RenderPanel>& panels, const RenderOptions& o = {});

/// \brief Maps scalar values to colours (blue → green → yellow → red) over [lo, hi].
Eigen::MatrixX3d colormap(const Eigen::VectorXd& values, double lo, double hi);

}  // namespace tbsp
