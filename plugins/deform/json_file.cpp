#include "tbsp/plugins/json_file.h"

#include <cmath>
#include <cstdio>
#include <cstring>
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

void JsonReader::fail(const std::string& where, const std::string& msg) const {
  throw FileError(source_ + ": " + where + ": " + msg);
}

namespace {
// Lengths, positions and weights are squared by the solvers: beyond this the squares overflow
// a double and a solve returns infinities (a fuzz finding: a target of -1e308 exited 3 with
// "the solution is not finite", naming nothing).
constexpr double kMaxJsonMagnitude = 1e150;

std::string magnitude_message(double v) {
  char buf[160];
  std::snprintf(buf, sizeof buf, "%.6g is out of range: numbers must be within +-1e150 (the solvers square them)", v);
  return buf;
}
}  // namespace

double JsonReader::number(const nlohmann::json& j, const std::string& where) const {
  if (!j.is_number()) fail(where, "expected a number");
  const double v = j.get<double>();
  if (!std::isfinite(v)) fail(where, "non-finite value: numbers must be finite");
  if (std::abs(v) > kMaxJsonMagnitude) fail(where, magnitude_message(v));
  return v;
}

double JsonReader::positive(const nlohmann::json& j, const std::string& where) const {
  const double v = number(j, where);
  if (!(v > 0)) fail(where, "must be > 0");
  return v;
}

Eigen::Vector3d JsonReader::vec3(const nlohmann::json& j, const std::string& where) const {
  if (!j.is_array() || j.size() != 3) fail(where, "expected an array of 3 numbers, e.g. [0.1, 0.2, 0.3]");
  Eigen::Vector3d v;
  for (int k = 0; k < 3; ++k) {
    if (!j[std::size_t(k)].is_number()) fail(where, "expected an array of 3 numbers, e.g. [0.1, 0.2, 0.3]");
    v(k) = j[std::size_t(k)].get<double>();
  }
  if (!v.allFinite()) fail(where, "non-finite value: numbers must be finite");
  for (int k = 0; k < 3; ++k)
    if (std::abs(v(k)) > kMaxJsonMagnitude) fail(where, magnitude_message(v(k)));
  return v;
}

long long JsonReader::integer(const nlohmann::json& j, const std::string& where) const {
  if (!j.is_number_integer()) fail(where, "expected an integer");
  return j.get<long long>();
}

int JsonReader::index(const nlohmann::json& j, const std::string& where, Eigen::Index count, const std::string& kind) const {
  if (!j.is_number_integer()) fail(where, "expected an integer " + kind + " index");
  const long long v = j.get<long long>();
  if (v < 0 || v >= count)
    fail(where, kind + " " + std::to_string(v) + " does not exist: the mesh has " + std::to_string(count) + " " +
                    (kind == "vertex" ? std::string("vertices") : kind + "s") + " (valid: 0.." + std::to_string(count - 1) + ")");
  return int(v);
}

bool JsonReader::boolean(const nlohmann::json& j, const std::string& where) const {
  if (!j.is_boolean()) fail(where, "expected true or false");
  return j.get<bool>();
}

void JsonReader::check_keys(const nlohmann::json& j, std::initializer_list<const char*> allowed, const std::string& where) const {
  if (!j.is_object()) return;
  for (auto it = j.begin(); it != j.end(); ++it) {
    bool known = false;
    for (const char* a : allowed) known = known || it.key() == a;
    if (known) continue;
    std::string list;
    for (const char* a : allowed) list += (list.empty() ? "" : ", ") + std::string(a);
    fail(where, "unknown key \"" + it.key() + "\" (known: " + list + ")");
  }
}

}  // namespace tbsp
