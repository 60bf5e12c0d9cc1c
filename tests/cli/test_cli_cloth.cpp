// `tbsp cloth synth|segment|proxies|build|animate` end to end on the CMU clips, and their bad inputs.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>

#include "cli_util.h"
#include "test_util.h"
#include "tbsp/io/mesh_io.h"
#include "tbsp/plugins/cloth_model_json.h"

namespace fs = std::filesystem;
using tbsp::test::run_cli;

namespace {

std::string clip(const char* name) { return std::string(TBSP_SHARED_DATA_DIR) + "/capture/dopomoc__BVH/" + name; }

fs::path temp_dir(const char* name) {
  const fs::path d = fs::temp_directory_path() / (std::string("tbsp_cloth_") + name + "_" + std::to_string(::getpid()));
  fs::remove_all(d);
  fs::create_directories(d);
  return d;
}

nlohmann::json read_json(const fs::path& p) {
  std::ifstream in(p);
  return nlohmann::json::parse(in);
}

}  // namespace

TEST(CliCloth, SynthSegmentBuildAnimate) {
  TBSP_REQUIRE_FILE(clip("02_05.bvh"));
  const fs::path d = temp_dir("pipeline");
  auto r = run_cli("cloth synth --bvh " + clip("02_05.bvh") + " --frames 60 --out " + (d / "seq").string() + " -q", d);
  ASSERT_EQ(r.code, 0) << r.err;
  ASSERT_TRUE(fs::exists(d / "seq" / "mesh_0059.ply"));
  EXPECT_GT(fs::file_size(d / "seq" / "contact_sheet.png"), 10000u);
  r = run_cli("cloth segment --frames " + (d / "seq").string() + " --out " + (d / "seg.json").string() + " --png " + (d / "seg.png").string() + " -q", d);
  ASSERT_EQ(r.code, 0) << r.err;
  const auto seg = read_json(d / "seg.json"), truth = read_json(d / "seq" / "truth.json");
  ASSERT_EQ(seg["clothness"].size(), truth["cloth"].size());
  int correct = 0;
  for (std::size_t i = 0; i < seg["clothness"].size(); ++i) correct += (seg["clothness"][i].get<double>() > 0.5) == (truth["cloth"][i].get<int>() == 1);
  EXPECT_GE(double(correct) / double(seg["clothness"].size()), 0.95);
  EXPECT_TRUE(fs::exists(d / "seg.png"));
  r = run_cli("cloth build --template " + (d / "seq" / "mesh_0000.ply").string() + " --bvh " + clip("02_05.bvh") +
                  " --bvh-frame 0 --segmentation " + (d / "seg.json").string() + " --out " + (d / "model.json").string() + " -q",
              d);
  ASSERT_EQ(r.code, 0) << r.err;
  const tbsp::AnimatableModel model = tbsp::load_animatable_model((d / "model.json").string());
  EXPECT_EQ(model.mesh.V.rows(), Eigen::Index(seg["clothness"].size()));
  EXPECT_GE(model.proxies.size(), 4u);
  // the proxies alone: the model's cones, each inside the body (at most 2 % of its radius)
  const std::string inputs = "--template " + (d / "seq" / "mesh_0000.ply").string() + " --bvh " + clip("02_05.bvh") +
                             " --segmentation " + (d / "seg.json").string();
  r = run_cli("cloth proxies " + inputs + " --out " + (d / "proxies.json").string(), d);
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_NE(r.out.find("max inside"), std::string::npos) << r.out;
  const auto px = read_json(d / "proxies.json");
  EXPECT_EQ(px["format"], "tbsp-collision-proxies");
  ASSERT_EQ(px["proxies"].size(), model.proxies.size());
  for (std::size_t k = 0; k < model.proxies.size(); ++k) {
    EXPECT_NEAR(px["proxies"][k]["ra"].get<double>(), model.proxies[k].cone.ra, 1e-9);
    EXPECT_NEAR(px["proxies"][k]["rb"].get<double>(), model.proxies[k].cone.rb, 1e-9);
    EXPECT_GE(px["proxies"][k]["penetration"].get<double>(), 0.0);
  }
  r = run_cli("cloth proxies " + inputs + " --proxy-joints Tentacle --out " + (d / "none.json").string(), d);
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.err.find("Tentacle"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(d / "none.json"));
  // a new animation from another clip
  TBSP_REQUIRE_FILE(clip("01_01.bvh"));
  r = run_cli("cloth animate --model " + (d / "model.json").string() + " --bvh " + clip("01_01.bvh") + " --frames 0:297 --out " +
                  (d / "anim").string() + " -q",
              d);
  ASSERT_EQ(r.code, 0) << r.err;
  const auto rep = read_json(d / "anim" / "animate_report.json");
  EXPECT_EQ(rep["frames"].get<int>(), 100);
  EXPECT_EQ(rep["meshes_written"].get<int>(), 100);
  EXPECT_LT(rep["worst_strain_p99"].get<double>(), 0.5);
  const tbsp::TriMesh last = tbsp::read_mesh((d / "anim" / "mesh_0297.ply").string());
  EXPECT_EQ(last.V.rows(), model.mesh.V.rows());
  EXPECT_TRUE(last.V.allFinite());
  EXPECT_GT(fs::file_size(d / "anim" / "contact_sheet.png"), 10000u);
  // a clip without the model's joints (the creature of dopomoc/Skinning): named, nothing written
  const std::string creature = std::string(TBSP_SHARED_DATA_DIR) + "/capture/dopomoc__Skinning/skeleton_motion_jump.bvh";
  TBSP_REQUIRE_FILE(creature);
  r = run_cli("cloth animate --model " + (d / "model.json").string() + " --bvh " + creature + " --out " + (d / "anim2").string(), d);
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.err.find("lacks joint"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(d / "anim2"));
  // a clip of another skeleton (Bandai-Namco walk: other names, lengths and local axes) retargeted
  const std::string walk = std::string(TBSP_SHARED_DATA_DIR) +
                           "/capture/BandaiNamcoResearchInc__Bandai-Namco-Research-Motiondataset/dataset/Bandai-Namco-Research-Motiondataset-1/"
                           "data/dataset-1_walk_normal_001.bvh";
  TBSP_REQUIRE_FILE(walk);
  const std::string map =
      "hip=Hips,abdomen=Spine,chest=Chest,neck=Neck,head=Head,lCollar=Shoulder_L,lShldr=UpperArm_L,lForeArm=LowerArm_L,lHand=Hand_L,"
      "rCollar=Shoulder_R,rShldr=UpperArm_R,rForeArm=LowerArm_R,rHand=Hand_R,lThigh=UpperLeg_L,lShin=LowerLeg_L,lFoot=Foot_L,"
      "rThigh=UpperLeg_R,rShin=LowerLeg_R,rFoot=Foot_R";
  r = run_cli("cloth animate --model " + (d / "model.json").string() + " --bvh " + walk + " --joint-map " + map +
                  " --step 1 --frames 0:39 --no-meshes --contact-sheet 0 --out " + (d / "anim3").string() + " -q",
              d);
  ASSERT_EQ(r.code, 0) << r.err;
  const auto rep3 = read_json(d / "anim3" / "animate_report.json");
  EXPECT_EQ(rep3["frames"].get<int>(), 40);
  EXPECT_LT(rep3["worst_strain_p99"].get<double>(), 0.5);
  EXPECT_GT(rep3["retarget_scale"].get<double>(), 0.3);
  // a map naming a joint the clip lacks: named, nothing written
  r = run_cli("cloth animate --model " + (d / "model.json").string() + " --bvh " + walk + " --joint-map hip=Pelvis --out " +
                  (d / "anim4").string(),
              d);
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.err.find("clip has no joint 'Pelvis'"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(d / "anim4"));
  fs::remove_all(d);
}

