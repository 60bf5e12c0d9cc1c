#pragma once
/// \file inverse_texture_mapping.h
/// \brief tbsp::InverseTextureMapping: constrained texture mapping without a parameterization
/// (thesis ch. 4). The image is a planar template — one grid node per pixel (or per s×s pixels
/// for large images) — that is deformed onto the target mesh; any manifold mesh, any genus,
/// no cutting.
///
/// \code
/// tbsp::InverseTextureMapping itm;
/// itm.setInputMesh(mesh);                        // tbsp::TriMesh (or pcl::PolygonMesh via pcl_conversions)
/// itm.setImageSize(1024, 768);                   // pixels; optional setMask() for sewing patterns
/// itm.setConstraints({{{512, 300}, 1234}, ...}); // pixel (x right, y down) <-> vertex, >= 3
/// tbsp::TextureMappingResult r = itm.compute();
/// // r.uv: per-vertex pixel coordinates (NaN where unmatched); r.surface: the deformed image
/// // surface (grid nodes in mesh units); r.report: residuals, matched fraction, distortion, timings
/// \endcode
///
/// Stages (timed separately in the report, the columns of Table 4.1):
/// 1. **deform 1** (§4.1, eq. 4.1): the grid is bent onto the k constraints by minimizing the
///    discrete thin-plate energy of the node positions (second differences, per-pixel units)
///    plus ω²·Σ|x(s_i) − q_i|². Departure from the thesis, which uses the uniform Laplacian with
///    δ = 0: that energy also pulls the image border inwards (the boundary rows of the uniform
///    Laplacian are not zero on a flat grid); the thin-plate form has the same interior
///    behaviour (∫(Δx)² and ∫|∇²x|² differ by boundary terms only) and exactly the affine maps
///    as its null space, so an undistorted image stays undistorted. Solved on the geodesic grid
///    (≤ `max_geodesic_nodes`) and bilinearly up-sampled to the solve grid: it only carries the
///    texture geodesics, and the thin-plate solution is smooth.
/// 2. **mesh geodesics**: distances from each constraint over the mesh (heat method,
///    heat_geodesics.h; all k sources share one factorization). Mesh and image fields use the
///    same heat time (the coarser surface's squared mean edge length × heat_time_factor).
/// 3. **texture geodesics**: the same on the deform-1 surface of the geodesic grid
///    (triangulated), sources spread bilinearly.
///    With MatchDistance::ImagePlane the flat-image (Euclidean) distances are used instead —
///    the Fig. 4.7 baseline.
/// 4. **matching** (§4.2, eq. 4.2): every free mesh vertex is matched to the grid position whose
///    k-vector of distances is nearest (nanoflann k-d tree in k dimensions, refined to sub-node
///    precision by Gauss-Newton on the bilinear distance field), accepted when the difference is
///    below ε = `epsilon_factor` · bbox diagonal · k. Mismatch detection: where the ratio of mesh
///    to image distances between two constraints a, b leaves [0.8, 1.25], channel b is dropped
///    for the vertices and pixels whose nearest constraint is a. Matches on the outermost grid
///    nodes are rejected (`reject_border_matches`).
/// 5. **deform 2** (eq. 4.3): thin-plate energy + ω² on the constraints + σ² on the matches, on
///    the solve grid (≤ `max_solve_nodes`).
///
/// Errors (tbsp::InvalidInput): fewer than 3 constraints, a constraint pixel outside the image or
/// the mask, a constraint on a missing vertex/face, two constraints on one pixel, a
/// non-manifold or empty mesh, a mask component with fewer than 3 constraints, bad options.
/// Cost: O(#nodes log #nodes) for each factorization (2D nested dissection), O(k (#V + #nodes))
/// for the geodesics, O(#V log #nodes) for the matching.

#include <Eigen/Core>
#include <memory>
#include <string>
#include <cstdint>
#include <vector>

#include "tbsp/core/progress.h"
#include "tbsp/mesh/tri_mesh.h"

