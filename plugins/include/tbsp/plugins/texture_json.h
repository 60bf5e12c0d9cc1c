#pragma once
/// \file texture_json.h
/// \brief Constraint files of `tbsp texture` (docs/texture_json.md):
/// \code
/// {"constraints": [ {"pixel": [x, y], "vertex": 12},
///                   {"pixel": [x, y], "face": 40, "barycentric": [0.2, 0.3, 0.5]} ]}
/// \endcode
/// Pixels: x to the right, y down, pixel centres at integers (0 .. width-1 / height-1).
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "tbsp/fitting/inverse_texture_mapping.h"

namespace tbsp {

/// \brief Parses the constraint list. \throws FileError naming `path`, the item and the fix for
/// a missing list, an item without a 2-number pixel, without vertex/face, with a non-integer or
/// negative index or bad barycentric coordinates. Range checks against the mesh and the image
/// are done by InverseTextureMapping::compute().
std::vector<TextureConstraint> parse_texture_constraints(const nlohmann::json& j, const std::string& path);

}  // namespace tbsp
