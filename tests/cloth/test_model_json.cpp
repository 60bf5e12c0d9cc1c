// The animatable-model file: round trip and malformed content (every parser gets these tests).
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>

#include "cloth_test_util.h"
#include "tbsp/core/error.h"
#include "tbsp/plugins/cloth_model_json.h"

namespace fs = std::filesystem;
using namespace tbsp;

namespace {

AnimatableModel small_model() {
  AnimatableModel m;
  m.mesh = make_tube(9, 8, 1.0, 0.1);
  m.skeleton = cloth_test::two_bone_skeleton();
  m.weights = bone_heat_weights(m.mesh.V, m.mesh.F, m.skeleton);
  m.clothness = Eigen::VectorXd::Zero(m.mesh.V.rows());
  m.clothness.tail(20).setConstant(1.0);
  m.materials = {{1.5, 7.0, 0.4}};
  CollisionProxy p;
  p.bone = {0, 1};
  p.cone = {{0, 0, 0}, {0.5, 0, 0}, 0.05, 0.04};
  m.proxies = {p};
  m.settings.thickness = 0.004;
  return m;
}

fs::path tmp(const char* name) { return fs::temp_directory_path() / (std::string("tbsp_model_") + name + "_" + std::to_string(::getpid()) + ".json"); }

// Writes the saved model with `edit` applied and expects a FileError naming the file and `item`.
void expect_bad(const std::function<void(nlohmann::json&)>& edit, const std::string& item) {
  const fs::path p = tmp("bad");
  save_animatable_model(p.string(), small_model());
  nlohmann::json j;
  {
    std::ifstream in(p);
    j = nlohmann::json::parse(in);
  }
  edit(j);
  {
    std::ofstream(p) << j.dump();
  }
  try {
    load_animatable_model(p.string());
    ADD_FAILURE() << "accepted a model with a bad " << item;
  } catch (const FileError& e) {
    EXPECT_NE(std::string(e.what()).find(p.string()), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find(item), std::string::npos) << e.what();
  }
  fs::remove(p);
}

}  // namespace

TEST(ModelJson, RoundTripKeepsEverything) {
  const AnimatableModel m = small_model();
  const fs::path p = tmp("rt");
  save_animatable_model(p.string(), m);
  const AnimatableModel r = load_animatable_model(p.string());
  EXPECT_EQ((r.mesh.V - m.mesh.V).cwiseAbs().maxCoeff(), 0.0);
  EXPECT_EQ(r.mesh.F, m.mesh.F);
  EXPECT_EQ(r.skeleton.names, m.skeleton.names);
  EXPECT_EQ(r.skeleton.parents, m.skeleton.parents);
  EXPECT_EQ(Eigen::MatrixXd(r.weights - m.weights).cwiseAbs().maxCoeff(), 0.0);
  EXPECT_EQ(r.clothness, m.clothness);
  EXPECT_EQ(r.materials[0].d_t, 7.0);
  EXPECT_EQ(r.proxies[0].cone.rb, 0.04);
  EXPECT_EQ(r.settings.thickness, 0.004);
  fs::remove(p);
}

TEST(ModelJson, MalformedFilesNameTheItem) {
  expect_bad([](nlohmann::json& j) { j["format"] = "mesh"; }, "format");
  expect_bad([](nlohmann::json& j) { j["version"] = 7; }, "version");
  expect_bad([](nlohmann::json& j) { j.erase("weights"); }, "weights");
  expect_bad([](nlohmann::json& j) { j["weights"].erase(0); }, "weights");
  expect_bad([](nlohmann::json& j) { j["weights"][3][0][0] = 99; }, "weights[3][0]");
  expect_bad([](nlohmann::json& j) { j["mesh"]["faces"][2][1] = -4; }, "mesh.faces[2]");
  expect_bad([](nlohmann::json& j) { j["mesh"]["vertices"][1] = {1, 2}; }, "mesh.vertices[1]");
  expect_bad([](nlohmann::json& j) { j["skeleton"]["joints"][1]["parent"] = 5; }, "skeleton.joints[1].parent");
  expect_bad([](nlohmann::json& j) { j["clothness"][0] = 3.0; }, "clothness");
  expect_bad([](nlohmann::json& j) { j["materials"][0]["k_bend"] = 2.0; }, "material");
  expect_bad([](nlohmann::json& j) { j["settings"]["iterations"] = 0; }, "iterations");
  expect_bad([](nlohmann::json& j) { j["settings"]["colour"] = 1; }, "colour");
  expect_bad([](nlohmann::json& j) { j["proxies"][0]["joint"] = "hip"; }, "proxies[0].joint");
  // truncated file, empty file
  const fs::path p = tmp("trunc");
  save_animatable_model(p.string(), small_model());
  fs::resize_file(p, fs::file_size(p) / 2);
  EXPECT_THROW(load_animatable_model(p.string()), FileError);
  fs::resize_file(p, 0);
  EXPECT_THROW(load_animatable_model(p.string()), FileError);
  fs::remove(p);
  EXPECT_THROW(load_animatable_model("/nonexistent/model.json"), FileError);
}

TEST(ModelJson, AnInvalidModelIsNotWritten) {
  AnimatableModel m = small_model();
  m.clothness.resize(3);
  const fs::path p = tmp("invalid");
  EXPECT_THROW(save_animatable_model(p.string(), m), InvalidInput);
  EXPECT_FALSE(fs::exists(p));
}
