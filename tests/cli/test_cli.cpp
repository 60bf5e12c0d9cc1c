// The `tbsp` executable end to end: exit codes, messages, atomic outputs, reports.
#include <gtest/gtest.h>

#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>

#include <opencv2/imgcodecs.hpp>
#include "cli_util.h"
#include "test_util.h"
#include "tbsp/io/mesh_io.h"
#include "tbsp/mesh/primitives.h"

using namespace tbsp;

namespace {
using test::CliResult;
using test::run_cli;
}  // namespace

TEST(Cli, DeformWritesMeshAndReport) {
  const auto dir = test::temp_dir("cli_ok");
  const std::string out = (dir / "bent.ply").string(), rep = (dir / "r.json").string();
  const CliResult r = run_cli("deform -q --mesh " + test::sample("bumpy_bar.off") + " --constraints " + test::sample("bend_90.json") +
                        " --out " + out + " --rotation-field --check-self-intersections --report " + rep,
                    dir);
  ASSERT_EQ(r.code, 0) << r.err;
  const TriMesh m = read_mesh(out);
  EXPECT_EQ(m.V.rows(), read_mesh(test::sample("bumpy_bar.off")).V.rows());
  nlohmann::json j;
  std::ifstream(rep) >> j;
  EXPECT_GT(j["timings_s"]["factorize"].get<double>(), 0.0);
  EXPECT_GE(j["timings_s"]["solve"].get<double>(), 0.0);
  EXPECT_EQ(j["counts"]["hard_constraints"].get<int>(), 73);
  EXPECT_EQ(j["residuals"]["by_type"]["hard"]["max"].get<double>(), 0.0);
  EXPECT_TRUE(j["solver"]["rotation_field"].get<bool>());
  EXPECT_EQ(j["residuals"]["constraints"].size(), 146u);
  EXPECT_EQ(j["self_intersections"]["input"].get<int>(), 0);  // the 90° bend crosses nothing
  EXPECT_EQ(j["self_intersections"]["output"].get<int>(), 0);
  std::filesystem::remove_all(dir);
}

TEST(Cli, DeformReportsTheCrossingsItMade) {
  // a sphere whose vertex 0 is pulled through the far side, which is held: the deformation pushes
  // the surface through itself, and the report says so
  const auto dir = test::temp_dir("cli_cross");
  const TriMesh m = make_icosphere(3);
  const std::string in = (dir / "s.ply").string(), cons = (dir / "c.json").string(), out = (dir / "o.ply").string(),
                    rep = (dir / "r.json").string();
  write_mesh(in, m);
  nlohmann::json c;
  const Eigen::RowVector3d v0 = m.V.row(0);
  c["constraints"].push_back({{"vertex", 0}, {"target", {-1.5 * v0(0), -1.5 * v0(1), -1.5 * v0(2)}}});
  for (Eigen::Index i = 1; i < m.V.rows(); ++i)
    if (m.V.row(i).dot(v0) < -0.3) c["constraints"].push_back({{"vertex", i}, {"target", {m.V(i, 0), m.V(i, 1), m.V(i, 2)}}});
  std::ofstream(cons) << c.dump();
  const CliResult r = run_cli("deform --mesh " + in + " --constraints " + cons + " --out " + out + " --check-self-intersections --report " + rep, dir);
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_NE(r.out.find("self-intersecting face pairs: 0 in the input"), std::string::npos) << r.out;
  nlohmann::json j;
  std::ifstream(rep) >> j;
  EXPECT_EQ(j["self_intersections"]["input"].get<int>(), 0);
  EXPECT_GT(j["self_intersections"]["output"].get<int>(), 0);
  std::filesystem::remove_all(dir);
}

