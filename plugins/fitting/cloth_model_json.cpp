#include "tbsp/plugins/cloth_model_json.h"

#include <nlohmann/json.hpp>

#include "tbsp/core/error.h"
#include "tbsp/io/atomic_file.h"
#include "tbsp/plugins/json_file.h"

namespace tbsp {

namespace {

constexpr const char* kFormat = "tbsp-animatable-model";

nlohmann::json v3(const Eigen::Vector3d& v) { return {v.x(), v.y(), v.z()}; }

nlohmann::json settings_json(const PbdSettings& s) {
  return {{"iterations", s.iterations},     {"substeps", s.substeps},         {"time_step", s.time_step},
          {"gravity", v3(s.gravity)},       {"drag_constant", s.drag_constant}, {"drag_unit", s.drag_unit},
          {"k_stretch", s.k_stretch},       {"thickness", s.thickness},       {"friction", s.friction},
          {"restitution", s.restitution},   {"self_collision", s.self_collision}, {"contact_interval", s.contact_interval},
          {"tethers", s.tethers},           {"tether_slack", s.tether_slack}, {"flat_rest_angle", s.flat_rest_angle}};
}

const nlohmann::json& member(const JsonReader& r, const nlohmann::json& j, const char* key, const std::string& where) {
  if (!j.is_object()) r.fail(where, "expected an object");
  auto it = j.find(key);
  if (it == j.end()) r.fail(where, std::string("missing \"") + key + "\"");
  return *it;
}

const nlohmann::json& array(const JsonReader& r, const nlohmann::json& j, const std::string& where) {
  if (!j.is_array()) r.fail(where, "expected an array");
  return j;
}

}  // namespace

void save_animatable_model(const std::string& path, const AnimatableModel& m) {
  m.validate("tbsp::save_animatable_model");
  nlohmann::json j;
  j["format"] = kFormat;
  j["version"] = 1;
  nlohmann::json V = nlohmann::json::array(), F = nlohmann::json::array();
  for (Eigen::Index i = 0; i < m.mesh.V.rows(); ++i) V.push_back(v3(m.mesh.V.row(i).transpose()));
  for (Eigen::Index f = 0; f < m.mesh.F.rows(); ++f) F.push_back({m.mesh.F(f, 0), m.mesh.F(f, 1), m.mesh.F(f, 2)});
  j["mesh"] = {{"vertices", V}, {"faces", F}};
  nlohmann::json joints = nlohmann::json::array();
  for (int k = 0; k < m.skeleton.numJoints(); ++k) {
    const Eigen::Matrix4d T = m.skeleton.rest[std::size_t(k)].matrix();
    nlohmann::json rest = nlohmann::json::array();
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 4; ++c) rest.push_back(T(r, c));
    joints.push_back({{"name", m.skeleton.names[std::size_t(k)]}, {"parent", m.skeleton.parents[std::size_t(k)]}, {"rest", rest}});
  }
  j["skeleton"] = {{"joints", joints}};
  nlohmann::json W = nlohmann::json::array();
  for (Eigen::Index i = 0; i < m.weights.rows(); ++i) {
    nlohmann::json row = nlohmann::json::array();
    for (SkinningWeights::InnerIterator it(m.weights, i); it; ++it) row.push_back({int(it.col()), it.value()});
    W.push_back(row);
  }
  j["weights"] = W;
  j["clothness"] = std::vector<double>(m.clothness.data(), m.clothness.data() + m.clothness.size());
  if (m.region.size()) j["region"] = std::vector<int>(m.region.data(), m.region.data() + m.region.size());
  nlohmann::json mats = nlohmann::json::array();
  for (const auto& c : m.materials) mats.push_back({{"d_n", c.d_n}, {"d_t", c.d_t}, {"k_bend", c.k_bend}});
  j["materials"] = mats;
  nlohmann::json px = nlohmann::json::array();
  for (const auto& p : m.proxies)
    px.push_back({{"joint", p.bone.joint}, {"child", p.bone.child}, {"a", v3(p.cone.a)}, {"b", v3(p.cone.b)}, {"ra", p.cone.ra}, {"rb", p.cone.rb}});
  j["proxies"] = px;
  j["settings"] = settings_json(m.settings);
  write_text_file_atomic(path, j.dump() + "\n");
}