namespace tbsp {

/// A constraint: an image pixel ↔ a mesh vertex, or ↔ a surface point (face + barycentric).
struct TextureConstraint {
  Eigen::Vector2d pixel{0, 0};  ///< (x, y) in pixels, x to the right, y down, pixel centres at integers
  int vertex = -1;              ///< mesh vertex, or -1 when `face` is used
  int face = -1;                ///< triangle of a surface-point constraint
  Eigen::Vector3d barycentric{1.0 / 3, 1.0 / 3, 1.0 / 3};
};

/// Which distances on the image side the matching uses.
enum class MatchDistance {
  DeformedSurface,  ///< geodesics on the deformed image surface (the method of ch. 4)
  ImagePlane        ///< Euclidean distances in the flat image, scaled to mesh units (Fig. 4.7 baseline)
};

struct InverseTextureMappingOptions {
  double omega = 10.0;             ///< weight of the constraints (both deformations), ≥ 0.001; large = hard (below ~1e-4 the solves lose the constraints)
  double sigma = 1.0;              ///< weight of the matches in deform 2; small = smoother, 0 = deform 1 only
  double epsilon_factor = 0.01;    ///< ε = epsilon_factor · bbox diagonal · k (eq. 4.2)
  double ratio_low = 0.8;          ///< mismatch test bounds on mesh/image constraint distances
  double ratio_high = 1.25;
  bool mismatch_detection = true;
  /// Reject matches that land on the outermost grid nodes of the image or a pattern piece: a
  /// vertex beyond the image's edge has its nearest distance vector on the edge, so without this
  /// the part of a closed mesh the image does not reach is folded onto the image border.
  bool reject_border_matches = true;
  MatchDistance match_distance = MatchDistance::DeformedSurface;
  long max_solve_nodes = 400000;   ///< larger images are solved on a grid of one node per s×s pixels
  long max_geodesic_nodes = 20000; ///< deform 1 and the texture geodesics on a grid of at most this many nodes
  double heat_time_factor = 1.0;   ///< heat-method time t = factor · h², h = the larger mean edge length of mesh and geodesic grid
  int local_channels = 0;          ///< > 0: match on the distances to the m nearest constraints only (closed / high-genus meshes); 0 = all k (thesis)
  /// Also measure the deformed image's distortion on the mesh and its fit to the mesh (report
  /// fields surface_*, mesh_to_surface_*): two closest-point passes, ~20 % of a 65k-pixel run.
  bool surface_fit_report = false;
  double normal_offset = 0.0;      ///< draping (§4.4): targets moved along the mesh normals (mesh units; |offset| ≤ the mesh's bbox diagonal, checked by compute())
  ProgressCallback progress;       ///< (set with InverseTextureMapping::setProgressCallback)
  /// True when omega >= 0.001, sigma >= 0, epsilon_factor > 0, 0 < ratio_low < ratio_high,
  /// max_solve_nodes and max_geodesic_nodes >= 16, heat_time_factor > 0, local_channels >= 0 and
  /// normal_offset is finite; else false and, if given, `why` says which.
  bool isValid(std::string* why = nullptr) const;
};

/// Per-vertex outcome.
enum class TextureVertexStatus : std::uint8_t { Constraint, Matched, Unmatched };

struct TextureMappingReport {
  int constraints = 0;
  long mesh_vertices = 0, pixels = 0, grid_nodes = 0, geodesic_nodes = 0;
  double pixels_per_node = 1;           ///< s: one solve node per s×s pixels
  /// Per constraint: distance from where its pixel lands on the final surface to its target, in
  /// units of the local size of a pixel on that surface (so 1 = one pixel off).
  std::vector<double> constraint_residual_px;
  double max_constraint_residual_px = 0;
  double matched_fraction = 0;          ///< (constraint + matched vertices) / vertices
  long matched = 0, unmatched = 0;
  long dropped_channels = 0;            ///< (constraint, channel) pairs removed by the ratio test
  long uv_faces = 0, flipped_uv_faces = 0;  ///< faces with all three UVs; those with the minority orientation
  double angle_distortion_mean_deg = 0, angle_distortion_p95_deg = 0;   ///< |angle in 3D − angle in UV|
  double area_distortion_mean = 0, area_distortion_p95 = 0;             ///< |log(area_uv · s² / area_3d)|, s = global scale
  /// With options.surface_fit_report (else 0): distortion of the deformed image where it lies on
  /// the mesh (cells within 1 % of the bbox diagonal): mean |corner angle − 90°| and mean
  /// |log(cell area / median cell area)|.
  double surface_angle_distortion_mean_deg = 0, surface_area_distortion_mean = 0;
  long surface_cells_on_mesh = 0;
  /// Distance from the matched/constraint vertices to the final surface (minus the normal
  /// offset), mesh units: how well the textured surface reproduces the mesh.
  double mesh_to_surface_mean = 0, mesh_to_surface_max = 0;
  double roughness = 0;                 ///< RMS second difference of the final surface / mean node spacing (dimensionless)
  double initial_roughness = 0;         ///< the same for the deform-1 surface
  double epsilon = 0;                   ///< ε in mesh units
  // Timings in seconds (Table 4.1 columns).
  double t_deform1 = 0, t_mesh_geodesics = 0, t_texture_geodesics = 0, t_matching = 0, t_deform2 = 0, t_total = 0;
};

struct TextureMappingResult {
  int grid_width = 0, grid_height = 0;  ///< solve grid, nodes
  double node_spacing_x = 1, node_spacing_y = 1;  ///< pixels between nodes
  std::vector<int> node_index;          ///< grid_width·grid_height; row-major (y·w + x); -1 outside the mask
  Eigen::MatrixX2d node_pixel;          ///< #active nodes: pixel coordinates
  Eigen::MatrixX3d initial_surface;     ///< #active nodes: after deform 1 (mesh units)
  Eigen::MatrixX3d surface;             ///< #active nodes: final deformed image surface
  Eigen::MatrixX3i surface_faces;       ///< triangulation of the active grid cells (indices into the active nodes)
  Eigen::MatrixX2d uv;                  ///< #V: pixel coordinates per mesh vertex, NaN where unmatched
  std::vector<TextureVertexStatus> status;  ///< #V
  TextureMappingReport report;
};

class InverseTextureMapping {
public:
  using Ptr = std::shared_ptr<InverseTextureMapping>;
  using ConstPtr = std::shared_ptr<const InverseTextureMapping>;
  using Options = InverseTextureMappingOptions;

