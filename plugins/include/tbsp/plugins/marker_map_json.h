#pragma once
/// \file marker_map_json.h
/// \brief The marker map of `tbsp animate` / MarkerAnimation (docs/performance_capture.md):
///
///     {"template": "FinalBaseMesh.obj",            (optional, informative)
///      "markers": [{"marker": "LFHD", "vertex": 1234, "align": true}, ...
///                  {"marker": "l_knee", "point": [0.09, 0.46, 0.0],            (inside the template)
///                   "pixels": {"cam00": [413.5, 408.0], "cam01": [323, 356]}}],   (optional)
///      "rigid_regions": [{"name": "head", "box": [[x0, y0, z0], [x1, y1, z1]]},   (optional)
///                        {"name": "pelvis", "vertices": [12, 13, ...]}]}
///
/// `marker`: the label in the C3D/TRC file (unique); `vertex`: template vertex (0-based, checked
/// against the template by MarkerAnimation) or `point`: template rest coordinates inside the
/// body (a joint centre); `align` (default true): used by the first-frame similarity alignment;
/// `pixels` (optional): where the marker is seen in the images of a studio, per camera name, in
/// at least 2 views — hand-placed markers that pose a template (triangulate_image_markers,
/// `tbsp refine-silhouette --pose`). A rigid region is a set of template vertices, given as a list or as an
/// axis-aligned box in template coordinates (MarkerAnimation::setRigidRegions). Unknown keys
/// are errors (a typo would silently change the result).

#include <string>
#include <vector>

#include <Eigen/Core>

#include "tbsp/mesh/tri_mesh.h"
#include "tbsp/multiview/marker_animation.h"

namespace tbsp {

struct MarkerMapRigidRegion {
  std::string name;
  std::vector<int> vertices;  ///< given as a list, or
  bool box = false;           ///< an axis-aligned box [lo, hi] (template coordinates)
  Eigen::Vector3d lo = Eigen::Vector3d::Zero(), hi = Eigen::Vector3d::Zero();
};
struct MarkerMap {
  std::vector<MarkerMapEntry> markers;
  std::vector<ImageMarker> image_markers;  ///< the entries that have `pixels`, in file order
  std::vector<MarkerMapRigidRegion> rigid_regions;
};

/// \throws FileError naming the file and the item (e.g. `markers[3].vertex`) on a missing file,
/// bad JSON, a missing or ill-typed field, a negative vertex, both or neither of vertex/point, a
/// duplicate or empty name, pixels in fewer than 2 views, or an empty list.
MarkerMap load_marker_map(const std::string& path);
/// The markers of load_marker_map.
std::vector<MarkerMapEntry> load_marker_map_json(const std::string& path);
/// The rigid regions as template vertex sets (boxes resolved against `tmpl`). \throws
/// InvalidInput naming the region when a box holds no vertex.
std::vector<std::vector<int>> rigid_region_vertices(const MarkerMap& map, const TriMesh& tmpl);

}  // namespace tbsp
