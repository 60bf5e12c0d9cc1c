#pragma once
/// \file range_scanner.h
/// \brief Virtual range scanner: a depth map of a mesh seen by a camera turned into a partial,
/// noisy point cloud with occlusion holes — the kind of data template fitting (ch. 5) gets from
/// a real scanner. Deterministic for a given seed.

#include <cstdint>

#include <pcl/point_cloud.h>
#include <pcl/point_types.h>

#include "tbsp/mesh/tri_mesh.h"
#include "tbsp/multiview/camera.h"
#include "tbsp/multiview/rasterizer.h"

namespace tbsp {

struct RangeScanOptions {
  double noise_sigma = 0.0;         ///< Gaussian noise along the viewing ray (world units)
  int stride = 1;                   ///< keep every stride-th pixel in x and y (>= 1)
  double max_incidence_deg = 80.0;  ///< drop grazing samples (angle between ray and normal)
  std::uint64_t seed = 1;           ///< noise seed
};

/// Scans `mesh` from `camera`: one point per covered pixel centre (back-projected with the
/// rendered depth, plus noise), normal = the face normal turned towards the camera.
/// Returns an organized cloud (width = ceil(W / stride), height = ceil(H / stride)) with NaN
/// points where nothing was hit; is_dense = false. Throws tbsp::InvalidInput on a bad mesh,
/// stride < 1 or negative noise.
pcl::PointCloud<pcl::PointNormal> range_scan(const TriMesh& mesh, const Camera& camera,
                                             const RangeScanOptions& options = {});

}  // namespace tbsp
