#pragma once
/// \file json_file.h
/// \brief Reads a JSON document from a file; errors name the file (and nlohmann's line/column).

#include <nlohmann/json.hpp>
#include <string>

namespace tbsp {

/// \throws FileError when the file cannot be opened or is not valid JSON (syntax errors with
/// nlohmann's line/column; numbers outside the range of a double, e.g. 1e309, are named too).
nlohmann::json load_json_file(const std::string& path);

/// Safety net of the JSON front ends (constraints, markers, ROI, tet handles/rigid/stiffness,
/// texture constraints): a value of an unexpected kind that no explicit check names becomes a
/// FileError naming the file and nlohmann's description, so the CLI exits 2, never 1.
[[noreturn]] void throw_json_structure_error(const std::string& source, const nlohmann::json::exception& e);

}  // namespace tbsp
