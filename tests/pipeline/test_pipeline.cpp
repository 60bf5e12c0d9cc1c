// Pipelines and stage plugins (plugins/pipeline, plugins/stages): validation names the line and
// the fix, PCL filters give the analytic result, outputs appear only when a run succeeds, a
// third-party plugin loads and runs.
#include <gtest/gtest.h>

#include <pcl/conversions.h>

#include <filesystem>
#include <fstream>
#include <sstream>

#include "../fitting/texture_test_util.h"
#include "test_util.h"
#include "tbsp/io/cloud_io.h"
#include "tbsp/io/mesh_io.h"
#include "tbsp/plugins/pipeline.h"

namespace fs = std::filesystem;
using namespace tbsp::pipeline;

namespace {

const Registry& builtin() {
  static Registry* r = [] {
    auto* reg = new Registry;
    reg->load_default_path();  // <build>/lib/tbsp/plugins next to tests/
    return reg;
  }();
  return *r;
}

void write_text(const fs::path& p, const std::string& s) {
  std::ofstream(p) << s;
}

// A 100 x 100 grid in the z = 0 plane, spacing 0.01, cell centres (no point on a voxel border).
void write_grid_cloud(const std::string& path, double z = 0) {
  pcl::PointCloud<pcl::PointXYZ> c;
  for (int i = 0; i < 100; ++i)
    for (int j = 0; j < 100; ++j) c.push_back(pcl::PointXYZ(float(0.005 + 0.01 * i), float(0.005 + 0.01 * j), float(z)));
  pcl::PCLPointCloud2 b;
  pcl::toPCLPointCloud2(c, b);
  tbsp::write_cloud(path, b, true);
}

struct BadCase {
  const char* what;
  std::string yaml;
  int line;
  const char* says;
};

}  // namespace

TEST(PipelineValidation, BuiltinStagesAreFoundOnThePluginPath) {
  for (const char* s : {"read-cloud", "read-mesh", "read-depth", "pcl.voxel-grid", "pcl.statistical-outlier-removal", "pcl.pass-through",
                        "merge-clouds", "fit", "deform", "write-mesh", "write-cloud", "render-png"})
    EXPECT_NE(builtin().find(s), nullptr) << s;
  EXPECT_EQ(builtin().find("read-cloud")->plugin, "libtbsp_stages.so");
  const std::string md = describe_stages(builtin(), true);
  EXPECT_NE(md.find("| `leaf` | real | required |"), std::string::npos) << md.substr(0, 2000);
}

