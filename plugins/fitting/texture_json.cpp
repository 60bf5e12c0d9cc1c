#include "tbsp/plugins/texture_json.h"

#include <cmath>

#include "tbsp/core/error.h"
#include "tbsp/plugins/json_file.h"

namespace tbsp {

std::vector<TextureConstraint> parse_texture_constraints(const nlohmann::json& j, const std::string& path) try {
  const JsonReader in("'" + path + "'");
  if (!j.is_object() || !j.contains("constraints") || !j["constraints"].is_array())
    in.fail("top level", "expected an object with a \"constraints\" array, e.g. {\"constraints\": [{\"pixel\": [10, 20], \"vertex\": 5}]}");
  in.check_keys(j, {"constraints", "comment"}, "top level");
  std::vector<TextureConstraint> out;
  const auto& arr = j["constraints"];
  for (std::size_t i = 0; i < arr.size(); ++i) {
    const auto& c = arr[i];
    const std::string item = "constraints[" + std::to_string(i) + "]";
    if (!c.is_object()) in.fail(item, "expected an object with \"pixel\" and \"vertex\" (or \"face\" + \"barycentric\")");
    in.check_keys(c, {"pixel", "vertex", "face", "barycentric", "comment"}, item);
    if (!c.contains("pixel") || !c["pixel"].is_array() || c["pixel"].size() != 2)
      in.fail(item, "\"pixel\" must be [x, y] (two numbers, in pixels)");
    TextureConstraint t;
    t.pixel = Eigen::Vector2d(in.number(c["pixel"][0], item + ".pixel"), in.number(c["pixel"][1], item + ".pixel"));
    const bool has_v = c.contains("vertex"), has_f = c.contains("face");
    if (has_v == has_f) in.fail(item, "give exactly one of \"vertex\" (index) or \"face\" (index, with \"barycentric\")");
    const long long idx = in.integer(has_v ? c["vertex"] : c["face"], item + (has_v ? ".vertex" : ".face"));
    if (idx < 0 || idx > 2000000000LL)
      in.fail(item, "\"" + std::string(has_v ? "vertex" : "face") + "\" must be a non-negative integer index (0-based)");
    if (has_v) {
      t.vertex = int(idx);
    } else {
      t.face = int(idx);
      if (!c.contains("barycentric"))
        in.fail(item, "a face constraint needs \"barycentric\": [a, b, c] (non-negative, summing to 1)");
      t.barycentric = in.vec3(c["barycentric"], item + ".barycentric");
      if (t.barycentric.minCoeff() < 0 || std::abs(t.barycentric.sum() - 1) > 1e-6)
        in.fail(item + ".barycentric", "must be non-negative and sum to 1");
    }
    out.push_back(t);
  }
  return out;
} catch (const nlohmann::json::exception& e) {
  throw_json_structure_error(path, e);
}

}  // namespace tbsp