TEST(Cli, MalformedInputsFailClearlyAndKeepExistingOutputs) {
  const auto dir = test::temp_dir("cli_bad");
  const std::string out = (dir / "out.ply").string();
  write_mesh(out, make_icosphere(1));
  const auto before = std::filesystem::last_write_time(out);
  // truncated mesh
  const std::string bad = (dir / "bad.off").string();
  std::ofstream(bad) << "OFF\n4 2 0\n0 0 0\n1 0 0\n";
  CliResult r = run_cli("deform --mesh " + bad + " --constraints " + test::sample("bend_90.json") + " --out " + out, dir);
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.err.find(bad), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("truncated"), std::string::npos) << r.err;
  // constraint on a missing vertex
  const std::string cons = (dir / "c.json").string();
  std::ofstream(cons) << R"({"constraints": [{"vertex": 5, "target": [0,0,0]}, {"vertex": 99999, "target": [1,2,3]}]})";
  r = run_cli("deform --mesh " + test::sample("bumpy_bar.off") + " --constraints " + cons + " --out " + out, dir);
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.err.find("constraints[1].vertex"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("99999"), std::string::npos) << r.err;
  // invalid JSON
  std::ofstream(cons) << "{ not json";
  r = run_cli("deform --mesh " + test::sample("bumpy_bar.off") + " --constraints " + cons + " --out " + out, dir);
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.err.find("not valid JSON"), std::string::npos) << r.err;
  // under-determined: only a plane constraint
  std::ofstream(cons) << R"({"constraints": [{"vertex": 5, "type": "plane", "point": [0,0,0], "normal": [0,0,1]}]})";
  r = run_cli("deform --mesh " + test::sample("bumpy_bar.off") + " --constraints " + cons + " --out " + out, dir);
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.err.find("free to translate"), std::string::npos) << r.err;
  EXPECT_EQ(std::filesystem::last_write_time(out), before) << "a failed run must not touch the existing output";
  EXPECT_EQ(read_mesh(out).V.rows(), make_icosphere(1).V.rows());
  // validate: exit 4 with --strict on a mesh with problems
  const std::string dup = (dir / "dup.off").string();
  std::ofstream(dup) << "OFF\n3 2 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n3 0 1 2\n";
  EXPECT_EQ(run_cli("validate --strict " + dup, dir).code, 4);
  EXPECT_EQ(run_cli("validate " + dup, dir).code, 0);
  std::filesystem::remove_all(dir);
}

TEST(Cli, ValidateCountsSelfIntersections) {
  const auto dir = test::temp_dir("cli_selfint");
  TriMesh m = make_icosphere(3);
  const std::string good = (dir / "good.ply").string(), poked = (dir / "poked.ply").string(), js = (dir / "v.json").string();
  write_mesh(good, m);
  m.V.row(0) *= -1.5;  // a vertex pulled through the far side of the sphere
  write_mesh(poked, m);
  CliResult r = run_cli("validate --self-intersections --strict " + good, dir);
  EXPECT_EQ(r.code, 0) << r.out << r.err;
  EXPECT_NE(r.out.find("self-intersections: 0 pairs"), std::string::npos) << r.out;
  r = run_cli("validate --self-intersections " + poked + " --json " + js, dir);
  EXPECT_EQ(r.code, 0) << r.err;  // a report, not a failure, without --strict
  nlohmann::json j;
  std::ifstream(js) >> j;
  EXPECT_TRUE(j["clean"].get<bool>());  // no other problem
  const int n = j["self_intersections"].get<int>();
  EXPECT_GT(n, 0);
  EXPECT_EQ(int(j["self_intersecting_pairs"].size()), n);
  EXPECT_EQ(run_cli("validate --self-intersections --strict " + poked, dir).code, 4);
  EXPECT_EQ(run_cli("validate --strict " + poked, dir).code, 0);  // not asked for: not checked
  // a mesh the test cannot run on: said so, not counted as 0
  const std::string dup = (dir / "dup.off").string();
  std::ofstream(dup) << "OFF\n3 2 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n3 0 1 2\n";
  r = run_cli("validate --self-intersections " + dup + " --json " + js, dir);
  EXPECT_EQ(r.code, 0);
  EXPECT_NE(r.out.find("not checked"), std::string::npos) << r.out;
  std::ifstream(js) >> j;
  EXPECT_EQ(j["self_intersections"].get<int>(), -1);
  std::filesystem::remove_all(dir);
}