TEST(PipelineValidation, EveryMalformedFileNamesTheLineAndTheFix) {
  const fs::path dir = tbsp::test::temp_dir("pipeline_bad");
  write_grid_cloud((dir / "in.pcd").string());
  const std::string head = "stages:\n  - id: in\n    stage: read-cloud\n    params: {path: in.pcd}\n";  // lines 1-4
  const std::vector<BadCase> cases = {
      {"YAML syntax", "stages:\n  - id: a\n    stage: [read-cloud\n", 4, "YAML syntax"},
      {"not a map", "- a\n- b\n", 1, "'stages:' list"},
      {"unknown top-level key", "stage:\n  - id: a\n", 1, "did you mean 'stages'"},
      {"unknown stage", head + "  - id: v\n    stage: pcl.voxelgrid\n    input: in\n", 6, "did you mean 'pcl.voxel-grid'"},
      {"unknown parameter", head + "  - id: v\n    stage: pcl.voxel-grid\n    input: in\n    params: {leaf: 0.1, leaf_size: 2}\n", 8,
       "has no parameter 'leaf_size'"},
      {"wrong type", head + "  - id: v\n    stage: pcl.voxel-grid\n    input: in\n    params:\n      leaf: big\n", 9, "not a finite number"},
      {"out of range", head + "  - id: s\n    stage: pcl.statistical-outlier-removal\n    input: in\n    params: {mean_k: 0}\n", 8,
       "outside [1, 10000]"},
      {"bad choice", head + "  - id: p\n    stage: pcl.pass-through\n    input: in\n    params: {field: w}\n", 8, "not one of x, y, z"},
      {"required parameter", head + "  - id: v\n    stage: pcl.voxel-grid\n    input: in\n", 5, "needs parameter 'leaf'"},
      {"missing input file", "stages:\n  - id: in\n    stage: read-cloud\n    params: {path: nowhere.pcd}\n", 4, "does not exist"},
      {"unconnected input", head + "  - id: v\n    stage: pcl.voxel-grid\n    params: {leaf: 0.1}\n", 5, "needs its input 'cloud'"},
      {"unknown node", head + "  - id: v\n    stage: pcl.voxel-grid\n    input: inn\n    params: {leaf: 0.1}\n", 7, "did you mean 'in'"},
      {"type mismatch", head + "  - id: w\n    stage: write-mesh\n    input: in\n    params: {path: out.ply}\n", 7, "type mismatch"},
      {"duplicate id", head + "  - id: in\n    stage: read-cloud\n    params: {path: in.pcd}\n", 5, "used twice (first on line 2)"},
      {"cycle", "stages:\n  - {id: a, stage: pcl.voxel-grid, input: b, params: {leaf: 1}}\n"
                "  - {id: b, stage: pcl.voxel-grid, input: a, params: {leaf: 1}}\n", 2, "cycle"},
      {"bad frame range", "frames: 5:2\n" + head, 1, "first:last"},
      {"bad output pattern", head + "  - id: w\n    stage: write-cloud\n    input: in\n    params: {path: out_%q.pcd}\n", 8, "%d"},
  };
  for (const auto& c : cases) {
    try {
      parse_pipeline(c.yaml, dir.string(), "p.yaml", builtin());
      ADD_FAILURE() << c.what << ": accepted";
    } catch (const PipelineError& e) {
      EXPECT_EQ(e.line(), c.line) << c.what << ": " << e.what();
      EXPECT_NE(std::string(e.what()).find(c.says), std::string::npos) << c.what << ": " << e.what();
      EXPECT_EQ(std::string(e.what()).rfind("p.yaml:" + std::to_string(c.line) + ": ", 0), 0u) << e.what();
    }
  }
  fs::remove_all(dir);
}

TEST(PipelineRun, PclFiltersGiveTheAnalyticResult) {
  const fs::path dir = tbsp::test::temp_dir("pipeline_filters");
  write_grid_cloud((dir / "in_0000.pcd").string(), 0.0);
  write_grid_cloud((dir / "in_0001.pcd").string(), 0.5);
  write_text(dir / "p.yaml",
             "report: out/report.json\n"
             "stages:\n"
             "  - {id: in, stage: read-cloud, params: {path: in_%04d.pcd}}\n"
             "  - {id: half, stage: pcl.pass-through, input: in, params: {field: x, min: 0, max: 0.5}}\n"
             "  - {id: vox, stage: pcl.voxel-grid, input: half, params: {leaf: 0.1}}\n"
             "  - {id: out, stage: write-cloud, input: vox, params: {path: out/v_%04d.pcd}}\n");
  const Pipeline p = load_pipeline((dir / "p.yaml").string(), builtin());
  const RunReport r = run_pipeline(p, builtin());
  ASSERT_EQ(r.frames.size(), 2u);
  EXPECT_EQ(r.outputs.size(), 3u);  // two clouds + the report
  for (int f = 0; f < 2; ++f) {
    const auto c = tbsp::read_cloud_normals((dir / ("out/v_000" + std::to_string(f) + ".pcd")).string());
    // x <= 0.5 keeps 50 x 100 grid points; 0.1 voxels hold 10 x 10 of them: 5 x 10 centroids at
    // the voxel centres (0.05 + 0.1 i, 0.05 + 0.1 j)
    ASSERT_EQ(c->size(), 50u) << "frame " << f;
    for (const auto& q : *c) {
      const double i = (q.x - 0.05) / 0.1, j = (q.y - 0.05) / 0.1;
      EXPECT_NEAR(i, std::round(i), 1e-4);
      EXPECT_NEAR(j, std::round(j), 1e-4);
      EXPECT_LT(q.x, 0.5);
      EXPECT_NEAR(q.z, 0.5 * f, 1e-6);
    }
  }
  std::ifstream rep(dir / "out/report.json");
  std::stringstream ss;
  ss << rep.rdbuf();
  EXPECT_NE(ss.str().find("\"frame\": 1"), std::string::npos);
  fs::remove_all(dir);
}

