#pragma once
// JSON reports of the CLI tests.
#include <filesystem>
#include <fstream>

#include <nlohmann/json.hpp>

namespace tbsp::test {

/// Parses the JSON file at `p` (throws nlohmann::json::parse_error when malformed).
inline nlohmann::json load_json(const std::filesystem::path& p) {
  std::ifstream in(p);
  return nlohmann::json::parse(in);
}

}  // namespace tbsp::test
