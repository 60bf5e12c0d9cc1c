// tbsp texture: outputs (OBJ + MTL + PNG, coloured surface, render, report) and bad input.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>

#include "../fitting/texture_test_util.h"
#include "cli_util.h"
#include "tbsp/io/mesh_io.h"
#include "tbsp/mesh/point_mesh_distance.h"
#include "tbsp/mesh/primitives.h"

using namespace tbsp;

TEST(CliTexture, WritesTexturedMeshSurfaceReportAndRender) {
  const std::string mesh = test::shared("meshes/cfwen__geometry-processing-package/data/face.off");
  const std::string image = test::shared("capture/maximm8__VisualHull/templeSparseRing/templeSR0001.png");
  TBSP_REQUIRE_FILE(mesh);
  TBSP_REQUIRE_FILE(image);
  const auto dir = test::temp_dir("cli_texture");
  const TriMesh m = read_mesh(mesh);
  const int W = 640, H = 480;
  const auto layout = test::reference_layout(m.V, W, H, false, &m.F);
  const auto cons = test::layout_constraints(m.V, layout, W, H, 12, false);
  nlohmann::json j;
  for (const auto& c : cons) j["constraints"].push_back({{"pixel", {c.pixel.x(), c.pixel.y()}}, {"vertex", c.vertex}});
  const auto cfile = dir / "c.json";
  std::ofstream(cfile) << j.dump(1);
  const std::string out = (dir / "face_tex.obj").string();
  const std::string args = "texture --mesh " + mesh + " --image " + image + " --constraints " + cfile.string() + " --out " + out +
                           " --surface " + (dir / "surface.ply").string() + " --report " + (dir / "r.json").string() + " --render " +
                           (dir / "render.png").string() + " -q";
  auto r = test::run_cli(args, dir);
  ASSERT_EQ(r.code, 0) << r.err;
  for (const char* f : {"face_tex.obj", "face_tex.mtl", "face_tex.png", "surface.ply", "r.json", "render.png"})
    EXPECT_TRUE(std::filesystem::exists(dir / f)) << f;
  std::ifstream rin(dir / "r.json");
  const auto rep = nlohmann::json::parse(rin);
  EXPECT_LE(rep["max_constraint_residual_px"].get<double>(), 2.0);
  EXPECT_GE(rep["matched_fraction"].get<double>(), 0.9);  // 307k pixels: geodesics on a 3x coarser grid
  // The OBJ reads back with the same vertices; texture coordinates lie in [0,1].
  const TriMesh back = read_mesh(out);
  EXPECT_EQ(back.V.rows(), m.V.rows());
  std::ifstream oin(out);
  std::string line;
  long vt = 0;
  while (std::getline(oin, line))
    if (line.rfind("vt ", 0) == 0) {
      ++vt;
      double u = -1, v = -1;
      std::sscanf(line.c_str(), "vt %lf %lf", &u, &v);
      EXPECT_TRUE(u >= 0 && u <= 1 && v >= 0 && v <= 1) << line;
    }
  EXPECT_GE(vt, static_cast<long>(0.9 * m.V.rows()));

  // Bad constraint files: exit 2, file and item named, the existing output untouched.
  const auto before = std::filesystem::last_write_time(out);
  std::ofstream(dir / "bad.json") << R"({"constraints": [{"pixel": [1, 2], "vertex": 0}, {"pixel": [3], "vertex": 1}]})";
  r = test::run_cli("texture --mesh " + mesh + " --image " + image + " --constraints " + (dir / "bad.json").string() + " --out " + out + " -q", dir);
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.err.find("bad.json"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("constraints[1]"), std::string::npos) << r.err;
  std::ofstream(dir / "few.json") << R"({"constraints": [{"pixel": [1, 2], "vertex": 0}, {"pixel": [30, 40], "vertex": 1}]})";
  r = test::run_cli("texture --mesh " + mesh + " --image " + image + " --constraints " + (dir / "few.json").string() + " --out " + out + " -q", dir);
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.err.find("at least 3"), std::string::npos) << r.err;
  std::ofstream(dir / "far.json") << R"({"constraints": [{"pixel": [1, 2], "vertex": 0}, {"pixel": [30, 40], "vertex": 1}, {"pixel": [900, 40], "vertex": 2}]})";
  r = test::run_cli("texture --mesh " + mesh + " --image " + image + " --constraints " + (dir / "far.json").string() + " --out " + out + " -q", dir);
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.err.find("outside the 640x480 image"), std::string::npos) << r.err;
  std::ofstream(dir / "notimage.png") << "not a png";
  r = test::run_cli("texture --mesh " + mesh + " --image " + (dir / "notimage.png").string() + " --constraints " + cfile.string() + " --out " + out + " -q", dir);
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.err.find("notimage.png"), std::string::npos) << r.err;
  EXPECT_EQ(std::filesystem::last_write_time(out), before);
}