TEST(PipelineRun, AFailedRunLeavesEarlierOutputsAndNoTemporaryFiles) {
  const fs::path dir = tbsp::test::temp_dir("pipeline_fail");
  for (int f = 0; f < 3; ++f) write_grid_cloud((dir / ("in_000" + std::to_string(f) + ".pcd")).string());
  write_text(dir / "p.yaml",
             "stages:\n"
             "  - {id: in, stage: read-cloud, params: {path: in_%04d.pcd}}\n"
             "  - {id: vox, stage: pcl.voxel-grid, input: in, params: {leaf: 0.1}}\n"
             "  - {id: out, stage: write-cloud, input: vox, params: {path: out/v_%04d.pcd}}\n");
  run_pipeline(load_pipeline((dir / "p.yaml").string(), builtin()), builtin());
  const auto before = fs::file_size(dir / "out/v_0000.pcd");
  // frame 2 becomes unreadable: the second run must fail naming it and keep the first run's files
  write_text(dir / "in_0002.pcd", "# .PCD v0.7\nVERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 5\nHEIGHT 1\nPOINTS 5\nDATA ascii\n1 2\n");
  write_text(dir / "p.yaml",
             "stages:\n"
             "  - {id: in, stage: read-cloud, params: {path: in_%04d.pcd}}\n"
             "  - {id: vox, stage: pcl.voxel-grid, input: in, params: {leaf: 0.2}}\n"
             "  - {id: out, stage: write-cloud, input: vox, params: {path: out/v_%04d.pcd}}\n");
  try {
    run_pipeline(load_pipeline((dir / "p.yaml").string(), builtin()), builtin());
    ADD_FAILURE() << "a corrupt frame was accepted";
  } catch (const tbsp::InvalidInput& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find("frame 2, node 'in' (read-cloud, "), std::string::npos) << msg;
    EXPECT_NE(msg.find("p.yaml:2)"), std::string::npos) << msg;
  }
  EXPECT_EQ(fs::file_size(dir / "out/v_0000.pcd"), before);  // leaf 0.1 result, not 0.2
  for (const auto& e : fs::directory_iterator(dir / "out")) EXPECT_EQ(e.path().filename().string().rfind(".tbsp-run-", 0), std::string::npos) << e.path();
  // one output path for several frames is refused before anything is renamed
  write_text(dir / "in_0002.pcd", "");
  fs::remove(dir / "in_0002.pcd");
  write_text(dir / "q.yaml",
             "stages:\n"
             "  - {id: in, stage: read-cloud, params: {path: in_%04d.pcd}}\n"
             "  - {id: out, stage: write-cloud, input: in, params: {path: out/same.pcd}}\n");
  EXPECT_THROW(run_pipeline(load_pipeline((dir / "q.yaml").string(), builtin()), builtin()), tbsp::InvalidInput);
  EXPECT_FALSE(fs::exists(dir / "out/same.pcd"));
  fs::remove_all(dir);
}

