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
  } catch (const nlohmann::json::out_of_range& e) {
    // 406: a number too large for a double (e.g. 1e309)
    throw FileError(path + ": a number is out of range (" + e.what() + "); numbers must be finite doubles (|x| < 1.8e308)");
  } catch (const nlohmann::json::exception& e) {
    throw FileError(path + ": cannot read JSON (" + e.what() + ")");
  }
  return doc;
}

void throw_json_structure_error(const std::string& source, const nlohmann::json::exception& e) {
  throw FileError(source + ": a value has an unexpected type or range (" + e.what() +
                  "); see the format's page in docs/ for what each key takes");
}

}  // namespace tbsp
