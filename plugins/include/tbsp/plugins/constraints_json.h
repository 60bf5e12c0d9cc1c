#pragma once
/// \file constraints_json.h
/// \brief The constraints file of `tbsp deform` (format: docs/constraints_json.md).

#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "tbsp/deform/laplacian_deformer.h"

namespace tbsp {

/// \brief Everything a constraints file asks for.
struct DeformJob {
  std::vector<DeformConstraint> constraints;
  std::optional<LaplacianWeights> weights;  ///< "laplacian": "cotangent" | "uniform"
  std::optional<bool> rotation_field;       ///< "rotation_field": true | false
  double scale = 1.0;                       ///< "scale": λ > 0
};

/// \brief Parses a constraints document against `mesh` (indices are checked against it;
/// `transform` groups are applied to the rest positions). `source` names the file in errors.
/// \throws FileError "SOURCE: constraints[3].target: expected an array of 3 numbers"-style.
DeformJob parse_constraints_json(const nlohmann::json& doc, const TriMesh& mesh, const std::string& source);

/// \brief Reads and parses a constraints file. \throws FileError.
DeformJob load_constraints_json(const std::string& path, const TriMesh& mesh);

}  // namespace tbsp
