#include "tbsp/plugins/marker_map_json.h"

#include "tbsp/core/error.h"
#include "tbsp/plugins/json_file.h"

namespace tbsp {

std::vector<MarkerMapEntry> load_marker_map_json(const std::string& path) try {
  const JsonReader in(path);
  const nlohmann::json doc = load_json_file(path);
  if (!doc.is_object()) throw FileError(path + ": expected a JSON object {\"markers\": [...]}");
  in.check_keys(doc, {"template", "markers", "comment"}, "(top level)");
  if (!doc.contains("markers") || !doc["markers"].is_array()) in.fail("markers", "missing: expected an array of {\"marker\", \"vertex\"}");
  const auto& a = doc["markers"];
  if (a.empty()) in.fail("markers", "is empty: map at least 3 markers to template vertices");
  std::vector<MarkerMapEntry> out;
  for (std::size_t i = 0; i < a.size(); ++i) {
    const std::string w = "markers[" + std::to_string(i) + "]";
    const auto& j = a[i];
    if (!j.is_object()) in.fail(w, "expected an object {\"marker\": NAME, \"vertex\": INDEX}");
    in.check_keys(j, {"marker", "vertex", "align", "comment"}, w);
    MarkerMapEntry e;
    if (!j.contains("marker") || !j["marker"].is_string()) in.fail(w + ".marker", "missing: expected the marker's label (a string)");
    e.marker = j["marker"].get<std::string>();
    if (e.marker.empty()) in.fail(w + ".marker", "is empty");
    if (!j.contains("vertex")) in.fail(w + ".vertex", "missing: expected the template vertex the marker sits on");
    const long long v = in.integer(j["vertex"], w + ".vertex");
    if (v < 0 || v > 2000000000LL) in.fail(w + ".vertex", "template vertex " + std::to_string(v) + " does not exist");
    e.vertex = static_cast<int>(v);
    if (j.contains("align")) e.align = in.boolean(j["align"], w + ".align");
    out.push_back(e);
  }
  return out;
} catch (const nlohmann::json::exception& e) {
  throw_json_structure_error(path, e);
}

}  // namespace tbsp
