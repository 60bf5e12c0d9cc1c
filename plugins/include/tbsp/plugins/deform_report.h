#pragma once
/// \file deform_report.h
/// \brief JSON form of tbsp::DeformReport (the `--report` of `tbsp deform`).

#include <nlohmann/json.hpp>

#include "tbsp/deform/laplacian_deformer.h"

namespace tbsp {

/// timings (s): laplacian, constraint_graph, factorize, rotations, solve, total; counts;
/// residuals: max, rms, per type, and per constraint (id, type, hard, distance).
nlohmann::json deform_report_json(const DeformReport& r);

}  // namespace tbsp