TEST(Cli, ValidateAgainstAReference) {
  const auto dir = test::temp_dir("cli_against");
  const std::string ref = (dir / "ref.ply").string(), fit = (dir / "fit.ply").string(), inv = (dir / "inv.ply").string(),
                    js = (dir / "v.json").string(), cloud = (dir / "cloud.ply").string();
  TriMesh sphere = make_icosphere(4);
  sphere.V *= 1.02;
  write_mesh(ref, sphere);
  TriMesh m = make_icosphere(3);  // centroids 0.02-0.03 inside the reference
  write_mesh(fit, m);
  m.F.col(1).swap(m.F.col(2));  // turned inside out
  write_mesh(inv, m);
  CliResult r = run_cli("validate --strict " + fit + " --against " + ref + " --probe-distance 0.05 --json " + js, dir);
  EXPECT_EQ(r.code, 0) << r.out << r.err;
  EXPECT_NE(r.out.find("0 point into it"), std::string::npos) << r.out;
  nlohmann::json j;
  std::ifstream(js) >> j;
  EXPECT_EQ(j["against"]["consistent"].get<int>(), m.F.rows());
  EXPECT_EQ(j["against"]["flipped"].get<int>(), 0);
  EXPECT_DOUBLE_EQ(j["against"]["probe_distance"].get<double>(), 0.05);
  r = run_cli("validate " + inv + " --against " + ref + " --probe-distance 0.05 --json " + js, dir);
  EXPECT_EQ(r.code, 0) << r.err;  // a report, not a failure, without --strict
  std::ifstream(js) >> j;
  EXPECT_EQ(j["against"]["flipped"].get<int>(), m.F.rows());
  EXPECT_EQ(int(j["against"]["flipped_faces"].size()), m.F.rows());
  EXPECT_EQ(run_cli("validate --strict " + inv + " --against " + ref + " --probe-distance 0.05", dir).code, 4);
  // the default probe (0.1 % of the reference diagonal, 0.0035) does not reach them: not judged,
  // never counted as flipped
  r = run_cli("validate " + inv + " --against " + ref + " --json " + js, dir);
  EXPECT_EQ(r.code, 0) << r.out;
  std::ifstream(js) >> j;
  EXPECT_NEAR(j["against"]["probe_distance"].get<double>(), 0.001 * 2.04 * std::sqrt(3.0), 1e-5);
  EXPECT_EQ(j["against"]["unmatched"].get<int>(), m.F.rows());
  // bad input: a reference without faces, a missing one, a probe that is not positive
  std::ofstream(cloud) << "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
                          "end_header\n0 0 0\n1 0 0\n0 1 0\n";
  r = run_cli("validate " + fit + " --against " + cloud, dir);
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.err.find("cloud.ply has no faces"), std::string::npos) << r.err;
  r = run_cli("validate " + fit + " --against " + (dir / "missing.ply").string(), dir);
  EXPECT_NE(r.code, 0);
  EXPECT_NE(r.err.find("missing.ply"), std::string::npos) << r.err;
  EXPECT_NE(run_cli("validate " + fit + " --against " + ref + " --probe-distance -1", dir).code, 0);
  std::filesystem::remove_all(dir);
}

TEST(Cli, DemoProducesOutputs) {
  const auto dir = test::temp_dir("cli_demo");
  const CliResult r = run_cli("demo -q --out " + (dir / "o").string(), dir);
  ASSERT_EQ(r.code, 0) << r.err;
  for (const char* f : {"fitted.ply", "fit_report.json", "fit.png", "bent_rotation_field.ply", "bent_linear.ply", "demo.png",
                        "report.json"})
    EXPECT_TRUE(std::filesystem::exists(dir / "o" / f)) << f;
  nlohmann::json j;
  std::ifstream(dir / "o" / "report.json") >> j;
  EXPECT_LT(j["mean_edge_strain"]["rotation_field"].get<double>(), j["mean_edge_strain"]["linear"].get<double>());
  nlohmann::json f;
  std::ifstream(dir / "o" / "fit_report.json") >> f;
  EXPECT_NEAR(f["scale"].get<double>(), 1.5, 0.1);  // the sample scan is the bar scaled ×1.5
  EXPECT_LT(f["metrics"]["p99"].get<double>() / f["metrics"]["bbox_diagonal"].get<double>(), 0.2);
  std::filesystem::remove_all(dir);
}

// Issue: `tbsp render` given a point cloud (a PLY with vertices only) drew an empty panel.
// Found by hand (2026-12-06): a mesh in tiny units (1e-100) rendered as an empty panel (its
// face normals underflowed to zero and every face was skipped), exit 0. Each panel framed on its
// own, the mesh at 1e-100, 1 and 1e100 draws the same picture.
TEST(Cli, RenderDrawsMeshesInAnyUnit) {
  const auto dir = test::temp_dir("cli_render_units");
  std::vector<std::string> files;
  for (double s : {1e-100, 1.0, 1e100}) {
    TriMesh m = make_icosphere(2);
    m.V *= s;
    files.push_back((dir / ("m" + std::to_string(files.size()) + ".off")).string());
    write_mesh(files.back(), m);
  }
  const std::string png = (dir / "u.png").string();
  const CliResult r = run_cli("render " + files[0] + " " + files[1] + " " + files[2] + " --own-frames --out " + png, dir);
  ASSERT_EQ(r.code, 0) << r.err;
  const cv::Mat img = cv::imread(png);
  ASSERT_FALSE(img.empty());
  const int w = img.cols / 3;
  std::vector<int> ink(3, 0);
  for (int k = 0; k < 3; ++k) {
    const cv::Mat area = img(cv::Rect(k * w + 2, 30, w - 4, img.rows - 30));
    for (int y = 0; y < area.rows; ++y)
      for (int x = 0; x < area.cols; ++x) ink[std::size_t(k)] += area.at<cv::Vec3b>(y, x) != cv::Vec3b(255, 255, 255);
  }
  EXPECT_GT(ink[1], 20000);  // a shaded sphere
  EXPECT_NEAR(ink[0], ink[1], 0.02 * ink[1]);
  EXPECT_NEAR(ink[2], ink[1], 0.02 * ink[1]);
  std::filesystem::remove_all(dir);
}

