#include "tbsp/plugins/tet_job_json.h"

#include <algorithm>
#include <cmath>

#include "tbsp/core/error.h"
#include "tbsp/plugins/json_file.h"

namespace tbsp {

namespace {
using json = nlohmann::json;

[[noreturn]] void fail(const std::string& source, const std::string& where, const std::string& msg) {
  throw FileError(source + ": " + where + ": " + msg);
}

Eigen::Vector3d vec3(const json& j, const std::string& source, const std::string& where) {
  if (!j.is_array() || j.size() != 3) fail(source, where, "expected an array of 3 numbers");
  Eigen::Vector3d v;
  for (int k = 0; k < 3; ++k) {
    if (!j[std::size_t(k)].is_number()) fail(source, where, "expected an array of 3 numbers");
    v(k) = j[std::size_t(k)].get<double>();
    if (!std::isfinite(v(k))) fail(source, where, "non-finite value");
  }
  return v;
}

double number(const json& j, const std::string& source, const std::string& where) {
  if (!j.is_number()) fail(source, where, "expected a number");
  const double v = j.get<double>();
  if (!std::isfinite(v)) fail(source, where, "non-finite value");
  return v;
}

int vertex_index(const json& j, Eigen::Index n, const std::string& source, const std::string& where) {
  if (!j.is_number_integer()) fail(source, where, "expected a vertex index (integer)");
  const long long v = j.get<long long>();
  if (v < 0 || v >= n)
    fail(source, where, "vertex " + std::to_string(v) + " does not exist (the input mesh has " + std::to_string(n) + " vertices)");
  return int(v);
}

// Reads one region from the keys "vertices" | "sphere" | "box" of `j`; false if none present.
bool parse_region(const json& j, Eigen::Index n, const std::string& source, const std::string& where, TetRegion& r) {
  int count = int(j.contains("vertices")) + int(j.contains("sphere")) + int(j.contains("box"));
  if (count == 0) return false;
  if (count > 1) fail(source, where, "give one of \"vertices\", \"sphere\" or \"box\", not several");
  if (j.contains("vertices")) {
    const json& v = j["vertices"];
    if (!v.is_array() || v.empty()) fail(source, where + ".vertices", "expected a non-empty array of vertex indices");
    r.kind = TetRegion::Vertices;
    for (std::size_t i = 0; i < v.size(); ++i)
      r.vertices.push_back(vertex_index(v[i], n, source, where + ".vertices[" + std::to_string(i) + "]"));
  } else if (j.contains("sphere")) {
    const json& s = j["sphere"];
    if (!s.is_object() || !s.contains("center") || !s.contains("radius"))
      fail(source, where + ".sphere", "expected {\"center\": [x, y, z], \"radius\": r}");
    r.kind = TetRegion::Sphere;
    r.a = vec3(s["center"], source, where + ".sphere.center");
    r.radius = number(s["radius"], source, where + ".sphere.radius");
    if (!(r.radius > 0)) fail(source, where + ".sphere.radius", "must be > 0");
  } else {
    const json& b = j["box"];
    if (!b.is_object() || !b.contains("min") || !b.contains("max"))
      fail(source, where + ".box", "expected {\"min\": [x, y, z], \"max\": [x, y, z]}");
    r.kind = TetRegion::Box;
    r.a = vec3(b["min"], source, where + ".box.min");
    r.b = vec3(b["max"], source, where + ".box.max");
    if ((r.b.array() < r.a.array()).any()) fail(source, where + ".box", "min must not exceed max");
  }
  return true;
}

void check_keys(const json& j, const std::vector<std::string>& allowed, const std::string& source, const std::string& where) {
  for (auto it = j.begin(); it != j.end(); ++it)
    if (std::find(allowed.begin(), allowed.end(), it.key()) == allowed.end()) {
      std::string list;
      for (const auto& a : allowed) list += (list.empty() ? "" : ", ") + a;
      fail(source, where, "unknown key \"" + it.key() + "\" (known: " + list + ")");
    }
}
}  // namespace

bool TetRegion::contains(const Eigen::Vector3d& p) const {
  if (kind == Sphere) return (p - a).norm() <= radius;
  if (kind == Box) return (p.array() >= a.array()).all() && (p.array() <= b.array()).all();
  return false;
}

void parse_tet_handles(const json& doc, Eigen::Index n, const std::string& source, TetJob& job) try {
  if (!doc.is_object()) fail(source, "top level", "expected an object with a \"handles\" array");
  check_keys(doc, {"handles", "iterations", "rotation_interpolation", "max_step_degrees", "comment"}, source, "top level");
  if (!doc.contains("handles") || !doc["handles"].is_array())
    fail(source, "handles", "missing: give an array of handles (docs/tetdeform_json.md)");
  const json& hs = doc["handles"];
  if (hs.empty()) fail(source, "handles", "empty: at least one handle is needed, or the deformation is undetermined");
  for (std::size_t i = 0; i < hs.size(); ++i) {
    const std::string w = "handles[" + std::to_string(i) + "]";
    const json& h = hs[i];
    if (!h.is_object()) fail(source, w, "expected an object");
    check_keys(h, {"vertices", "sphere", "box", "vertex", "point", "target", "translate", "rotate", "comment"}, source, w);
    TetHandleSpec spec;
    spec.where = w;
    if (h.contains("vertex") || h.contains("point")) {
      if (h.contains("vertex") && h.contains("point")) fail(source, w, "give \"vertex\" or \"point\", not both");
      if (!h.contains("target")) fail(source, w, "a vertex or point handle needs a \"target\": [x, y, z]");
      if (h.contains("rotate") || h.contains("translate"))
        fail(source, w, "vertex/point handles take a \"target\"; \"rotate\"/\"translate\" belong to regions");
      if (h.contains("vertex")) {
        spec.kind = TetHandleSpec::Vertex;
        spec.vertex = vertex_index(h["vertex"], n, source, w + ".vertex");
      } else {
        spec.kind = TetHandleSpec::Point;
        spec.point = vec3(h["point"], source, w + ".point");
      }
      spec.target = vec3(h["target"], source, w + ".target");
    } else {
      spec.kind = TetHandleSpec::Region;
      if (!parse_region(h, n, source, w, spec.region))
        fail(source, w, "a handle needs \"vertices\", \"sphere\", \"box\" (regions) or \"vertex\"/\"point\" + \"target\"");
      if (h.contains("target")) fail(source, w, "regions move by \"translate\"/\"rotate\", not \"target\"");
      if (h.contains("translate")) spec.motion.translation = vec3(h["translate"], source, w + ".translate");
      if (h.contains("rotate")) {
        const json& r = h["rotate"];
        const std::string wr = w + ".rotate";
        if (!r.is_object() || !r.contains("axis") || !r.contains("degrees"))
          fail(source, wr, "expected {\"axis\": [x, y, z], \"degrees\": a, \"center\": [x, y, z]}");
        check_keys(r, {"axis", "degrees", "center"}, source, wr);
        spec.motion.axis = vec3(r["axis"], source, wr + ".axis");
        if (!(spec.motion.axis.norm() > 0)) fail(source, wr + ".axis", "the axis is zero");
        spec.motion.angle = number(r["degrees"], source, wr + ".degrees") * M_PI / 180.0;
        if (r.contains("center")) spec.motion.center = vec3(r["center"], source, wr + ".center");
        else fail(source, wr, "missing \"center\": the point the region turns about");
      }
    }
    job.handles.push_back(spec);
  }
  if (doc.contains("iterations")) {
    if (!doc["iterations"].is_number_integer() || doc["iterations"].get<long long>() < 1)
      fail(source, "iterations", "expected a positive integer");
    job.iterations = int(doc["iterations"].get<long long>());
  }
  if (doc.contains("rotation_interpolation")) {
    if (!doc["rotation_interpolation"].is_boolean()) fail(source, "rotation_interpolation", "expected true or false");
    job.rotation_interpolation = doc["rotation_interpolation"].get<bool>();
  }
  if (doc.contains("max_step_degrees")) {
    const double v = number(doc["max_step_degrees"], source, "max_step_degrees");
    if (!(v > 0 && v < 180)) fail(source, "max_step_degrees", "must be in (0, 180)");
    job.max_step_degrees = v;
  }
} catch (const nlohmann::json::exception& e) {
  throw_json_structure_error(source, e);
}

void parse_tet_rigid(const json& doc, Eigen::Index n, const std::string& source, TetJob& job) try {
  if (!doc.is_object() || !doc.contains("rigid") || !doc["rigid"].is_array())
    fail(source, "top level", "expected {\"rigid\": [region, ...]} (docs/tetdeform_json.md)");
  const json& rs = doc["rigid"];
  for (std::size_t i = 0; i < rs.size(); ++i) {
    const std::string w = "rigid[" + std::to_string(i) + "]";
    if (!rs[i].is_object()) fail(source, w, "expected an object");
    check_keys(rs[i], {"vertices", "sphere", "box", "comment"}, source, w);
    TetRegion r;
    if (!parse_region(rs[i], n, source, w, r)) fail(source, w, "needs \"vertices\", \"sphere\" or \"box\"");
    job.rigid.push_back(r);
  }
} catch (const nlohmann::json::exception& e) {
  throw_json_structure_error(source, e);
}

void parse_tet_stiffness(const json& doc, Eigen::Index n, const std::string& source, TetJob& job) try {
  if (!doc.is_object()) fail(source, "top level", "expected {\"default\": s, \"regions\": [...]}");
  check_keys(doc, {"default", "regions", "comment"}, source, "top level");
  if (doc.contains("default")) {
    job.default_stiffness = number(doc["default"], source, "default");
    if (!(job.default_stiffness > 0)) fail(source, "default", "stiffness must be > 0");
  }
  if (doc.contains("regions")) {
    if (!doc["regions"].is_array()) fail(source, "regions", "expected an array");
    const json& rs = doc["regions"];
    for (std::size_t i = 0; i < rs.size(); ++i) {
      const std::string w = "regions[" + std::to_string(i) + "]";
      if (!rs[i].is_object()) fail(source, w, "expected an object");
      check_keys(rs[i], {"vertices", "sphere", "box", "stiffness", "comment"}, source, w);
      TetRegion r;
      if (!parse_region(rs[i], n, source, w, r)) fail(source, w, "needs \"vertices\", \"sphere\" or \"box\"");
      if (!rs[i].contains("stiffness")) fail(source, w, "missing \"stiffness\"");
      const double s = number(rs[i]["stiffness"], source, w + ".stiffness");
      if (!(s > 0)) fail(source, w + ".stiffness", "must be > 0 (mark rigid parts with --rigid instead)");
      job.stiffness.push_back({r, s});
    }
  }
} catch (const nlohmann::json::exception& e) {
  throw_json_structure_error(source, e);
}

std::vector<int> resolve_region_vertices(const TetRegion& r, const Eigen::MatrixX3d& V, const std::vector<Eigen::Index>& to_input,
                                         const std::vector<double>& dist, double snap) {
  std::vector<int> out;
  if (r.kind == TetRegion::Vertices) {
    std::vector<char> in;
    Eigen::Index maxv = 0;
    for (int v : r.vertices) maxv = std::max<Eigen::Index>(maxv, v);
    in.assign(std::size_t(maxv + 1), 0);
    for (int v : r.vertices) in[std::size_t(v)] = 1;
    for (Eigen::Index i = 0; i < V.rows(); ++i) {
      const Eigen::Index k = to_input[std::size_t(i)];
      if (k >= 0 && k <= maxv && in[std::size_t(k)] && dist[std::size_t(i)] <= snap) out.push_back(int(i));
    }
  } else {
    for (Eigen::Index i = 0; i < V.rows(); ++i)
      if (r.contains(V.row(i).transpose())) out.push_back(int(i));
  }
  return out;
}

std::vector<int> resolve_region_tets(const TetRegion& r, const TetMesh& tets, const std::vector<Eigen::Index>& to_input,
                                     const std::vector<double>& dist, double snap) {
  std::vector<int> out;
  if (r.kind == TetRegion::Vertices) {
    const std::vector<int> vs = resolve_region_vertices(r, tets.V, to_input, dist, snap);
    std::vector<char> in(std::size_t(tets.V.rows()), 0);
    for (int v : vs) in[std::size_t(v)] = 1;
    for (Eigen::Index t = 0; t < tets.T.rows(); ++t)
      if (in[std::size_t(tets.T(t, 0))] && in[std::size_t(tets.T(t, 1))] && in[std::size_t(tets.T(t, 2))] && in[std::size_t(tets.T(t, 3))])
        out.push_back(int(t));
  } else {
    for (Eigen::Index t = 0; t < tets.T.rows(); ++t) {
      const Eigen::Vector3d c = 0.25 * (tets.V.row(tets.T(t, 0)) + tets.V.row(tets.T(t, 1)) + tets.V.row(tets.T(t, 2)) + tets.V.row(tets.T(t, 3))).transpose();
      if (r.contains(c)) out.push_back(int(t));
    }
  }
  return out;
}

}  // namespace tbsp