TEST(CliCloth, BadInputsAreClearErrorsAndWriteNothing) {
  TBSP_REQUIRE_FILE(clip("02_05.bvh"));
  const fs::path d = temp_dir("bad");
  // a sequence whose second frame has another vertex count
  fs::create_directories(d / "seq");
  tbsp::TriMesh a;
  a.V = Eigen::MatrixX3d::Random(4, 3);
  a.F.resize(2, 3);
  a.F << 0, 1, 2, 0, 2, 3;
  tbsp::write_mesh((d / "seq" / "a.ply").string(), a);
  auto r = run_cli("cloth segment --frames " + (d / "seq").string() + " --out " + (d / "seg.json").string(), d);
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.err.find("one mesh only"), std::string::npos) << r.err;
  tbsp::TriMesh b = a;
  b.V.conservativeResize(5, 3);
  b.V.row(4) = Eigen::RowVector3d(1, 1, 1);
  tbsp::write_mesh((d / "seq" / "b.ply").string(), b);
  r = run_cli("cloth segment --frames " + (d / "seq").string() + " --out " + (d / "seg.json").string(), d);
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.err.find("b.ply"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(d / "seg.json"));
  // an empty folder, a missing folder
  fs::create_directories(d / "empty");
  EXPECT_EQ(run_cli("cloth segment --frames " + (d / "empty").string() + " --out " + (d / "seg.json").string(), d).code, 2);
  EXPECT_EQ(run_cli("cloth segment --frames " + (d / "nope").string() + " --out " + (d / "seg.json").string(), d).code, 2);
  // a model that is not one
  {
    std::ofstream(d / "model.json") << "{\"format\": \"something-else\", \"version\": 1}";
  }
  r = run_cli("cloth animate --model " + (d / "model.json").string() + " --bvh " + clip("02_05.bvh") + " --out " + (d / "anim").string(), d);
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.err.find("model.json"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(d / "anim"));
  // more frames than the clip has
  r = run_cli("cloth synth --bvh " + clip("02_05.bvh") + " --frames 5000 --out " + (d / "long").string(), d);
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.err.find("frames"), std::string::npos) << r.err;
  fs::remove_all(d);
}