TEST(PipelinePlugins, AThirdPartyPluginLoadsAndRuns) {
  Registry reg;
  reg.load_default_path();
  reg.load(TBSP_SAMPLE_PLUGIN);
  const StageInfo* s = reg.find("sample.scale");
  ASSERT_NE(s, nullptr);
  EXPECT_EQ(s->plugin, fs::path(TBSP_SAMPLE_PLUGIN).filename().string());
  EXPECT_NO_THROW(reg.load(TBSP_SAMPLE_PLUGIN));  // the same library twice: loaded once

  const fs::path dir = tbsp::test::temp_dir("pipeline_plugin");
  tbsp::TriMesh m;
  m.V.resize(3, 3);
  m.V << 0, 0, 0, 1, 0, 0, 0, 1, 0.5;
  m.F.resize(1, 3);
  m.F << 0, 1, 2;
  tbsp::write_mesh((dir / "tri.ply").string(), m);
  write_text(dir / "p.yaml",
             "stages:\n"
             "  - {id: in, stage: read-mesh, params: {path: tri.ply}}\n"
             "  - {id: big, stage: sample.scale, input: in, params: {factor: 3}}\n"
             "  - {id: out, stage: write-mesh, input: big, params: {path: big.ply}}\n");
  const RunReport r = run_pipeline(load_pipeline((dir / "p.yaml").string(), reg), reg);
  EXPECT_EQ(r.frames.at(0).numbers.at("big").at("factor"), 3.0);
  const tbsp::TriMesh out = tbsp::read_mesh((dir / "big.ply").string());
  EXPECT_EQ((out.V - 3.0 * m.V).cwiseAbs().maxCoeff(), 0.0);
  // a library that is not a plugin, and a file that is not a library
  write_text(dir / "junk.so", "not an ELF file");
  EXPECT_THROW(reg.load((dir / "junk.so").string()), tbsp::FileError);
  try {
    reg.load("/lib/x86_64-linux-gnu/libm.so.6");
    ADD_FAILURE() << "libm accepted as a plugin";
  } catch (const tbsp::InvalidInput& e) {
    EXPECT_NE(std::string(e.what()).find("not a tbsp stage plugin"), std::string::npos) << e.what();
  }
  fs::remove_all(dir);
}

TEST(PipelineCli, RunAndPluginsCommands) {
  const fs::path dir = tbsp::test::temp_dir("pipeline_cli");
  write_grid_cloud((dir / "in.pcd").string());
  write_text(dir / "bad.yaml", "stages:\n  - id: in\n    stage: read-cloud\n    params: {path: in.pcd, stride: 2}\n");
  const std::string cli = TBSP_CLI;
  const std::string err = (dir / "err.txt").string();
  int rc = std::system((cli + " run " + (dir / "bad.yaml").string() + " 2> " + err).c_str());
  EXPECT_EQ(WEXITSTATUS(rc), 2);
  std::ifstream e(err);
  std::stringstream ss;
  ss << e.rdbuf();
  EXPECT_NE(ss.str().find("bad.yaml:4: stage 'read-cloud' has no parameter 'stride'"), std::string::npos) << ss.str();
  write_text(dir / "good.yaml", "stages:\n  - {id: in, stage: read-cloud, params: {path: in.pcd}}\n"
                                "  - {id: out, stage: write-cloud, input: in, params: {path: copy.ply}}\n");
  rc = std::system((cli + " run -q " + (dir / "good.yaml").string()).c_str());
  EXPECT_EQ(WEXITSTATUS(rc), 0);
  EXPECT_EQ(tbsp::read_cloud_normals((dir / "copy.ply").string())->size(), 10000u);
  rc = std::system((cli + " plugins --markdown " + (dir / "stages.md").string() + " > /dev/null").c_str());
  EXPECT_EQ(WEXITSTATUS(rc), 0);
  EXPECT_TRUE(fs::exists(dir / "stages.md"));
  fs::remove_all(dir);
}

