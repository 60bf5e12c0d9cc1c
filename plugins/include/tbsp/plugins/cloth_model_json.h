#pragma once
/// \file cloth_model_json.h
/// \brief An AnimatableModel as one JSON file (format "tbsp-animatable-model", version 1): mesh,
/// skeleton (names, parents, rest transforms), skinning weights, clothness, regions, materials,
/// collision proxies and the simulator settings. See docs/cloth.md for the layout.

#include <string>

#include "tbsp/cloth/animatable_model.h"

namespace tbsp {

/// Writes the model (atomically: a failed write leaves an existing file untouched).
/// \throws InvalidInput when the model is not valid, FileError when the file cannot be written.
void save_animatable_model(const std::string& path, const AnimatableModel& model);

/// Reads and validates a model. \throws FileError naming the file and the item
/// (e.g. `weights[12][0]`) for malformed or inconsistent content.
AnimatableModel load_animatable_model(const std::string& path);

}  // namespace tbsp