// The material estimation end to end: a rendered 4-view studio of a simulated skirt, the model our
// pipeline builds from the meshes, `cloth estimate` with a small budget and a landscape.
TEST(CliCloth, EstimateFromARenderedStudio) {
  TBSP_REQUIRE_FILE(clip("02_05.bvh"));
  const fs::path d = temp_dir("estimate");
  const std::string seq = (d / "seq").string();
  auto r = run_cli("cloth synth --bvh " + clip("02_05.bvh") + " --frames 16 --studio-views 4 --studio-size 240 --contact-sheet 0 --out " + seq + " -q", d);
  ASSERT_EQ(r.code, 0) << r.err;
  ASSERT_TRUE(fs::exists(d / "seq" / "studio" / "studio.yaml"));
  ASSERT_TRUE(fs::exists(d / "seq" / "studio" / "images" / "cam3" / "0015.png"));
  r = run_cli("cloth segment --frames " + seq + " --out " + (d / "seg.json").string() + " -q", d);
  ASSERT_EQ(r.code, 0) << r.err;
  r = run_cli("cloth build --template " + (d / "seq" / "mesh_0000.ply").string() + " --bvh " + clip("02_05.bvh") + " --segmentation " +
                  (d / "seg.json").string() + " --out " + (d / "model.json").string() + " -q",
              d);
  ASSERT_EQ(r.code, 0) << r.err;
  const std::string common = "cloth estimate --model " + (d / "model.json").string() + " --studio " + (d / "seq" / "studio" / "studio.yaml").string() +
                             " --bvh " + clip("02_05.bvh");
  r = run_cli(common + " --reference " + seq + " --start-samples 4 --max-evaluations 8 --landscape 2 --truth 2,4,0.3 --out " + (d / "est").string() + " -q", d);
  ASSERT_EQ(r.code, 0) << r.err;
  const auto rep = read_json(d / "est" / "estimate_report.json");
  ASSERT_EQ(rep["regions"].size(), 1u);
  const int sims = rep["regions"][0]["simulations"].get<int>();
  EXPECT_GE(sims, 4);
  EXPECT_LE(sims, 8);
  EXPECT_EQ(rep["samples"].size(), std::size_t(sims));
  EXPECT_GT(rep["regions"][0]["energy"]["rim_samples"].get<long>(), 0);
  EXPECT_GT(rep["regions"][0]["energy"]["feature_samples"].get<long>(), 0);
  EXPECT_EQ(rep["landscape"]["e_fit"].size(), 4u);
  EXPECT_GT(fs::file_size(d / "est" / "landscape.png"), 1000u);
  const tbsp::AnimatableModel est = tbsp::load_animatable_model((d / "est" / "estimated_model.json").string());
  EXPECT_DOUBLE_EQ(est.materials[0].k_bend, rep["regions"][0]["material"]["k_bend"].get<double>());
  // bad inputs: a reference with fewer meshes than studio frames; a clip too short for the studio
  fs::create_directories(d / "short");
  fs::copy_file(d / "seq" / "mesh_0000.ply", d / "short" / "mesh_0000.ply");
  r = run_cli(common + " --reference " + (d / "short").string() + " --out " + (d / "bad").string(), d);
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.err.find("1 meshes for the studio's 16 frames"), std::string::npos) << r.err;
  r = run_cli(common + " --first 1850 --out " + (d / "bad").string(), d);
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.err.find("--first"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(d / "bad"));
  fs::remove_all(d);
}
