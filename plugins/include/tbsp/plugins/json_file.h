#pragma once
/// \file json_file.h
/// \brief Reads a JSON document from a file; errors name the file (and nlohmann's line/column).

#include <nlohmann/json.hpp>
#include <string>

namespace tbsp {

/// \throws FileError when the file cannot be opened or is not valid JSON.
nlohmann::json load_json_file(const std::string& path);

}  // namespace tbsp