TEST(PipelineRun, DeformStageEqualsTheDeformCommand) {
  const fs::path dir = tbsp::test::temp_dir("pipeline_deform");
  const std::string bar = tbsp::test::sample("bumpy_bar.off"), cons = tbsp::test::sample("bend_90.json");
  write_text(dir / "p.yaml", "stages:\n  - {id: bar, stage: read-mesh, params: {path: " + bar + "}}\n"
                             "  - {id: bent, stage: deform, input: bar, params: {constraints: " + cons + ", rotation_field: true}}\n"
                             "  - {id: out, stage: write-mesh, input: bent, params: {path: bent.ply}}\n");
  const RunReport r = run_pipeline(load_pipeline((dir / "p.yaml").string(), builtin()), builtin());
  EXPECT_LT(r.frames.at(0).numbers.at("bent").at("max_residual"), 5e-3);  // soft end-ring constraints: measured 1.2e-3
  const std::string cli = TBSP_CLI;
  ASSERT_EQ(WEXITSTATUS(std::system((cli + " deform -q --rotation-field --mesh " + bar + " --constraints " + cons + " --out " +
                                     (dir / "cli.ply").string()).c_str())), 0);
  const tbsp::TriMesh a = tbsp::read_mesh((dir / "bent.ply").string()), b = tbsp::read_mesh((dir / "cli.ply").string()),
                      rest = tbsp::read_mesh(bar);
  ASSERT_EQ(a.V.rows(), b.V.rows());
  EXPECT_LT((a.V - b.V).cwiseAbs().maxCoeff(), 1e-12);  // the same library call behind both
  // rings 0-2 are fixed by hard constraints (sample_data/README.md): they do not move
  EXPECT_LT((a.V.topRows(72) - rest.V.topRows(72)).cwiseAbs().maxCoeff(), 1e-9);
  EXPECT_GT((a.V - rest.V).rowwise().norm().maxCoeff(), 0.3);  // the far end did move
  fs::remove_all(dir);
}