namespace {
/// Binary PGM (P5) / PPM (P6) writers: OpenCV reads both, so the test needs no image library.
void write_pnm(const std::filesystem::path& p, int w, int h, int channels, const std::vector<unsigned char>& data) {
  std::ofstream out(p, std::ios::binary);
  out << (channels == 1 ? "P5" : "P6") << "\n" << w << " " << h << "\n255\n";
  out.write(reinterpret_cast<const char*>(data.data()), static_cast<std::streamsize>(data.size()));
}
}  // namespace

// §4.4 from the command line: a masked pattern piece draped on a body with a normal offset; the
// deformed image surface (--surface) is the garment. A mask of the wrong size is refused.
TEST(CliTexture, DrapesAMaskedPatternAsAGarment) {
  const auto dir = test::temp_dir("cli_texture_drape");
  TriMesh body = make_tube(81, 48, 2.0, 0.3);
  write_mesh((dir / "body.ply").string(), body);
  const int W = 200, H = 160;
  std::vector<unsigned char> img(static_cast<std::size_t>(W) * H * 3, 180), mask(static_cast<std::size_t>(W) * H, 0);
  for (int y = 30; y < 130; ++y)
    for (int x = 20; x < 180; ++x) mask[static_cast<std::size_t>(y) * W + x] = 255;
  write_pnm(dir / "pattern.ppm", W, H, 3, img);
  write_pnm(dir / "mask.pgm", W, H, 1, mask);
  write_pnm(dir / "small_mask.pgm", W / 2, H, 1, std::vector<unsigned char>(static_cast<std::size_t>(W / 2) * H, 255));
  // Pixel x -> position along the tube, pixel y -> angle in [-90°, 90°] on the +y side.
  nlohmann::json j;
  for (double fx : {0.15, 0.5, 0.85})
    for (double fy : {0.25, 0.75}) {
      const double a = M_PI * (fy - 0.5);
      const Eigen::RowVector3d q(0.25 + 1.5 * fx, 0.3 * std::cos(a), 0.3 * std::sin(a));
      Eigen::Index best = 0;
      (body.V.rowwise() - q).rowwise().squaredNorm().minCoeff(&best);
      j["constraints"].push_back({{"pixel", {20 + fx * 159, 30 + fy * 99}}, {"vertex", best}});
    }
  std::ofstream(dir / "c.json") << j.dump(1);
  const std::string common = "texture --mesh " + (dir / "body.ply").string() + " --image " + (dir / "pattern.ppm").string() +
                             " --constraints " + (dir / "c.json").string() + " --out " + (dir / "garment_tex.obj").string() + " --offset 0.03 -q";
  auto r = test::run_cli(common + " --mask " + (dir / "mask.pgm").string() + " --surface " + (dir / "garment.ply").string(), dir);
  ASSERT_EQ(r.code, 0) << r.err;
  const TriMesh garment = read_mesh((dir / "garment.ply").string());
  // Only pattern pixels became garment: 100 x 160 pixels of the 200 x 160 image.
  EXPECT_NEAR(static_cast<double>(garment.V.rows()), 100.0 * 160.0, 0.05 * 100 * 160);
  const Eigen::VectorXd d = MeshDistance(body.V, body.F).distances(garment.V);
  EXPECT_NEAR(d.mean(), 0.03, 0.006);
  const auto before = std::filesystem::last_write_time(dir / "garment.ply");
  r = test::run_cli(common + " --mask " + (dir / "small_mask.pgm").string() + " --surface " + (dir / "garment.ply").string(), dir);
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.err.find("small_mask.pgm"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("the mask is 100x160"), std::string::npos) << r.err;
  EXPECT_EQ(std::filesystem::last_write_time(dir / "garment.ply"), before);
}