AnimatableModel load_animatable_model(const std::string& path) {
  const nlohmann::json j = load_json_file(path);
  const JsonReader r(path);
  try {
    r.check_keys(j, {"format", "version", "mesh", "skeleton", "weights", "clothness", "region", "materials", "proxies", "settings"}, "(top)");
    const auto& fmt = member(r, j, "format", "(top)");
    if (!fmt.is_string() || fmt.get<std::string>() != kFormat)
      r.fail("format", std::string("expected \"") + kFormat + "\" (is this an animatable model written by `tbsp cloth build`?)");
    if (r.integer(member(r, j, "version", "(top)"), "version") != 1) r.fail("version", "only version 1 is known");
    AnimatableModel m;
    const auto& mesh = member(r, j, "mesh", "(top)");
    const auto& V = array(r, member(r, mesh, "vertices", "mesh"), "mesh.vertices");
    const auto& F = array(r, member(r, mesh, "faces", "mesh"), "mesh.faces");
    m.mesh.V.resize(Eigen::Index(V.size()), 3);
    for (std::size_t i = 0; i < V.size(); ++i) m.mesh.V.row(Eigen::Index(i)) = r.vec3(V[i], "mesh.vertices[" + std::to_string(i) + "]").transpose();
    m.mesh.F.resize(Eigen::Index(F.size()), 3);
    for (std::size_t f = 0; f < F.size(); ++f) {
      const std::string w = "mesh.faces[" + std::to_string(f) + "]";
      if (!F[f].is_array() || F[f].size() != 3) r.fail(w, "expected three vertex indices");
      for (int k = 0; k < 3; ++k) m.mesh.F(Eigen::Index(f), k) = r.index(F[f][std::size_t(k)], w, m.mesh.V.rows(), "vertex");
    }
    const auto& joints = array(r, member(r, member(r, j, "skeleton", "(top)"), "joints", "skeleton"), "skeleton.joints");
    for (std::size_t k = 0; k < joints.size(); ++k) {
      const std::string w = "skeleton.joints[" + std::to_string(k) + "]";
      const auto& name = member(r, joints[k], "name", w);
      if (!name.is_string()) r.fail(w + ".name", "expected a string");
      m.skeleton.names.push_back(name.get<std::string>());
      const long long parent = r.integer(member(r, joints[k], "parent", w), w + ".parent");
      if (parent < -1 || parent >= (long long)k) r.fail(w + ".parent", "must be -1 or the index of an earlier joint");
      m.skeleton.parents.push_back(int(parent));
      const auto& rest = member(r, joints[k], "rest", w);
      if (!rest.is_array() || rest.size() != 12) r.fail(w + ".rest", "expected 12 numbers (3 x 4 matrix, row-major)");
      Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
      for (int rr = 0; rr < 3; ++rr)
        for (int c = 0; c < 4; ++c) T.matrix()(rr, c) = r.number(rest[std::size_t(4 * rr + c)], w + ".rest");
      m.skeleton.rest.push_back(T);
    }
    const auto& W = array(r, member(r, j, "weights", "(top)"), "weights");
    if (Eigen::Index(W.size()) != m.mesh.V.rows())
      r.fail("weights", std::to_string(W.size()) + " rows for " + std::to_string(m.mesh.V.rows()) + " vertices");
    std::vector<Eigen::Triplet<double>> t;
    for (std::size_t i = 0; i < W.size(); ++i) {
      const std::string w = "weights[" + std::to_string(i) + "]";
      array(r, W[i], w);
      for (std::size_t q = 0; q < W[i].size(); ++q) {
        const std::string wq = w + "[" + std::to_string(q) + "]";
        if (!W[i][q].is_array() || W[i][q].size() != 2) r.fail(wq, "expected [joint, weight]");
        const int jt = r.index(W[i][q][0], wq, m.skeleton.numJoints(), "joint");
        const double wt = r.number(W[i][q][1], wq);
        t.emplace_back(int(i), jt, wt);
      }
    }
    m.weights = SkinningWeights(m.mesh.V.rows(), m.skeleton.numJoints());
    m.weights.setFromTriplets(t.begin(), t.end());
    const auto& cl = array(r, member(r, j, "clothness", "(top)"), "clothness");
    m.clothness.resize(Eigen::Index(cl.size()));
    for (std::size_t i = 0; i < cl.size(); ++i) m.clothness(Eigen::Index(i)) = r.number(cl[i], "clothness[" + std::to_string(i) + "]");
    if (j.contains("region")) {
      const auto& rg = array(r, j["region"], "region");
      m.region.resize(Eigen::Index(rg.size()));
      for (std::size_t i = 0; i < rg.size(); ++i) m.region(Eigen::Index(i)) = int(r.integer(rg[i], "region[" + std::to_string(i) + "]"));
    }
    const auto& mats = array(r, member(r, j, "materials", "(top)"), "materials");
    for (std::size_t k = 0; k < mats.size(); ++k) {
      const std::string w = "materials[" + std::to_string(k) + "]";
      r.check_keys(mats[k], {"d_n", "d_t", "k_bend"}, w);
      m.materials.push_back({r.number(member(r, mats[k], "d_n", w), w + ".d_n"), r.number(member(r, mats[k], "d_t", w), w + ".d_t"),
                             r.number(member(r, mats[k], "k_bend", w), w + ".k_bend")});
    }
    const auto& px = array(r, member(r, j, "proxies", "(top)"), "proxies");
    for (std::size_t k = 0; k < px.size(); ++k) {
      const std::string w = "proxies[" + std::to_string(k) + "]";
      CollisionProxy p;
      p.bone.joint = r.index(member(r, px[k], "joint", w), w + ".joint", m.skeleton.numJoints(), "joint");
      p.bone.child = r.index(member(r, px[k], "child", w), w + ".child", m.skeleton.numJoints(), "joint");
      p.cone.a = r.vec3(member(r, px[k], "a", w), w + ".a");
      p.cone.b = r.vec3(member(r, px[k], "b", w), w + ".b");
      p.cone.ra = r.number(member(r, px[k], "ra", w), w + ".ra");
      p.cone.rb = r.number(member(r, px[k], "rb", w), w + ".rb");
      m.proxies.push_back(p);
    }
    const auto& s = member(r, j, "settings", "(top)");
    r.check_keys(s, {"iterations", "substeps", "time_step", "gravity", "drag_constant", "drag_unit", "k_stretch", "thickness", "friction",
                     "restitution", "self_collision", "contact_interval", "tethers", "tether_slack", "flat_rest_angle"},
                 "settings");
    PbdSettings& st = m.settings;
    auto num = [&](const char* k, double& out) {
      if (s.contains(k)) out = r.number(s[k], std::string("settings.") + k);
    };
    auto integer = [&](const char* k, int& out) {
      if (s.contains(k)) out = int(r.integer(s[k], std::string("settings.") + k));
    };
    auto flag = [&](const char* k, bool& out) {
      if (s.contains(k)) out = r.boolean(s[k], std::string("settings.") + k);
    };
    integer("iterations", st.iterations);
    integer("substeps", st.substeps);
    num("time_step", st.time_step);
    if (s.contains("gravity")) st.gravity = r.vec3(s["gravity"], "settings.gravity");
    num("drag_constant", st.drag_constant);
    num("drag_unit", st.drag_unit);
    num("k_stretch", st.k_stretch);
    num("thickness", st.thickness);
    num("friction", st.friction);
    num("restitution", st.restitution);
    flag("self_collision", st.self_collision);
    integer("contact_interval", st.contact_interval);
    flag("tethers", st.tethers);
    num("tether_slack", st.tether_slack);
    flag("flat_rest_angle", st.flat_rest_angle);
    try {
      m.validate("model");
      validate_pbd_settings(st, "model settings");
    } catch (const InvalidInput& e) {
      throw FileError(path + ": " + e.what());
    }
    return m;
  } catch (const nlohmann::json::exception& e) {
    throw_json_structure_error(path, e);
  }
}

}  // namespace tbsp