// tetdeform stage: the library call behind `tbsp tetdeform` (tet_job_run.h), so the same bits.
TEST(PipelineRun, TetDeformStageEqualsTheTetDeformCommand) {
  const fs::path dir = tbsp::test::temp_dir("pipeline_tetdeform");
  const std::string cli = TBSP_CLI, box = (dir / "box.ply").string(), handles = tbsp::test::sample("bar_twist_tet.json");
  ASSERT_EQ(WEXITSTATUS(std::system((cli + " generate box --level 1 --out " + box).c_str())), 0);
  write_text(dir / "p.yaml", "stages:\n  - {id: bar, stage: read-mesh, params: {path: " + box + "}}\n"
                             "  - {id: twisted, stage: tetdeform, input: bar, params: {handles: " + handles + ", iterations: 8}}\n"
                             "  - {id: out, stage: write-mesh, input: twisted, params: {path: twisted.ply}}\n");
  const RunReport r = run_pipeline(load_pipeline((dir / "p.yaml").string(), builtin()), builtin());
  EXPECT_EQ(r.frames.at(0).numbers.at("twisted").at("iterations"), 8);
  ASSERT_EQ(WEXITSTATUS(std::system((cli + " tetdeform -q --iterations 8 --mesh " + box + " --handles " + handles + " --out " +
                                     (dir / "cli.ply").string()).c_str())), 0);
  const tbsp::TriMesh a = tbsp::read_mesh((dir / "twisted.ply").string()), b = tbsp::read_mesh((dir / "cli.ply").string()),
                      rest = tbsp::read_mesh(box);
  ASSERT_EQ(a.V.rows(), b.V.rows());
  EXPECT_LT((a.V - b.V).cwiseAbs().maxCoeff(), 1e-9);
  // the left end (x <= 0.05) is held; the bar is twisted in between (mid-length points moved)
  double left = 0, mid = 0;
  for (Eigen::Index i = 0; i < rest.V.rows(); ++i) {
    const double d = (a.V.row(i) - rest.V.row(i)).norm();
    if (rest.V(i, 0) <= 0.05) left = std::max(left, d);
    if (std::abs(rest.V(i, 0) - 0.5) < 0.1) mid = std::max(mid, d);
  }
  EXPECT_LT(left, 1e-6);
  EXPECT_GT(mid, 0.05);
  // a handle file that does not fit the mesh names the file and the entry, with exit 2 from `tbsp run`
  write_text(dir / "bad.json", R"({"handles": [{"vertex": 100000, "target": [0, 0, 0]}]})");
  write_text(dir / "bad.yaml", "stages:\n  - {id: bar, stage: read-mesh, params: {path: " + box + "}}\n"
                               "  - {id: twisted, stage: tetdeform, input: bar, params: {handles: bad.json}}\n"
                               "  - {id: out, stage: write-mesh, input: twisted, params: {path: bad.ply}}\n");
  const std::string log = (dir / "bad.log").string();
  EXPECT_EQ(WEXITSTATUS(std::system((cli + " run -q " + (dir / "bad.yaml").string() + " 2> " + log).c_str())), 2);
  std::ifstream in(log);
  const std::string msg((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  EXPECT_NE(msg.find("bad.json"), std::string::npos) << msg;
  EXPECT_NE(msg.find("handles[0]"), std::string::npos) << msg;
  EXPECT_FALSE(fs::exists(dir / "bad.ply"));
  fs::remove_all(dir);
}

// texture stage: the image is a colour ramp (red = x, green = y), so each vertex's colour says
// where in the image it landed: the constrained vertices land on their pixels.
TEST(PipelineRun, TextureStageColoursEachVertexFromItsTexturePosition) {
  const std::string mesh = tbsp::test::shared("meshes/cfwen__geometry-processing-package/data/face.off");
  TBSP_REQUIRE_FILE(mesh);
  const fs::path dir = tbsp::test::temp_dir("pipeline_texture");
  const int W = 256, H = 192;
  {
    std::ofstream ppm(dir / "ramp.ppm", std::ios::binary);
    ppm << "P6\n" << W << " " << H << "\n255\n";
    for (int y = 0; y < H; ++y)
      for (int x = 0; x < W; ++x) ppm << char(std::lround(255.0 * x / (W - 1))) << char(std::lround(255.0 * y / (H - 1))) << char(0);
  }
  const tbsp::TriMesh m = tbsp::read_mesh(mesh);
  const auto cons = tbsp::test::layout_constraints(m.V, tbsp::test::reference_layout(m.V, W, H, false, &m.F), W, H, 12, false);
  std::string json = "{\"constraints\": [";
  for (std::size_t i = 0; i < cons.size(); ++i)
    json += (i ? ", " : "") + std::string("{\"pixel\": [") + std::to_string(cons[i].pixel.x()) + ", " + std::to_string(cons[i].pixel.y()) +
            "], \"vertex\": " + std::to_string(cons[i].vertex) + "}";
  write_text(dir / "c.json", json + "]}");
  write_text(dir / "p.yaml", "stages:\n  - {id: face, stage: read-mesh, params: {path: " + mesh + "}}\n"
                             "  - {id: tex, stage: texture, input: face, params: {image: ramp.ppm, constraints: c.json}}\n"
                             "  - {id: out, stage: write-mesh, input: tex, params: {path: face_tex.ply}}\n");
  const RunReport r = run_pipeline(load_pipeline((dir / "p.yaml").string(), builtin()), builtin());
  const auto& num = r.frames.at(0).numbers.at("tex");
  EXPECT_LT(num.at("max_constraint_residual_px"), 1.0);
  EXPECT_GT(num.at("matched_fraction"), 0.5);
  const tbsp::TriMesh out = tbsp::read_mesh((dir / "face_tex.ply").string());
  ASSERT_EQ(out.C.rows(), m.V.rows());
  double worst = 0;
  for (const auto& c : cons) {  // the ramp decoded: 8-bit steps of (W-1)/255 = 1 px
    const Eigen::Vector2d at(out.C(c.vertex, 0) * (W - 1), out.C(c.vertex, 1) * (H - 1));
    worst = std::max(worst, (at - c.pixel).norm());
  }
  std::printf("texture stage: worst constrained vertex %.2f px from its pixel\n", worst);
  EXPECT_LT(worst, 3.0);
  fs::remove_all(dir);
}

