#include "tbsp/plugins/texture_json.h"

#include <cmath>

#include "tbsp/core/error.h"
#include "tbsp/plugins/json_file.h"

namespace tbsp {

std::vector<TextureConstraint> parse_texture_constraints(const nlohmann::json& j, const std::string& path) try {
  const std::string where = "'" + path + "'";
  if (!j.is_object() || !j.contains("constraints") || !j["constraints"].is_array())
    throw FileError(where + ": expected an object with a \"constraints\" array, e.g. {\"constraints\": [{\"pixel\": [10, 20], \"vertex\": 5}]}");
  std::vector<TextureConstraint> out;
  const auto& arr = j["constraints"];
  for (std::size_t i = 0; i < arr.size(); ++i) {
    const auto& c = arr[i];
    const std::string item = where + ": constraints[" + std::to_string(i) + "]";
    if (!c.is_object()) throw FileError(item + ": expected an object with \"pixel\" and \"vertex\" (or \"face\" + \"barycentric\")");
    if (!c.contains("pixel") || !c["pixel"].is_array() || c["pixel"].size() != 2 || !c["pixel"][0].is_number() || !c["pixel"][1].is_number())
      throw FileError(item + ": \"pixel\" must be [x, y] (two numbers, in pixels)");
    TextureConstraint t;
    t.pixel = Eigen::Vector2d(c["pixel"][0].get<double>(), c["pixel"][1].get<double>());
    if (!t.pixel.allFinite()) throw FileError(item + ": \"pixel\" is not finite");
    const bool has_v = c.contains("vertex"), has_f = c.contains("face");
    if (has_v == has_f) throw FileError(item + ": give exactly one of \"vertex\" (index) or \"face\" (index, with \"barycentric\")");
    const auto& idx = has_v ? c["vertex"] : c["face"];
    if (!idx.is_number_integer() || idx.get<long>() < 0 || idx.get<long>() > 2000000000L)
      throw FileError(item + ": \"" + std::string(has_v ? "vertex" : "face") + "\" must be a non-negative integer index (0-based)");
    if (has_v) {
      t.vertex = idx.get<int>();
    } else {
      t.face = idx.get<int>();
      const auto& b = c.contains("barycentric") ? c["barycentric"] : nlohmann::json();
      if (!b.is_array() || b.size() != 3 || !b[0].is_number() || !b[1].is_number() || !b[2].is_number())
        throw FileError(item + ": a face constraint needs \"barycentric\": [a, b, c] (non-negative, summing to 1)");
      t.barycentric = Eigen::Vector3d(b[0].get<double>(), b[1].get<double>(), b[2].get<double>());
      if (!t.barycentric.allFinite() || t.barycentric.minCoeff() < 0 || std::abs(t.barycentric.sum() - 1) > 1e-6)
        throw FileError(item + ": \"barycentric\" must be non-negative and sum to 1");
    }
    out.push_back(t);
  }
  return out;
} catch (const nlohmann::json::exception& e) {
  throw_json_structure_error(path, e);
}

}  // namespace tbsp
