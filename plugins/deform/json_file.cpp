#include "tbsp/plugins/json_file.h"

#include <fstream>

#include "tbsp/core/error.h"

namespace tbsp {

nlohmann::json load_json_file(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw FileError("'" + path + "': cannot open; check the path");
  nlohmann::json doc;
  try {
    in >> doc;
  } catch (const nlohmann::json::parse_error& e) {
    throw FileError(path + ": not valid JSON (" + e.what() + ")");
  }
  return doc;
}

}  // namespace tbsp
