// libFuzzer targets for every file format and JSON/YAML front end tbsp reads.
//
// One binary, one target per run: the target is named by the environment variable
// TBSP_FUZZ_TARGET (scripts/fuzz sets it; `TBSP_FUZZ_TARGET=list tbsp_fuzz` prints the names).
// Each input is written to a file with the target's extension and handed to the reader, as the
// CLI would. What counts as a finding: a crash, a sanitizer report (ASan + UBSan), a hang
// (libFuzzer -timeout), an allocation beyond -rss_limit_mb, or any exception other than
// tbsp::InvalidInput (exit 2 in the CLI) and tbsp::NumericalFailure (exit 3): a std::exception
// of another kind would reach the CLI's catch-all and exit 1 with a library's message.
#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iostream>
#include <map>
#include <string>
#include <typeinfo>

#include "tbsp/core/error.h"
#include "tbsp/core/logging.h"
#include "tbsp/io/camera_io.h"
#include "tbsp/io/cloud_io.h"
#include "tbsp/io/depth_io.h"
#include "tbsp/io/mesh_io.h"
#include "tbsp/io/mocap_io.h"
#include "tbsp/io/studio.h"
#include "tbsp/io/tet_mesh_io.h"
#include "tbsp/io/range_scan_conf.h"
#include "tbsp/cloth/retarget.h"
#include "tbsp/plugins/constraints_json.h"
#include "tbsp/plugins/fit_json.h"
#include "tbsp/plugins/json_file.h"
#include "tbsp/plugins/marker_map_json.h"
#include "tbsp/cloth/cloth_observations.h"
#include "tbsp/multiview/camera.h"
#include "tbsp/plugins/cloth_model_json.h"
#include "tbsp/plugins/pipeline.h"
#include "tbsp/plugins/tet_job_json.h"
#include "tbsp/plugins/texture_json.h"

namespace fs = std::filesystem;
using namespace tbsp;

