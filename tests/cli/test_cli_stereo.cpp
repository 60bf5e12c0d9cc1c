// `tbsp stereo` end to end: a small synthetic studio (fused clouds, depth PNGs, render, report),
// a Middlebury pair with ground truth, and bad input (exit 2, message, nothing clobbered).
#include <gtest/gtest.h>

#include <fstream>
#include <sstream>

#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>

#include "cli_json.h"
#include "cli_util.h"
#include "test_util.h"
#include "tbsp/io/cloud_io.h"
#include "tbsp/io/mesh_io.h"
#include "tbsp/io/studio.h"

using namespace tbsp;
namespace fs = std::filesystem;

namespace {
using test::run_cli;
}  // namespace

TEST(CliStereo, StudioFramesToFusedCloudsDepthMapsRenderAndReport) {
  const auto dir = test::temp_dir("cli_stereo");
  const std::string st = (dir / "studio").string(), out = (dir / "out").string();
  auto r = run_cli("synth-studio -q --out " + st + " --cameras 8 --width 400 --height 400 --frames 2 --detail 0", dir);
  ASSERT_EQ(r.code, 0) << r.err;
  r = run_cli("stereo " + st + " --out " + out + " --frames 0:1 --scale 1 -q", dir);
  ASSERT_EQ(r.code, 0) << r.err;
  for (const char* f : {"cloud_0000.ply", "cloud_0001.ply", "cloud_0000.png", "stereo_report.json"})
    EXPECT_TRUE(fs::exists(out + "/" + f)) << f;
  const auto rep = test::load_json(out + "/stereo_report.json");
  ASSERT_EQ(rep["frames"].size(), 2u);
  const auto& f0 = rep["frames"][0];
  EXPECT_GE(f0["pairs"].size(), 6u);
  EXPECT_GT(f0["points"]["output"].get<long>(), 5000);
  // The synthetic studio has ground truth: 90 % of the points within 0.5 % of the diagonal.
  ASSERT_TRUE(f0.contains("accuracy90_percent_of_diagonal"));
  EXPECT_LT(f0["accuracy90_percent_of_diagonal"].get<double>(), 0.5);
  // The cloud has normals, colour and the confidence field (PLY header), and reads back.
  std::ifstream ply(out + "/cloud_0000.ply", std::ios::binary);
  std::string header, line;
  while (std::getline(ply, line) && line != "end_header") header += line + "\n";
  for (const char* prop : {"property float nx", "property uchar red", "property float confidence"})
    EXPECT_NE(header.find(prop), std::string::npos) << prop << " missing in\n" << header;
  const auto cloud = read_cloud(out + "/cloud_0000.ply");
  EXPECT_EQ(static_cast<long>(cloud.width) * cloud.height, f0["points"]["output"].get<long>());
  // 16-bit depth PNGs, one per view and pair.
  int depth_pngs = 0;
  for (const auto& e : fs::directory_iterator(out + "/depth")) {
    const cv::Mat d = cv::imread(e.path().string(), cv::IMREAD_ANYDEPTH);
    EXPECT_EQ(d.type(), CV_16U) << e.path();
    ++depth_pngs;
  }
  EXPECT_EQ(depth_pngs, 2 * static_cast<int>(f0["pairs"].size() + rep["frames"][1]["pairs"].size()));
  // Frames outside the studio: exit 2, the previous report kept.
  const auto before = fs::last_write_time(out + "/stereo_report.json");
  r = run_cli("stereo " + st + " --out " + out + " --frames 5:9 -q", dir);
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.err.find("outside the studio's frames 0..1"), std::string::npos) << r.err;
  EXPECT_EQ(fs::last_write_time(out + "/stereo_report.json"), before);
}