TEST(Cli, RenderDrawsPointCloudsWithAColourBar) {
  const auto dir = test::temp_dir("cli_render_cloud");
  TriMesh cloud;
  cloud.V = make_icosphere(3).V;  // 642 points, no faces
  cloud.F.resize(0, 3);
  const std::string in = (dir / "cloud.ply").string(), png = (dir / "c.png").string();
  write_mesh(in, cloud);
  std::ofstream sc(dir / "s.txt");
  for (Eigen::Index i = 0; i < cloud.V.rows(); ++i) sc << cloud.V(i, 0) << "\n";
  sc.close();
  CliResult r = run_cli("render " + in + " --scalar " + (dir / "s.txt").string() + " --out " + png, dir);
  ASSERT_EQ(r.code, 0) << r.err;
  const cv::Mat img = cv::imread(png);
  ASSERT_FALSE(img.empty());
  // the drawing area (below the title, above the colour bar) holds coloured dots: red and blue
  // ends of the scalar both appear
  const cv::Mat area = img(cv::Rect(0, 30, img.cols, img.rows - 90));
  int red = 0, blue = 0, ink = 0;
  for (int y = 0; y < area.rows; ++y)
    for (int x = 0; x < area.cols; ++x) {
      const cv::Vec3b p = area.at<cv::Vec3b>(y, x);
      ink += p != cv::Vec3b(255, 255, 255);
      red += p[2] > p[0] + 60 && p[2] > p[1] + 30;  // (dots are shaded by depth: judged by hue)
      blue += p[0] > p[2] + 60 && p[0] > p[1] + 30;
    }
  EXPECT_GT(ink, 5000);
  EXPECT_GT(red, 100);
  EXPECT_GT(blue, 100);
  // a wrong number of scalar values is an error naming the counts
  std::ofstream(dir / "short.txt") << "1\n2\n";
  r = run_cli("render " + in + " --scalar " + (dir / "short.txt").string() + " --out " + png, dir);
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.err.find("2 values for the 642 points"), std::string::npos) << r.err;
  // a colour bar range with LO >= HI (it painted everything the LO colour)
  const auto before = std::filesystem::file_size(png);
  r = run_cli("render " + in + " --scalar " + (dir / "s.txt").string() + " --range 1 0 --out " + png, dir);
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.err.find("--range 1 0: give LO < HI"), std::string::npos) << r.err;
  EXPECT_EQ(std::filesystem::file_size(png), before);
  std::filesystem::remove_all(dir);
}

// `tbsp` is a launcher that executes tbsp-cli (plugins/cli/launcher.cpp): arguments, output and
// exit codes pass through, and a launcher without its CLI says what it looked for.
TEST(Cli, LauncherPassesThroughAndNamesAMissingCli) {
  const auto dir = test::temp_dir("cli_launcher");
  CliResult r = run_cli("--version", dir);
  EXPECT_EQ(r.code, 0) << r.err;
  EXPECT_NE(r.out.find("tbsp 0.1.0"), std::string::npos) << r.out;
  r = run_cli("no-such-command", dir);
  EXPECT_NE(r.code, 0);
  EXPECT_EQ(r.err.find("tbsp-cli"), std::string::npos) << "the CLI, not the launcher, answers: " << r.err;
  // the launcher alone, without tbsp-cli beside it or in ../libexec
  const auto alone = dir / "bin" / "tbsp";
  std::filesystem::create_directories(alone.parent_path());
  std::filesystem::copy_file(TBSP_CLI, alone);
  r = run_cli("--version", dir, alone.string());
  EXPECT_EQ(r.code, 127);
  EXPECT_NE(r.err.find("tbsp-cli"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find((dir / "bin").string()), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("Fix:"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find(std::strerror(ENOENT)), std::string::npos) << r.err;
  // a tbsp-cli that is there but not executable: the reason is the permission, not absence
  std::ofstream(dir / "bin" / "tbsp-cli") << "#!/bin/sh\n";
  std::filesystem::permissions(dir / "bin" / "tbsp-cli", std::filesystem::perms::owner_read | std::filesystem::perms::owner_write);
  r = run_cli("--version", dir, alone.string());
  EXPECT_EQ(r.code, 127);
  EXPECT_NE(r.err.find(std::strerror(EACCES)), std::string::npos) << r.err;  // (root too: no execute bit at all)
  std::filesystem::remove_all(dir);
}
