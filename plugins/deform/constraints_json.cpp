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

using ConstraintsCtx = JsonReader;



Eigen::Matrix3d rotation(const nlohmann::json& j, const ConstraintsCtx& c, const std::string& where) {
  if (!j.is_object()) c.fail(where, "expected {\"axis\": [x,y,z], \"angle_deg\": a}, {\"quaternion\": [w,x,y,z]} or {\"matrix\": [[..],[..],[..]]}");
  Eigen::Matrix3d R;
  if (j.contains("axis")) {
    const Eigen::Vector3d axis = c.vec3(j["axis"], where + ".axis");
    if (axis.norm() < 1e-12) c.fail(where + ".axis", "must be non-zero");
    if (!j.contains("angle_deg")) c.fail(where, "axis given without angle_deg");
    R = Eigen::AngleAxisd(c.number(j["angle_deg"], where + ".angle_deg") * M_PI / 180.0, axis.normalized()).toRotationMatrix();
  } else if (j.contains("quaternion")) {
    const auto& q = j["quaternion"];
    if (!q.is_array() || q.size() != 4) c.fail(where + ".quaternion", "expected [w, x, y, z]");
    Eigen::Quaterniond qq(c.number(q[0], where + ".quaternion"), c.number(q[1], where + ".quaternion"),
                          c.number(q[2], where + ".quaternion"), c.number(q[3], where + ".quaternion"));
    if (qq.norm() < 1e-12) c.fail(where + ".quaternion", "must be non-zero");
    R = qq.normalized().toRotationMatrix();
  } else if (j.contains("matrix")) {
    const auto& m = j["matrix"];
    if (!m.is_array() || m.size() != 3) c.fail(where + ".matrix", "expected 3 rows of 3 numbers");
    for (int r = 0; r < 3; ++r) R.row(r) = c.vec3(m[std::size_t(r)], where + ".matrix[" + std::to_string(r) + "]").transpose();
    if ((R.transpose() * R - Eigen::Matrix3d::Identity()).norm() > 1e-4 || R.determinant() < 0)
      c.fail(where + ".matrix", "is not a rotation (orthonormal with determinant +1)");
  } else {
    c.fail(where, "give axis+angle_deg, quaternion or matrix");
  }
  return R;
}

// 4x4 (row-major) or 3x4 rigid/affine transform
Eigen::Matrix4d transform(const nlohmann::json& j, const ConstraintsCtx& c, const std::string& where) {
  if (!j.is_array() || (j.size() != 4 && j.size() != 3)) c.fail(where, "expected a 4x4 (or 3x4) row-major matrix");
  Eigen::Matrix4d M = Eigen::Matrix4d::Identity();
  for (std::size_t r = 0; r < j.size(); ++r) {
    const auto& row = j[r];
    if (!row.is_array() || row.size() != 4) c.fail(where + "[" + std::to_string(r) + "]", "expected 4 numbers");
    for (int k = 0; k < 4; ++k) M(Eigen::Index(r), k) = c.number(row[std::size_t(k)], where + "[" + std::to_string(r) + "]");
  }
  return M;
}


}  // namespace

DeformJob parse_constraints_json(const nlohmann::json& doc, const TriMesh& mesh, const std::string& source) try {
  const ConstraintsCtx c{source};
  DeformJob job;
  if (!doc.is_object()) c.fail("top level", "expected an object with a \"constraints\" array");
  c.check_keys(doc, {"constraints", "laplacian", "rotation_field", "scale", "comment"}, "top level");
  if (doc.contains("laplacian")) {
    const auto& l = doc["laplacian"];
    if (l == "cotangent") job.weights = LaplacianWeights::Cotangent;
    else if (l == "uniform") job.weights = LaplacianWeights::Uniform;
    else c.fail("laplacian", "expected \"cotangent\" or \"uniform\"");
  }
  if (doc.contains("rotation_field")) job.rotation_field = c.boolean(doc["rotation_field"], "rotation_field");
  if (doc.contains("scale")) job.scale = c.positive(doc["scale"], "scale");
  if (!doc.contains("constraints") || !doc["constraints"].is_array())
    c.fail("constraints", "missing: expected an array of constraint objects");
  const auto& arr = doc["constraints"];
  for (std::size_t i = 0; i < arr.size(); ++i) {
    const std::string w = "constraints[" + std::to_string(i) + "]";
    const auto& j = arr[i];
    if (!j.is_object()) c.fail(w, "expected an object");
    c.check_keys(j, {"vertex", "vertices", "face", "bary", "type", "target", "point", "direction", "normal", "weight", "hard",
                     "rotation", "transform", "comment"},
                 w);
    DeformConstraint d;
    if (j.contains("type") && !j["type"].is_string())
      c.fail(w + ".type", "expected a string: \"position\", \"line\" or \"plane\"");
    const std::string type = j.value("type", std::string("position"));
    if (type == "position") d.type = ConstraintType::Position;
    else if (type == "line") d.type = ConstraintType::Line;
    else if (type == "plane") d.type = ConstraintType::Plane;
    else c.fail(w + ".type", "unknown type '" + type + "' (position, line or plane)");
    if (j.contains("weight")) d.weight = c.positive(j["weight"], w + ".weight");
    if (j.contains("hard")) d.hard = c.boolean(j["hard"], w + ".hard");
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
        e.at = SurfacePoint::atVertex(c.index(vs[k], w + ".vertices[" + std::to_string(k) + "]", mesh.V.rows(), "vertex"));
        e.target = (M * mesh.V.row(e.at.vertex).transpose().homogeneous()).head<3>();
        if (!e.rotation && rigid) e.rotation = Rm;
        job.constraints.push_back(e);
      }
      continue;
    }
    if (j.contains("transform")) c.fail(w + ".transform", "\"transform\" goes with \"vertices\"");
    if (j.contains("vertex")) {
      d.at = SurfacePoint::atVertex(c.index(j["vertex"], w + ".vertex", mesh.V.rows(), "vertex"));
    } else {
      const int f = c.index(j["face"], w + ".face", mesh.F.rows(), "face");
      if (!j.contains("bary")) c.fail(w, "\"face\" needs \"bary\": barycentric coordinates [b0, b1, b2]");
      const Eigen::Vector3d b = c.vec3(j["bary"], w + ".bary");
      if ((b.array() < -1e-9).any() || std::abs(b.sum() - 1) > 1e-6) c.fail(w + ".bary", "must be >= 0 and sum to 1");
      d.at = SurfacePoint::onFace(f, b);
    }
    if (d.type == ConstraintType::Position) {
      if (!j.contains("target")) c.fail(w, "position constraints need \"target\": [x, y, z]");
      d.target = c.vec3(j["target"], w + ".target");
    } else {
      const char* axis_key = d.type == ConstraintType::Line ? "direction" : "normal";
      if (!j.contains("point") || !j.contains(axis_key))
        c.fail(w, std::string(type) + " constraints need \"point\" and \"" + axis_key + "\"");
      d.target = c.vec3(j["point"], w + ".point");
      d.axis = c.vec3(j[axis_key], w + "." + axis_key);
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
