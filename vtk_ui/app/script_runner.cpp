#include "script_runner.h"

#include <QApplication>
#include <fstream>
#include <set>

#include "studio_window.h"
#include "tbsp/core/error.h"
#include "tbsp/io/atomic_file.h"

namespace tbsp::studio {

namespace {

const std::set<std::string> kActions = {"open", "add", "edit", "select", "add_handle", "add_rigid", "add_stiffness", "drag", "iterate",
                                        "wait", "undo", "redo", "frame", "camera", "screenshot", "app_screenshot", "save",
                                        "report", "reset_measurements", "iterations_per_change", "rotation_field", "load_handles"};

Eigen::Vector3d vec3(const nlohmann::json& j, const std::string& where) {
  if (!j.is_array() || j.size() != 3 || !j[0].is_number() || !j[1].is_number() || !j[2].is_number())
    throw InvalidInput(where + ": expected [x, y, z]");
  return {j[0].get<double>(), j[1].get<double>(), j[2].get<double>()};
}

}  // namespace

nlohmann::json load_script(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw FileError(path + ": cannot open the script");
  nlohmann::json doc;
  try {
    doc = nlohmann::json::parse(in);
  } catch (const std::exception& e) {
    throw FileError(path + ": not valid JSON (" + e.what() + ")");
  }
  if (!doc.is_object() || !doc.contains("actions") || !doc["actions"].is_array())
    throw FileError(path + ": a script is {\"actions\": [{\"open\": \"mesh.ply\"}, ...]} (docs/studio.md)");
  for (std::size_t i = 0; i < doc["actions"].size(); ++i) {
    const auto& a = doc["actions"][i];
    const std::string where = path + ": actions[" + std::to_string(i) + "]";
    if (!a.is_object() || a.size() != 1)
      throw FileError(where + ": each action is an object with one key, e.g. {\"iterate\": 20}");
    const std::string k = a.begin().key();
    if (!kActions.count(k)) {
      std::string known;
      for (const auto& s : kActions) known += (known.empty() ? "" : ", ") + s;
      throw FileError(where + ": unknown action \"" + k + "\" (known: " + known + ")");
    }
    const auto& v = a.begin().value();
    auto need = [&](bool ok, const std::string& what) {
      if (!ok) throw FileError(where + " (\"" + k + "\"): " + what);
    };
    if (k == "open" || k == "add" || k == "screenshot" || k == "app_screenshot" || k == "report") need(v.is_string(), "expected a file path");
    if (k == "edit") need(v.is_string() || (v.is_object() && v.contains("mesh") && v["mesh"].is_string()),
                          "expected a path or {\"mesh\": PATH, \"tets\": N}");
    if (k == "iterate" || k == "undo" || k == "redo" || k == "frame" || k == "iterations_per_change")
      need(v.is_number_integer() && v.get<long>() >= 0, "expected a non-negative integer");
    if (k == "select") need(v.is_object() && v.contains("rect") && v["rect"].is_array() && v["rect"].size() == 4,
                            "expected {\"rect\": [x0, y0, x1, y1]} (pixels of the 3D view, origin top-left)");
    if (k == "drag") {
      need(v.is_object() && v.contains("handle") && v["handle"].is_number_integer(), "expected {\"handle\": i, \"translate\": [x, y, z], ...}");
      try {
        if (v.contains("translate")) vec3(v["translate"], "translate");
        if (v.contains("rotate")) {
          vec3(v["rotate"].at("axis"), "rotate.axis");
          need(v["rotate"].at("degrees").is_number(), "rotate.degrees: expected a number");
          vec3(v["rotate"].at("center"), "rotate.center");
        }
      } catch (const std::exception& e) {
        throw FileError(where + " (\"drag\"): " + e.what());
      }
    }
    if (k == "rotation_field") need(v.is_boolean(), "expected true or false");
    if (k == "load_handles") need(v.is_string() || (v.is_object() && v.contains("handles")),
                                  "expected a path or {\"handles\": PATH, \"rigid\": PATH, \"stiffness\": PATH}");
    if (k == "edit" && v.is_object() && v.contains("solver"))
      need(v["solver"] == "tet" || v["solver"] == "surface", "solver: \"tet\" (TetDeformer) or \"surface\" (LaplacianDeformer)");
    if (k == "save") need(v.is_object() && v.contains("mesh") && v.contains("handles"),
                          "expected {\"mesh\": PATH, \"handles\": PATH, \"iterations\": K}");
    if (k == "add_stiffness") need(v.is_object() && v.contains("stiffness") && v["stiffness"].is_number(),
                                   "expected {\"region\": REGION or \"selection\", \"stiffness\": s}");
  }
  return doc["actions"];
}

ScriptRunner::ScriptRunner(StudioWindow& w, const std::string& path) : w_(w), path_(path), actions_(load_script(path)) {
  poll_.setInterval(5);
  connect(&poll_, &QTimer::timeout, this, &ScriptRunner::step);
}

void ScriptRunner::start() { QTimer::singleShot(0, this, &ScriptRunner::step); }

void ScriptRunner::next() {
  ++index_;
  waiting_ = false;
  poll_.stop();
  QTimer::singleShot(0, this, &ScriptRunner::step);
}

void ScriptRunner::step() {
  if (index_ >= actions_.size()) {
    poll_.stop();
    QApplication::exit(w_.errors() > 0 ? 2 : 0);
    return;
  }
  bool done = true;
  try {
    done = run(actions_[index_]);
  } catch (const std::exception& e) {
    w_.showError(QString::fromStdString(path_ + ": actions[" + std::to_string(index_) + "]: " + e.what()));
  }
  if (done) next();
  else if (!poll_.isActive()) poll_.start();
}

bool ScriptRunner::run(const nlohmann::json& a) {
  const std::string k = a.begin().key();
  const auto& v = a.begin().value();
  auto region = [&](const nlohmann::json& r) { return r.is_string() && r == "selection" ? w_.selectionRegion() : r; };
  if (k == "iterate" || k == "wait") {
    if (!waiting_) {
      if (k == "iterate") w_.session().requestIterations(v.get<int>());
      waiting_ = true;
      return false;
    }
    if (w_.session().busy()) return false;
    QApplication::processEvents();  // the last frame's queued view update
    return true;
  }
  if (k == "open") w_.openFile(QString::fromStdString(v.get<std::string>()));
  else if (k == "add") w_.openFile(QString::fromStdString(v.get<std::string>()), true);
  else if (k == "edit") {
    const std::string mesh = v.is_string() ? v.get<std::string>() : v["mesh"].get<std::string>();
    const long tets = v.is_object() && v.contains("tets") ? v["tets"].get<long>() : 5000;
    const bool surface = v.is_object() && v.value("solver", "tet") == "surface";
    w_.openForEditing(QString::fromStdString(mesh), tets, surface ? EditSolver::Surface : EditSolver::Tet);
  } else if (k == "select") {
    const auto& r = v["rect"];
    w_.selectRect(r[0].get<int>(), r[1].get<int>(), r[2].get<int>(), r[3].get<int>());
  } else if (k == "add_handle") w_.addHandle(region(v));
  else if (k == "add_rigid") w_.addRigid(region(v));
  else if (k == "add_stiffness") w_.addStiffness(region(v.value("region", nlohmann::json("selection"))), v["stiffness"].get<double>());
  else if (k == "drag") {
    const Eigen::Vector3d t = v.contains("translate") ? vec3(v["translate"], "translate") : Eigen::Vector3d::Zero();
    Eigen::Vector3d axis = Eigen::Vector3d::UnitZ(), c = Eigen::Vector3d::Zero();
    double deg = 0;
    if (v.contains("rotate")) {
      axis = vec3(v["rotate"]["axis"], "rotate.axis");
      deg = v["rotate"]["degrees"].get<double>();
      c = vec3(v["rotate"]["center"], "rotate.center");
    }
    w_.dragHandle(v["handle"].get<int>(), t, axis, deg, c);
  } else if (k == "undo") {
    for (int i = 0; i < v.get<int>(); ++i) w_.undo();
  } else if (k == "redo") {
    for (int i = 0; i < v.get<int>(); ++i) w_.redo();
  } else if (k == "frame") w_.setFrame(v.get<int>());
  else if (k == "camera") {
    if (v.is_string() && v == "reset") w_.viz().resetCamera();
    else w_.viz().setCameraPose(vec3(v.at("eye"), "camera.eye"), vec3(v.at("focal"), "camera.focal"), vec3(v.at("up"), "camera.up"));
    w_.viz().render();
  } else if (k == "screenshot") w_.screenshot(QString::fromStdString(v.get<std::string>()), false);
  else if (k == "app_screenshot") w_.screenshot(QString::fromStdString(v.get<std::string>()), true);
  else if (k == "save") {
    w_.session().waitIdle();
    w_.save(QString::fromStdString(v["mesh"].get<std::string>()), QString::fromStdString(v["handles"].get<std::string>()),
            QString::fromStdString(v.value("rigid", "")), QString::fromStdString(v.value("stiffness", "")), v.value("iterations", 50),
            QString::fromStdString(v.value("constraints", "")));
  } else if (k == "report") writeReport(v.get<std::string>());
  else if (k == "reset_measurements") w_.resetMeasurements();
  else if (k == "iterations_per_change") w_.setIterationsPerChange(v.get<int>());
  else if (k == "rotation_field") w_.setRotationField(v.get<bool>());
  else if (k == "load_handles") {
    if (v.is_string()) w_.loadHandles(QString::fromStdString(v.get<std::string>()));
    else w_.loadHandles(QString::fromStdString(v["handles"].get<std::string>()), QString::fromStdString(v.value("rigid", "")),
                        QString::fromStdString(v.value("stiffness", "")));
  }
  return true;
}

void ScriptRunner::writeReport(const std::string& path) {
  const LatencyStats l = w_.latency();
  std::vector<double> r = w_.renderMs();
  std::sort(r.begin(), r.end());
  nlohmann::json j;
  j["event_loop_latency_ms"] = {{"samples", l.samples}, {"median", l.median_ms}, {"p95", l.p95_ms}, {"max", l.max_ms},
                                {"timer_interval_ms", 10}};
  j["view_updates"] = w_.framesShown();
  j["view_update_ms"] = {{"median", r.empty() ? 0.0 : r[r.size() / 2]}, {"max", r.empty() ? 0.0 : r.back()}};
  j["iterations"] = w_.session().iterations();
  j["errors"] = w_.errors();
  if (w_.session().isOpen()) {
    const auto& s = w_.session().setup();
    j["mesh"] = {{"vertices", s.surface.V.rows()}, {"tets", s.tets.T.rows()}, {"tet_vertices", s.tets.V.rows()}};
    j["handles"] = w_.session().handlesDoc();
  }
  write_text_file_atomic(path, j.dump(2) + "\n");
}

}  // namespace tbsp::studio
