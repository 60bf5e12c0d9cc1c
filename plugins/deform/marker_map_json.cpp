#include "tbsp/plugins/marker_map_json.h"

#include "tbsp/core/error.h"
#include "tbsp/plugins/json_file.h"

namespace tbsp {

MarkerMap load_marker_map(const std::string& path) try {
  const JsonReader in(path);
  const nlohmann::json doc = load_json_file(path);
  if (!doc.is_object()) throw FileError(path + ": expected a JSON object {\"markers\": [...]}");
  in.check_keys(doc, {"template", "markers", "rigid_regions", "comment"}, "(top level)");
  if (!doc.contains("markers") || !doc["markers"].is_array()) in.fail("markers", "missing: expected an array of {\"marker\", \"vertex\"}");
  const auto& a = doc["markers"];
  if (a.empty()) in.fail("markers", "is empty: map at least 3 markers to template vertices");
  MarkerMap map;
  std::vector<MarkerMapEntry>& out = map.markers;
  for (std::size_t i = 0; i < a.size(); ++i) {
    const std::string w = "markers[" + std::to_string(i) + "]";
    const auto& j = a[i];
    if (!j.is_object()) in.fail(w, "expected an object {\"marker\": NAME, \"vertex\": INDEX}");
    in.check_keys(j, {"marker", "vertex", "point", "align", "pixels", "comment"}, w);
    MarkerMapEntry e;
    if (!j.contains("marker") || !j["marker"].is_string()) in.fail(w + ".marker", "missing: expected the marker's label (a string)");
    e.marker = j["marker"].get<std::string>();
    if (e.marker.empty()) in.fail(w + ".marker", "is empty");
    if (j.contains("vertex") && j.contains("point")) in.fail(w, "give either \"vertex\" (a template vertex) or \"point\" (a point inside the template), not both");
    if (j.contains("point")) {
      e.point = in.vec3(j["point"], w + ".point");
    } else {
      if (!j.contains("vertex")) in.fail(w + ".vertex", "missing: expected the template vertex the marker sits on (or a \"point\" inside the template)");
      const long long v = in.integer(j["vertex"], w + ".vertex");
      if (v < 0 || v > 2000000000LL) in.fail(w + ".vertex", "template vertex " + std::to_string(v) + " does not exist");
      e.vertex = static_cast<int>(v);
    }
    if (j.contains("align")) e.align = in.boolean(j["align"], w + ".align");
    for (std::size_t k = 0; k < i; ++k) {
      if (out[k].marker == e.marker) in.fail(w + ".marker", "'" + e.marker + "' is mapped twice (also markers[" + std::to_string(k) + "])");
      if (e.vertex >= 0 && out[k].vertex == e.vertex)
        in.fail(w + ".vertex", "template vertex " + std::to_string(e.vertex) + " also carries markers[" + std::to_string(k) + "] ('" +
                                   out[k].marker + "'); one vertex cannot follow two markers: pick a neighbouring vertex");
    }
    if (j.contains("pixels")) {
      const auto& px = j["pixels"];
      if (!px.is_object() || px.empty()) in.fail(w + ".pixels", "expected an object {\"CAMERA\": [x, y], ...} with at least 2 cameras");
      ImageMarker im;
      im.marker = e.marker;
      for (auto it = px.begin(); it != px.end(); ++it) {
        const std::string wp = w + ".pixels." + it.key();
        if (!it.value().is_array() || it.value().size() != 2) in.fail(wp, "expected a pixel [x, y]");
        im.pixels[it.key()] = Eigen::Vector2d(in.number(it.value()[0], wp + "[0]"), in.number(it.value()[1], wp + "[1]"));
      }
      if (im.pixels.size() < 2) in.fail(w + ".pixels", "the marker is placed in 1 view: place it in at least 2 (it is triangulated)");
      map.image_markers.push_back(im);
    }
    out.push_back(e);
  }
  if (doc.contains("rigid_regions")) {
    const auto& rr = doc["rigid_regions"];
    if (!rr.is_array()) in.fail("rigid_regions", "expected an array of {\"name\", \"vertices\" or \"box\"}");
    for (std::size_t i = 0; i < rr.size(); ++i) {
      const std::string w = "rigid_regions[" + std::to_string(i) + "]";
      const auto& j = rr[i];
      if (!j.is_object()) in.fail(w, "expected an object {\"name\": NAME, \"vertices\": [...]} or {\"name\": NAME, \"box\": [[lo], [hi]]}");
      in.check_keys(j, {"name", "vertices", "box", "comment"}, w);
      MarkerMapRigidRegion g;
      if (j.contains("name")) {
        if (!j["name"].is_string()) in.fail(w + ".name", "expected a string");
        g.name = j["name"].get<std::string>();
      }
      if (j.contains("vertices") == j.contains("box")) in.fail(w, "give exactly one of \"vertices\" (a list) or \"box\" ([[x0,y0,z0],[x1,y1,z1]])");
      if (j.contains("vertices")) {
        const auto& v = j["vertices"];
        if (!v.is_array() || v.empty()) in.fail(w + ".vertices", "expected a non-empty array of template vertices");
        for (std::size_t k = 0; k < v.size(); ++k) {
          const long long x = in.integer(v[k], w + ".vertices[" + std::to_string(k) + "]");
          if (x < 0 || x > 2000000000LL) in.fail(w + ".vertices[" + std::to_string(k) + "]", "template vertex " + std::to_string(x) + " does not exist");
          g.vertices.push_back(static_cast<int>(x));
        }
      } else {
        const auto& b = j["box"];
        if (!b.is_array() || b.size() != 2) in.fail(w + ".box", "expected [[x0, y0, z0], [x1, y1, z1]]");
        g.box = true;
        g.lo = in.vec3(b[0], w + ".box[0]");
        g.hi = in.vec3(b[1], w + ".box[1]");
        if ((g.lo.array() > g.hi.array()).any()) in.fail(w + ".box", "the first corner must be the lower one on every axis");
      }
      map.rigid_regions.push_back(g);
    }
  }
  return map;
} catch (const nlohmann::json::exception& e) {
  throw_json_structure_error(path, e);
}

std::vector<MarkerMapEntry> load_marker_map_json(const std::string& path) { return load_marker_map(path).markers; }

std::vector<std::vector<int>> rigid_region_vertices(const MarkerMap& map, const TriMesh& tmpl) {
  std::vector<std::vector<int>> out;
  for (std::size_t r = 0; r < map.rigid_regions.size(); ++r) {
    const auto& g = map.rigid_regions[r];
    if (!g.box) {
      out.push_back(g.vertices);
      continue;
    }
    std::vector<int> v;
    for (Eigen::Index i = 0; i < tmpl.V.rows(); ++i)
      if ((tmpl.V.row(i).transpose().array() >= g.lo.array()).all() && (tmpl.V.row(i).transpose().array() <= g.hi.array()).all()) v.push_back(int(i));
    if (v.empty())
      throw InvalidInput("rigid region " + (g.name.empty() ? std::to_string(r) : "'" + g.name + "'") +
                         ": its box holds no template vertex (template coordinates: check the box against the template's bounding box)");
    out.push_back(std::move(v));
  }
  return out;
}

}  // namespace tbsp