TEST(CliStereo, RectifiedPairWithGroundTruthAndBadInput) {
  const auto dir = test::temp_dir("cli_stereo_pair");
  const std::string m = test::shared("capture/fjordyo0707__StereoMatching-CostFilter/testdata/cones/");
  TBSP_REQUIRE_FILE(m + "disp2.png");
  const std::string out = (dir / "pair").string();
  auto r = run_cli("stereo --left " + m + "im2.png --right " + m + "im6.png --disparities 64 --gt " + m + "disp2.png --gt-scale 4 --out " + out, dir);
  ASSERT_EQ(r.code, 0) << r.err;
  const auto rep = test::load_json(out + "/stereo_report.json");
  EXPECT_LT(rep["bad_pixels_1px_percent"].get<double>(), 12.5);  // measured 10.1 %
  const cv::Mat d = cv::imread(out + "/disparity.png", cv::IMREAD_ANYDEPTH);
  ASSERT_EQ(d.type(), CV_16U);
  EXPECT_EQ(d.cols, 450);
  EXPECT_TRUE(fs::exists(out + "/disparity_color.png"));
  // With a calibration: a cloud of the checked matches.
  const std::string calib = (dir / "calib.txt").string();
  std::ofstream(calib) << "cam0=[1000 0 225; 0 1000 187; 0 0 1]\ncam1=[1000 0 225; 0 1000 187; 0 0 1]\nbaseline=100\nwidth=450\nheight=375\nndisp=64\n";
  r = run_cli("stereo --left " + m + "im2.png --right " + m + "im6.png --calib " + calib + " --out " + out, dir);
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_GT(test::load_json(out + "/stereo_report.json")["points"].get<long>(), 100000);
  // Bad input: exit 2 with a message naming the file.
  r = run_cli("stereo --left " + m + "im2.png --right " + (dir / "nope.png").string() + " --out " + out, dir);
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.err.find("nope.png"), std::string::npos) << r.err;
  std::ofstream(calib) << "cam0=[1000 0 225; 0 1000 187; 0 0 1]\ncam1=[1000 0 225; 0 1000 187; 0 0 1]\nbaseline=100\nwidth=640\nheight=480\n";
  r = run_cli("stereo --left " + m + "im2.png --right " + m + "im6.png --calib " + calib + " --out " + out, dir);
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.err.find("640x480"), std::string::npos) << r.err;
  r = run_cli("stereo --left " + m + "im2.png --right " + m + "im6.png --disparities 50 --out " + out, dir);
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.err.find("multiple of 16"), std::string::npos) << r.err;
  r = run_cli("stereo --out " + out, dir);
  EXPECT_EQ(r.code, 2);
  // the same image twice: no parallax, no finite depth (found by hand 2026-12-06: "cannot write
  // cloud.ply", the writer refusing an empty cloud); the cloud of the run above stays
  std::ofstream(calib) << "cam0=[1000 0 225; 0 1000 187; 0 0 1]\ncam1=[1000 0 225; 0 1000 187; 0 0 1]\nbaseline=100\nwidth=450\nheight=375\nndisp=64\n";
  const auto before = fs::file_size(out + "/cloud.ply");
  r = run_cli("stereo --left " + m + "im2.png --right " + m + "im2.png --calib " + calib + " --out " + out, dir);
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.err.find("no parallax"), std::string::npos) << r.err;
  EXPECT_EQ(fs::file_size(out + "/cloud.ply"), before);
}

TEST(CliStereo, RefineStereoKeepsAGoodMeshAndNamesMissingMeshes) {
  const auto dir = test::temp_dir("cli_refine_stereo");
  const std::string st = (dir / "studio").string(), out = (dir / "out").string();
  auto r = run_cli("synth-studio -q --out " + st + " --cameras 8 --width 500 --height 500 --frames 1 --detail 1", dir);
  ASSERT_EQ(r.code, 0) << r.err;
  // The ground-truth mesh is already right: refinement moves it little (mean < 0.3 % of ~1.9 m).
  r = run_cli("refine-stereo " + st + " --meshes " + st + "/gt --out " + out + " -q", dir);
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_TRUE(fs::exists(out + "/refined_0000.ply"));
  const auto rep = test::load_json(out + "/refine_report.json");
  ASSERT_EQ(rep["frames"].size(), 1u);
  EXPECT_GT(rep["frames"][0]["points"].get<long>(), 1000);
  EXPECT_LT(rep["frames"][0]["mean_vertex_move"].get<double>(), 0.006);
  // A missing mesh is named before anything runs.
  r = run_cli("refine-stereo " + st + " --meshes " + (dir / "none_%04d.ply").string() + " --out " + out + " -q", dir);
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.err.find("none_0000.ply"), std::string::npos) << r.err;
}