namespace {

// A small closed mesh (octahedron) for the front ends that check indices against a mesh.
TriMesh octahedron() {
  TriMesh m;
  m.V.resize(6, 3);
  m.V << 1, 0, 0, -1, 0, 0, 0, 1, 0, 0, -1, 0, 0, 0, 1, 0, 0, -1;
  m.F.resize(8, 3);
  m.F << 0, 2, 4, 2, 1, 4, 1, 3, 4, 3, 0, 4, 2, 0, 5, 1, 2, 5, 3, 1, 5, 0, 3, 5;
  return m;
}

// Stages of every parameter and port kind for the pipeline validator (their makers are never
// called: parse_pipeline only reads the metadata).
const pipeline::Registry& fuzz_registry() {
  static pipeline::Registry* r = [] {
    using namespace tbsp::pipeline;
    auto* reg = new Registry;
    auto never = [](const Params&) -> std::unique_ptr<Stage> { return nullptr; };
    StageInfo src{"read-cloud", "source"};
    src.params = {ParamSpec::input_path("path", "file", true), ParamSpec::integer("first", "0", "first", 0, 1e9)};
    src.outputs = {{"cloud", DataType::Cloud, "cloud"}};
    reg->add(src, never);
    StageInfo mesh{"read-mesh", "source"};
    mesh.params = {ParamSpec::input_path("path", "file", false)};
    mesh.outputs = {{"mesh", DataType::Mesh, "mesh"}};
    reg->add(mesh, never);
    StageInfo filt{"pcl.pass-through", "filter"};
    filt.params = {ParamSpec::text("field", "z", "axis", {"x", "y", "z"}), ParamSpec::real("min", "0", "lo", -1e30, 1e30),
                   ParamSpec::boolean("negative", false, "flip")};
    filt.inputs = {{"cloud", DataType::Cloud, "in"}};
    filt.outputs = {{"cloud", DataType::Cloud, "out"}};
    reg->add(filt, never);
    StageInfo fit{"fit", "two inputs"};
    fit.inputs = {{"cloud", DataType::Cloud, "in"}, {"template", DataType::Mesh, "t"}, {"extra", DataType::Cloud, "x", true}};
    fit.outputs = {{"mesh", DataType::Mesh, "out"}, {"cloud", DataType::Cloud, "out2"}};
    reg->add(fit, never);
    StageInfo sink{"write-mesh", "sink"};
    sink.params = {ParamSpec::output_path("path", "out")};
    sink.inputs = {{"mesh", DataType::Mesh, "in"}};
    reg->add(sink, never);
    return reg;
  }();
  return *r;
}

struct Target {
  std::string file;                                 // name of the file the input is written to
  std::function<void(const std::string&)> run;      // reads it
};

const std::map<std::string, Target>& targets() {
  static const std::map<std::string, Target> t = {
      {"ply", {"in.ply", [](const std::string& p) { read_mesh(p); }}},
      {"obj", {"in.obj", [](const std::string& p) { read_mesh(p); }}},
      {"off", {"in.off", [](const std::string& p) { read_mesh(p); }}},
      {"vtk", {"in.vtk", [](const std::string& p) { read_mesh(p); }}},
      {"pcd", {"in.pcd", [](const std::string& p) { read_cloud_normals(p); }}},
      {"cloud_ply", {"in.ply", [](const std::string& p) { read_cloud_normals(p); }}},
      {"tetmesh", {"in.mesh", [](const std::string& p) { read_tet_mesh(p); }}},
      {"conf", {"in.conf", [](const std::string& p) { read_range_scan_conf(p); }}},
      {"middlebury", {"in_par.txt", [](const std::string& p) { read_middlebury_par(p); }}},
      {"pmatrix", {"in.txt", [](const std::string& p) { read_projection_matrix(p, 640, 480, "c"); }}},
      {"stereo_calib", {"calib.txt", [](const std::string& p) { read_middlebury_stereo_calib(p); }}},
      {"dome_calib", {"calib.txt", [](const std::string& p) { read_dome_calibration(p, 1024, 768); }}},
      // COLMAP: the input holds cameras.txt and images.txt, split at the first line "%%"
      {"colmap", {"colmap.txt", [](const std::string& p) {
                    std::ifstream in(p, std::ios::binary);
                    std::string s((std::istreambuf_iterator<char>(in)), {});
                    const std::size_t cut = s.find("\n%%\n");
                    const fs::path dir = fs::path(p).parent_path() / "colmap";
                    fs::create_directories(dir);
                    std::ofstream(dir / "cameras.txt", std::ios::binary) << s.substr(0, cut);
                    std::ofstream(dir / "images.txt", std::ios::binary) << (cut == std::string::npos ? "" : s.substr(cut + 4));
                    read_colmap_text(dir.string());
                  }}},
      {"trc", {"in.trc", [](const std::string& p) { read_trc(p); }}},
      {"c3d", {"in.c3d", [](const std::string& p) { read_c3d(p); }}},
      {"bvh", {"in.bvh", [](const std::string& p) {
                 const BvhMotion b = read_bvh(p);
                 if (b.numFrames() > 0) b.jointPositions(b.numFrames() - 1);
               }}},
      {"studio", {"studio.yaml", [](const std::string& p) {
                    const Studio s = read_studio(p);
                    check_studio(s);
                  }}},
      {"depth", {"in.png", [](const std::string& p) { read_depth_image(p); }}},
      {"constraints", {"c.json", [](const std::string& p) { load_constraints_json(p, octahedron()); }}},
      {"markers", {"m.json", [](const std::string& p) { load_markers_json(p); }}},
      {"roi", {"r.json", [](const std::string& p) { load_roi_json(p); }}},
      {"handles", {"h.json", [](const std::string& p) {
                     TetJob job;
                     parse_tet_handles(load_json_file(p), 6, p, job);
                   }}},
      {"rigid", {"g.json", [](const std::string& p) {
                   TetJob job;
                   parse_tet_rigid(load_json_file(p), 6, p, job);
                 }}},
      {"stiffness", {"s.json", [](const std::string& p) {
                       TetJob job;
                       parse_tet_stiffness(load_json_file(p), 6, p, job);
                     }}},
      {"texture", {"t.json", [](const std::string& p) { parse_texture_constraints(load_json_file(p), p); }}},
      {"marker_map", {"map.json", [](const std::string& p) { load_marker_map_json(p); }}},
      {"cloth_model", {"model.json", [](const std::string& p) { load_animatable_model(p); }}},
      // the bytes the ranks of `tbsp cloth estimate` under mpirun exchange (two 64×48 views)
      {"cloth_observations", {"obs.bin", [](const std::string& p) {
                                std::ifstream in(p, std::ios::binary);
                                const std::string bytes((std::istreambuf_iterator<char>(in)), {});
                                Eigen::Matrix3d K;
                                K << 50, 0, 32, 0, 50, 24, 0, 0, 1;
                                const Camera cam("c", 64, 48, K, Eigen::Matrix3d::Identity(), Eigen::Vector3d(0, 0, 2));
                                ClothObservations obs({cam, cam});
                                obs.append(bytes);
                                for (int f = 0; f < obs.numFrames(); ++f)
                                  for (int v = 0; v < obs.numViews(); ++v) {
                                    obs.boundaryDistance(f, v, Eigen::Vector2d(17.5, 9.25));
                                    obs.correspondences(f, v).size();
                                  }
                              }}},
      // a --joint-map string against the CMU skeleton's joints and the Bandai-Namco clip's
      {"joint_map", {"map.txt", [](const std::string& p) {
                       std::ifstream in(p, std::ios::binary);
                       const std::string spec((std::istreambuf_iterator<char>(in)), {});
                       const std::vector<std::string> model = {"hip", "abdomen", "chest", "lThigh", "lShin", "lFoot", "lFoot_End"};
                       const std::vector<std::string> clip = {"joint_Root", "Hips", "Spine", "Chest", "UpperLeg_L", "LowerLeg_L", "Foot_L"};
                       parse_joint_map(spec, model, clip);
                     }}},
      {"pipeline", {"p.yaml", [](const std::string& p) { pipeline::load_pipeline(p, fuzz_registry()); }}},
  };
  return t;
}

const Target* g_target = nullptr;
std::string g_path;

}  // namespace

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  const char* name = std::getenv("TBSP_FUZZ_TARGET");
  if (!name || std::string(name) == "list") {
    std::cerr << "set TBSP_FUZZ_TARGET to one of:";
    for (const auto& [k, v] : targets()) std::cerr << " " << k;
    std::cerr << "\n";
    std::exit(name ? 0 : 2);
  }
  auto it = targets().find(name);
  if (it == targets().end()) {
    std::cerr << "unknown TBSP_FUZZ_TARGET '" << name << "' (TBSP_FUZZ_TARGET=list prints the targets)\n";
    std::exit(2);
  }
  g_target = &it->second;
  const fs::path dir = fs::temp_directory_path() / ("tbsp_fuzz_" + std::string(name) + "_" + std::to_string(::getpid()));
  fs::create_directories(dir);
  g_path = (dir / g_target->file).string();
  logger()->set_level(spdlog::level::off);  // readers warn about what they skip; not a finding
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  {
    std::ofstream out(g_path, std::ios::binary | std::ios::trunc);
    out.write(reinterpret_cast<const char*>(data), std::streamsize(size));
  }
  try {
    g_target->run(g_path);
  } catch (const InvalidInput&) {
    // exit 2: the expected answer to malformed input (FileError is an InvalidInput)
  } catch (const NumericalFailure&) {
    // exit 3
  } catch (const std::exception& e) {
    std::fprintf(stderr, "tbsp_fuzz: a %s escaped the reader (the CLI would exit 1): %s\n", typeid(e).name(), e.what());
    std::abort();
  }
  return 0;
}
