#include "tbsp/plugins/constraints_json.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <fstream>
#include <sstream>

#include "tbsp/core/error.h"
#include "tbsp/plugins/json_file.h"

namespace tbsp {

namespace {

struct Ctx {
  const std::string& source;
  [[noreturn]] void fail(const std::string& where, const std::string& msg) const {
    throw FileError(source + ": " + where + ": " + msg);
  }
};

Eigen::Vector3d vec3(const nlohmann::json& j, const Ctx& c, const std::string& where) {
  if (!j.is_array() || j.size() != 3) c.fail(where, "expected an array of 3 numbers, e.g. [0.1, 0.2, 0.3]");
  Eigen::Vector3d v;
  for (int k = 0; k < 3; ++k) {
    if (!j[std::size_t(k)].is_number()) c.fail(where, "expected an array of 3 numbers, e.g. [0.1, 0.2, 0.3]");
    v(k) = j[std::size_t(k)].get<double>();
  }
  if (!v.allFinite()) c.fail(where, "values must be finite");
  return v;
}

double number(const nlohmann::json& j, const Ctx& c, const std::string& where) {
  if (!j.is_number()) c.fail(where, "expected a number");
  const double v = j.get<double>();
  if (!std::isfinite(v)) c.fail(where, "must be finite");
  return v;
}

Eigen::Matrix3d rotation(const nlohmann::json& j, const Ctx& c, const std::string& where) {
  if (!j.is_object()) c.fail(where, "expected {\"axis\": [x,y,z], \"angle_deg\": a}, {\"quaternion\": [w,x,y,z]} or {\"matrix\": [[..],[..],[..]]}");
  Eigen::Matrix3d R;
  if (j.contains("axis")) {
    const Eigen::Vector3d axis = vec3(j["axis"], c, where + ".axis");
    if (axis.norm() < 1e-12) c.fail(where + ".axis", "must be non-zero");
    if (!j.contains("angle_deg")) c.fail(where, "axis given without angle_deg");
    R = Eigen::AngleAxisd(number(j["angle_deg"], c, where + ".angle_deg") * M_PI / 180.0, axis.normalized()).toRotationMatrix();
  } else if (j.contains("quaternion")) {
    const auto& q = j["quaternion"];
    if (!q.is_array() || q.size() != 4) c.fail(where + ".quaternion", "expected [w, x, y, z]");
    Eigen::Quaterniond qq(number(q[0], c, where + ".quaternion"), number(q[1], c, where + ".quaternion"),
                          number(q[2], c, where + ".quaternion"), number(q[3], c, where + ".quaternion"));
    if (qq.norm() < 1e-12) c.fail(where + ".quaternion", "must be non-zero");
    R = qq.normalized().toRotationMatrix();
  } else if (j.contains("matrix")) {
    const auto& m = j["matrix"];
    if (!m.is_array() || m.size() != 3) c.fail(where + ".matrix", "expected 3 rows of 3 numbers");
    for (int r = 0; r < 3; ++r) R.row(r) = vec3(m[std::size_t(r)], c, where + ".matrix[" + std::to_string(r) + "]").transpose();
    if ((R.transpose() * R - Eigen::Matrix3d::Identity()).norm() > 1e-4 || R.determinant() < 0)
      c.fail(where + ".matrix", "is not a rotation (orthonormal with determinant +1)");
  } else {
    c.fail(where, "give axis+angle_deg, quaternion or matrix");
  }
  return R;
}

// 4x4 (row-major) or 3x4 rigid/affine transform
Eigen::Matrix4d transform(const nlohmann::json& j, const Ctx& c, const std::string& where) {
  if (!j.is_array() || (j.size() != 4 && j.size() != 3)) c.fail(where, "expected a 4x4 (or 3x4) row-major matrix");
  Eigen::Matrix4d M = Eigen::Matrix4d::Identity();
  for (std::size_t r = 0; r < j.size(); ++r) {
    const auto& row = j[r];
    if (!row.is_array() || row.size() != 4) c.fail(where + "[" + std::to_string(r) + "]", "expected 4 numbers");
    for (int k = 0; k < 4; ++k) M(Eigen::Index(r), k) = number(row[std::size_t(k)], c, where + "[" + std::to_string(r) + "]");
  }
  return M;
}

int index(const nlohmann::json& j, const Ctx& c, const std::string& where, Eigen::Index limit, const char* kind) {
  if (!j.is_number_integer()) c.fail(where, std::string("expected an integer ") + kind + " index");
  const long long v = j.get<long long>();
  if (v < 0 || v >= limit)
    c.fail(where, std::string(kind) + " " + std::to_string(v) + " does not exist: the mesh has " + std::to_string(limit) + " " +
                      kind + "s (valid: 0.." + std::to_string(limit - 1) + ")");
  return int(v);
}

}  // namespace

DeformJob parse_constraints_json(const nlohmann::json& doc, const TriMesh& mesh, const std::string& source) try {
  const Ctx c{source};
  DeformJob job;
  if (!doc.is_object()) c.fail("top level", "expected an object with a \"constraints\" array");
  for (auto it = doc.begin(); it != doc.end(); ++it)
    if (it.key() != "constraints" && it.key() != "laplacian" && it.key() != "rotation_field" && it.key() != "scale" &&
        it.key() != "comment")
      c.fail(it.key(), "unknown key (known: constraints, laplacian, rotation_field, scale, comment)");
  if (doc.contains("laplacian")) {
    const auto& l = doc["laplacian"];
    if (l == "cotangent") job.weights = LaplacianWeights::Cotangent;
    else if (l == "uniform") job.weights = LaplacianWeights::Uniform;
    else c.fail("laplacian", "expected \"cotangent\" or \"uniform\"");
  }
  if (doc.contains("rotation_field")) {
    if (!doc["rotation_field"].is_boolean()) c.fail("rotation_field", "expected true or false");
    job.rotation_field = doc["rotation_field"].get<bool>();
  }
  if (doc.contains("scale")) {
    job.scale = number(doc["scale"], c, "scale");
    if (!(job.scale > 0)) c.fail("scale", "must be > 0");
  }
  if (!doc.contains("constraints") || !doc["constraints"].is_array())
    c.fail("constraints", "missing: expected an array of constraint objects");
  const auto& arr = doc["constraints"];
  for (std::size_t i = 0; i < arr.size(); ++i) {
    const std::string w = "constraints[" + std::to_string(i) + "]";
    const auto& j = arr[i];
    if (!j.is_object()) c.fail(w, "expected an object");
    for (auto it = j.begin(); it != j.end(); ++it) {
      static const char* known[] = {"vertex", "vertices", "face", "bary", "type", "target", "point", "direction",
                                    "normal", "weight", "hard", "rotation", "transform", "comment"};
      if (std::find(std::begin(known), std::end(known), it.key()) == std::end(known))
        c.fail(w + "." + it.key(), "unknown key");
    }
    DeformConstraint d;
    if (j.contains("type") && !j["type"].is_string())
      c.fail(w + ".type", "expected a string: \"position\", \"line\" or \"plane\"");
    const std::string type = j.value("type", std::string("position"));
    if (type == "position") d.type = ConstraintType::Position;
    else if (type == "line") d.type = ConstraintType::Line;
    else if (type == "plane") d.type = ConstraintType::Plane;
    else c.fail(w + ".type", "unknown type '" + type + "' (position, line or plane)");
    if (j.contains("weight")) {
      d.weight = number(j["weight"], c, w + ".weight");
      if (!(d.weight > 0)) c.fail(w + ".weight", "must be > 0");
    }
    if (j.contains("hard")) {
      if (!j["hard"].is_boolean()) c.fail(w + ".hard", "expected true or false");
      d.hard = j["hard"].get<bool>();
    }
    if (j.contains("rotation")) d.rotation = rotation(j["rotation"], c, w + ".rotation");
    const int where_count = int(j.contains("vertex")) + int(j.contains("vertices")) + int(j.contains("face"));
    if (where_count != 1) c.fail(w, "give exactly one of \"vertex\", \"vertices\" or \"face\" (+ \"bary\")");
    if (d.hard && (d.type != ConstraintType::Position || j.contains("face")))
      c.fail(w + ".hard", "hard constraints must be position constraints on vertices");
    if (j.contains("vertices")) {
      // a group of vertices moved by one transform (targets = M · rest position)
      if (d.type != ConstraintType::Position) c.fail(w + ".vertices", "vertex groups take position constraints only");
      if (!j.contains("transform") && !j.contains("target"))
        c.fail(w, "a vertex group needs \"transform\" (4x4) or \"target\" (a common translation is not enough: use transform)");
      if (!j.contains("transform")) c.fail(w + ".target", "vertex groups use \"transform\"; \"target\" is for single points");
      const Eigen::Matrix4d M = transform(j["transform"], c, w + ".transform");
      const auto& vs = j["vertices"];
      if (!vs.is_array() || vs.empty()) c.fail(w + ".vertices", "expected a non-empty array of vertex indices");
      Eigen::Matrix3d Rm = M.topLeftCorner<3, 3>();
      const bool rigid = (Rm.transpose() * Rm - Eigen::Matrix3d::Identity()).norm() < 1e-6 && Rm.determinant() > 0;
      for (std::size_t k = 0; k < vs.size(); ++k) {
        DeformConstraint e = d;
        e.group = int(i);  // one handle: one node of the rotation field, whatever its size
        e.at = SurfacePoint::atVertex(index(vs[k], c, w + ".vertices[" + std::to_string(k) + "]", mesh.V.rows(), "vertex"));
        e.target = (M * mesh.V.row(e.at.vertex).transpose().homogeneous()).head<3>();
        if (!e.rotation && rigid) e.rotation = Rm;
        job.constraints.push_back(e);
      }
      continue;
    }
    if (j.contains("transform")) c.fail(w + ".transform", "\"transform\" goes with \"vertices\"");
    if (j.contains("vertex")) {
      d.at = SurfacePoint::atVertex(index(j["vertex"], c, w + ".vertex", mesh.V.rows(), "vertex"));
    } else {
      const int f = index(j["face"], c, w + ".face", mesh.F.rows(), "face");
      if (!j.contains("bary")) c.fail(w, "\"face\" needs \"bary\": barycentric coordinates [b0, b1, b2]");
      const Eigen::Vector3d b = vec3(j["bary"], c, w + ".bary");
      if ((b.array() < -1e-9).any() || std::abs(b.sum() - 1) > 1e-6) c.fail(w + ".bary", "must be >= 0 and sum to 1");
      d.at = SurfacePoint::onFace(f, b);
    }
    if (d.type == ConstraintType::Position) {
      if (!j.contains("target")) c.fail(w, "position constraints need \"target\": [x, y, z]");
      d.target = vec3(j["target"], c, w + ".target");
    } else {
      const char* axis_key = d.type == ConstraintType::Line ? "direction" : "normal";
      if (!j.contains("point") || !j.contains(axis_key))
        c.fail(w, std::string(type) + " constraints need \"point\" and \"" + axis_key + "\"");
      d.target = vec3(j["point"], c, w + ".point");
      d.axis = vec3(j[axis_key], c, w + "." + axis_key);
      if (d.axis.norm() < 1e-12) c.fail(w + "." + axis_key, "must be non-zero");
    }
    job.constraints.push_back(d);
  }
  return job;
} catch (const nlohmann::json::exception& e) {
  throw_json_structure_error(source, e);
}

DeformJob load_constraints_json(const std::string& path, const TriMesh& mesh) {
  return parse_constraints_json(load_json_file(path), mesh, path);
}

}  // namespace tbsp