TEST(CliStereo, RefineSilhouetteKeepsAMatchingMeshAndRefusesBadOptions) {
  const auto dir = test::temp_dir("cli_refine_sil");
  const std::string st = (dir / "studio").string(), out = (dir / "out").string();
  auto r = run_cli("synth-studio -q --out " + st + " --cameras 6 --width 400 --height 400 --frames 2 --detail 0", dir);
  ASSERT_EQ(r.code, 0) << r.err;
  r = run_cli("refine-silhouette " + st + " --meshes " + st + "/gt/%04d.ply --frames 1 --out " + out + " -q", dir);
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_TRUE(fs::exists(out + "/refined_0001.ply"));
  const auto rep = test::load_json(out + "/silhouette_report.json");
  ASSERT_EQ(rep["frames"].size(), 1u);
  EXPECT_EQ(rep["frames"][0]["views"].size(), 6u);
  // The ground truth already matches: the mismatch does not grow.
  EXPECT_LE(rep["frames"][0]["xor_after"].get<long>(), rep["frames"][0]["xor_before"].get<long>());
  r = run_cli("refine-silhouette " + st + " --meshes " + st + "/gt/%04d.ply --weight 0 --out " + out + " -q", dir);
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.err.find("weight"), std::string::npos) << r.err;
}

// --pose: the studio's template posed by markers placed in the images (here: the ground-truth
// positions of 12 template vertices projected into 3 of the 6 views), then refined.
TEST(CliStereo, RefineSilhouettePosesTheTemplateFromImageMarkers) {
  const auto dir = test::temp_dir("cli_refine_sil_pose");
  const std::string st = (dir / "studio").string(), out = (dir / "out").string();
  auto r = run_cli("synth-studio -q --out " + st + " --cameras 6 --width 400 --height 400 --frames 1 --detail 0", dir);
  ASSERT_EQ(r.code, 0) << r.err;
  const Studio studio = read_studio(st + "/studio.yaml");
  const TriMesh tmpl = read_mesh(studio.resolve(studio.template_mesh)), gt = read_mesh(studio.groundTruthPath(0));
  nlohmann::json markers = nlohmann::json::array();
  const std::vector<int> vs = test::farthest_points(tmpl.V, 12);
  for (std::size_t k = 0; k < vs.size(); ++k) {
    nlohmann::json px = nlohmann::json::object();
    for (std::size_t c = k % 2; c < studio.cameras.size(); c += 2) {
      const Eigen::Vector2d p = studio.cameras[c].camera.project(gt.V.row(vs[k]).transpose());
      px[studio.cameras[c].camera.name()] = {p.x(), p.y()};
    }
    markers.push_back({{"marker", "m" + std::to_string(k)}, {"vertex", vs[k]}, {"pixels", px}});
  }
  const std::string pose = (dir / "pose.json").string();
  std::ofstream(pose) << nlohmann::json({{"markers", markers}}).dump(1);
  r = run_cli("refine-silhouette " + st + " --pose " + pose + " --tets 2000 --overlays --out " + out + " -q", dir);
  ASSERT_EQ(r.code, 0) << r.err;
  for (const char* f : {"posed_0000.ply", "refined_0000.ply", "overlay_0000_before.png", "overlay_0000_after.png"})
    EXPECT_TRUE(fs::exists(out + "/" + f)) << f;
  EXPECT_FALSE(cv::imread(out + "/overlay_0000_after.png").empty());
  const auto rep = test::load_json(out + "/silhouette_report.json");
  ASSERT_EQ(rep["pose"]["markers"].size(), 12u);
  for (const auto& m : rep["pose"]["markers"]) EXPECT_LT(m["rms_px"].get<double>(), 0.01);  // exact projections
  double iou = 0;
  for (const auto& v : rep["frames"][0]["views"]) iou += v["iou_after"].get<double>() / 6.0;
  EXPECT_GE(iou, 0.9);

  // Bad input: --pose with --meshes, several frames, a marker in one view (named with the file).
  r = run_cli("refine-silhouette " + st + " --pose " + pose + " --meshes " + st + "/gt --out " + out + " -q", dir);
  EXPECT_NE(r.code, 0);
  markers[3]["pixels"] = {{studio.cameras[0].camera.name(), {10, 10}}};
  std::ofstream(pose) << nlohmann::json({{"markers", markers}}).dump(1);
  r = run_cli("refine-silhouette " + st + " --pose " + pose + " --out " + out + " -q", dir);
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.err.find("pose.json"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("markers[3].pixels"), std::string::npos) << r.err;
  EXPECT_TRUE(fs::exists(out + "/refined_0000.ply"));  // the good output of the first run is still there
}

