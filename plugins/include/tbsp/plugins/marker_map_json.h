#pragma once
/// \file marker_map_json.h
/// \brief The marker map of `tbsp animate` / MarkerAnimation (docs/performance_capture.md):
///
///     {"template": "FinalBaseMesh.obj",            (optional, informative)
///      "markers": [{"marker": "LFHD", "vertex": 1234, "align": true}, ...]}
///
/// `marker`: the label in the C3D/TRC file; `vertex`: template vertex (0-based, checked
/// against the template by MarkerAnimation); `align` (default true): used by the first-frame
/// similarity alignment. Unknown keys are errors (a typo would silently change the result).

#include <string>
#include <vector>

#include "tbsp/multiview/marker_animation.h"

namespace tbsp {

/// \throws FileError naming the file and the item (e.g. `markers[3].vertex`) on a missing file,
/// bad JSON, a missing or ill-typed field, a negative vertex, an empty name or an empty list.
std::vector<MarkerMapEntry> load_marker_map_json(const std::string& path);

}  // namespace tbsp
