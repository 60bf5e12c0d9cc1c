#include "tbsp/plugins/tet_job_json.h"

#include <algorithm>
#include <cmath>

#include "tbsp/core/error.h"
#include "tbsp/plugins/json_file.h"

namespace tbsp {

namespace {
using json = nlohmann::json;

// Reads one region from the keys "vertices" | "sphere" | "box" of `j`; false if none present.
bool parse_region(const json& j, Eigen::Index n, const JsonReader& in, const std::string& where, TetRegion& r) {
  int count = int(j.contains("vertices")) + int(j.contains("sphere")) + int(j.contains("box"));
  if (count == 0) return false;
  if (count > 1) in.fail(where, "give one of \"vertices\", \"sphere\" or \"box\", not several");
  if (j.contains("vertices")) {
    const json& v = j["vertices"];
    if (!v.is_array() || v.empty()) in.fail(where + ".vertices", "expected a non-empty array of vertex indices");
    r.kind = TetRegion::Vertices;
    for (std::size_t i = 0; i < v.size(); ++i)
      r.vertices.push_back(in.index(v[i], where + ".vertices[" + std::to_string(i) + "]", n, "vertex"));
  } else if (j.contains("sphere")) {
    const json& s = j["sphere"];
    if (!s.is_object() || !s.contains("center") || !s.contains("radius"))
      in.fail(where + ".sphere", "expected {\"center\": [x, y, z], \"radius\": r}");
    r.kind = TetRegion::Sphere;
    r.a = in.vec3(s["center"], where + ".sphere.center");
    r.radius = in.number(s["radius"], where + ".sphere.radius");
    if (!(r.radius > 0)) in.fail(where + ".sphere.radius", "must be > 0");
  } else {
    const json& b = j["box"];
    if (!b.is_object() || !b.contains("min") || !b.contains("max"))
      in.fail(where + ".box", "expected {\"min\": [x, y, z], \"max\": [x, y, z]}");
    r.kind = TetRegion::Box;
    r.a = in.vec3(b["min"], where + ".box.min");
    r.b = in.vec3(b["max"], where + ".box.max");
    if ((r.b.array() < r.a.array()).any()) in.fail(where + ".box", "min must not exceed max");
  }
  return true;
}

}  // namespace

bool TetRegion::contains(const Eigen::Vector3d& p) const {
  if (kind == Sphere) return (p - a).norm() <= radius;
  if (kind == Box) return (p.array() >= a.array()).all() && (p.array() <= b.array()).all();
  return false;
}

void parse_tet_handles(const json& doc, Eigen::Index n, const std::string& source, TetJob& job) try {
  const JsonReader in(source);
  if (!doc.is_object()) in.fail("top level", "expected an object with a \"handles\" array");
  in.check_keys(doc, {"handles", "iterations", "rotation_interpolation", "max_step_degrees", "comment"}, "top level");
  if (!doc.contains("handles") || !doc["handles"].is_array())
    in.fail("handles", "missing: give an array of handles (docs/tetdeform_json.md)");
  const json& hs = doc["handles"];
  if (hs.empty()) in.fail("handles", "empty: at least one handle is needed, or the deformation is undetermined");
  for (std::size_t i = 0; i < hs.size(); ++i) {
    const std::string w = "handles[" + std::to_string(i) + "]";
    const json& h = hs[i];
    if (!h.is_object()) in.fail(w, "expected an object");
    in.check_keys(h, {"vertices", "sphere", "box", "vertex", "point", "target", "translate", "rotate", "comment"}, w);
    TetHandleSpec spec;
    spec.where = w;
    if (h.contains("vertex") || h.contains("point")) {
      if (h.contains("vertex") && h.contains("point")) in.fail(w, "give \"vertex\" or \"point\", not both");
      if (!h.contains("target")) in.fail(w, "a vertex or point handle needs a \"target\": [x, y, z]");
      if (h.contains("rotate") || h.contains("translate"))
        in.fail(w, "vertex/point handles take a \"target\"; \"rotate\"/\"translate\" belong to regions");
      if (h.contains("vertex")) {
        spec.kind = TetHandleSpec::Vertex;
        spec.vertex = in.index(h["vertex"], w + ".vertex", n, "vertex");
      } else {
        spec.kind = TetHandleSpec::Point;
        spec.point = in.vec3(h["point"], w + ".point");
      }
      spec.target = in.vec3(h["target"], w + ".target");
    } else {
      spec.kind = TetHandleSpec::Region;
      if (!parse_region(h, n, in, w, spec.region))
        in.fail(w, "a handle needs \"vertices\", \"sphere\", \"box\" (regions) or \"vertex\"/\"point\" + \"target\"");
      if (h.contains("target")) in.fail(w, "regions move by \"translate\"/\"rotate\", not \"target\"");
      if (h.contains("translate")) spec.motion.translation = in.vec3(h["translate"], w + ".translate");
      if (h.contains("rotate")) {
        const json& r = h["rotate"];
        const std::string wr = w + ".rotate";
        if (!r.is_object() || !r.contains("axis") || !r.contains("degrees"))
          in.fail(wr, "expected {\"axis\": [x, y, z], \"degrees\": a, \"center\": [x, y, z]}");
        in.check_keys(r, {"axis", "degrees", "center"}, wr);
        spec.motion.axis = in.vec3(r["axis"], wr + ".axis");
        if (!(spec.motion.axis.norm() > 0)) in.fail(wr + ".axis", "the axis is zero");
        spec.motion.angle = in.number(r["degrees"], wr + ".degrees") * M_PI / 180.0;
        if (r.contains("center")) spec.motion.center = in.vec3(r["center"], wr + ".center");
        else in.fail(wr, "missing \"center\": the point the region turns about");
      }
    }
    job.handles.push_back(spec);
  }
  if (doc.contains("iterations")) {
    if (!doc["iterations"].is_number_integer() || doc["iterations"].get<long long>() < 1)
      in.fail("iterations", "expected a positive integer");
    job.iterations = int(doc["iterations"].get<long long>());
  }
  if (doc.contains("rotation_interpolation")) {
    if (!doc["rotation_interpolation"].is_boolean()) in.fail("rotation_interpolation", "expected true or false");
    job.rotation_interpolation = doc["rotation_interpolation"].get<bool>();
  }
  if (doc.contains("max_step_degrees")) {
    const double v = in.number(doc["max_step_degrees"], "max_step_degrees");
    if (!(v > 0 && v < 180)) in.fail("max_step_degrees", "must be in (0, 180)");
    job.max_step_degrees = v;
  }
} catch (const nlohmann::json::exception& e) {
  throw_json_structure_error(source, e);
}

void parse_tet_rigid(const json& doc, Eigen::Index n, const std::string& source, TetJob& job) try {
  const JsonReader in(source);
  if (!doc.is_object() || !doc.contains("rigid") || !doc["rigid"].is_array())
    in.fail("top level", "expected {\"rigid\": [region, ...]} (docs/tetdeform_json.md)");
  const json& rs = doc["rigid"];
  for (std::size_t i = 0; i < rs.size(); ++i) {
    const std::string w = "rigid[" + std::to_string(i) + "]";
    if (!rs[i].is_object()) in.fail(w, "expected an object");
    in.check_keys(rs[i], {"vertices", "sphere", "box", "comment"}, w);
    TetRegion r;
    if (!parse_region(rs[i], n, in, w, r)) in.fail(w, "needs \"vertices\", \"sphere\" or \"box\"");
    job.rigid.push_back(r);
  }
} catch (const nlohmann::json::exception& e) {
  throw_json_structure_error(source, e);
}

void parse_tet_stiffness(const json& doc, Eigen::Index n, const std::string& source, TetJob& job) try {
  const JsonReader in(source);
  if (!doc.is_object()) in.fail("top level", "expected {\"default\": s, \"regions\": [...]}");
  in.check_keys(doc, {"default", "regions", "comment"}, "top level");
  if (doc.contains("default")) {
    job.default_stiffness = in.number(doc["default"], "default");
    if (!(job.default_stiffness > 0)) in.fail("default", "stiffness must be > 0");
  }
  if (doc.contains("regions")) {
    if (!doc["regions"].is_array()) in.fail("regions", "expected an array");
    const json& rs = doc["regions"];
    for (std::size_t i = 0; i < rs.size(); ++i) {
      const std::string w = "regions[" + std::to_string(i) + "]";
      if (!rs[i].is_object()) in.fail(w, "expected an object");
      in.check_keys(rs[i], {"vertices", "sphere", "box", "stiffness", "comment"}, w);
      TetRegion r;
      if (!parse_region(rs[i], n, in, w, r)) in.fail(w, "needs \"vertices\", \"sphere\" or \"box\"");
      if (!rs[i].contains("stiffness")) in.fail(w, "missing \"stiffness\"");
      const double s = in.number(rs[i]["stiffness"], w + ".stiffness");
      if (!(s > 0)) in.fail(w + ".stiffness", "must be > 0 (mark rigid parts with --rigid instead)");
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
