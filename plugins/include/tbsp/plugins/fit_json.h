#pragma once
/// \file fit_json.h
/// \brief Files of `tbsp fit`: markers and region of interest (docs/fit_json.md), the report.

#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "tbsp/fitting/template_fitter.h"

namespace tbsp {

/// {"markers": [{"template_vertex": 12, "cloud_index": 345} | {"template_vertex": 12,
/// "position": [x,y,z]}, optional "weight", "rotation"]}. Indices are range-checked by the fit.
/// \throws FileError naming the file and item.
std::vector<FitMarker> load_markers_json(const std::string& path);

/// {"exclude_template_vertices": [...], "exclude_template_spheres": [{"center": [..], "radius": r}],
///  "exclude_template_boxes": [{"min": [..], "max": [..]}], "exclude_cloud_points": [...],
///  "exclude_cloud_spheres": [...], "exclude_cloud_boxes": [...]}. \throws FileError.
RegionOfInterest load_roi_json(const std::string& path);

/// The report: status, iterations (with history), scale, parameters used, counts, metrics
/// (Hausdorff absolute and relative to the bbox diagonal — the metric of Table 5.1 —, RMS,
/// mean, p99, coverage, flipped faces) and per-stage timings.
nlohmann::json fit_report_json(const FitReport& r);

const char* to_string(VertexStatus s);

}  // namespace tbsp
