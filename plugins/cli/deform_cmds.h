#pragma once
// `tbsp deform` (Laplacian deformation, thesis ch. 3); run_deform is shared with the demo.
#include "tbsp/deform/laplacian_deformer.h"
#include "tbsp/mesh/tri_mesh.h"
#include "tbsp/plugins/constraints_json.h"

namespace tbsp::cli {

/// Runs one deformation job; returns the deformed mesh and fills the report.
tbsp::TriMesh run_deform(const tbsp::TriMesh& mesh, const tbsp::DeformJob& job, bool rotation_field, bool uniform,
                         double scale, bool quiet, tbsp::DeformReport& report);

}  // namespace tbsp::cli