  /// \throws InvalidInput when !options.isValid().
  explicit InverseTextureMapping(const InverseTextureMappingOptions& options = {}) { setOptions(options); }
  /// \throws InvalidInput when !o.isValid() (nothing is clamped).
  void setOptions(const InverseTextureMappingOptions& o);
  const InverseTextureMappingOptions& options() const { return options_; }
  /// Progress of compute() (stages: deform 1, geodesics, matching, deform 2); returning false
  /// cancels (tbsp::Cancelled).
  void setProgressCallback(ProgressCallback cb) { options_.progress = std::move(cb); }
  /// The report of the last successful compute() (also in its result).
  const TextureMappingReport& report() const { return last_report_; }

  void setInputMesh(const TriMesh& mesh) { mesh_ = mesh; }
  /// Image size in pixels (width ≥ 2, height ≥ 2).
  void setImageSize(int width, int height) {
    width_ = width;
    height_ = height;
  }
  /// Optional sewing-pattern mask, row-major width·height, non-zero = pattern pixel. Empty = whole image.
  void setMask(const std::vector<std::uint8_t>& mask) { mask_ = mask; }
  void setConstraints(const std::vector<TextureConstraint>& constraints) { constraints_ = constraints; }

  /// Runs the five stages. \throws InvalidInput (see file doc), Cancelled from the progress callback.
  TextureMappingResult compute() const;

private:
  InverseTextureMappingOptions options_;
  mutable TextureMappingReport last_report_;
  TriMesh mesh_;
  int width_ = 0, height_ = 0;
  std::vector<std::uint8_t> mask_;
  std::vector<TextureConstraint> constraints_;
};

}  // namespace tbsp
