// `tbsp animate` end to end: a synthetic studio's markers drive its template (meshes, report,
// contact sheet), and bad input (exit 2, a message naming the file and item, nothing clobbered).
#include <gtest/gtest.h>

#include <fstream>
#include <sstream>

#include <nlohmann/json.hpp>

#include "cli_json.h"
#include "cli_util.h"
#include "test_util.h"
#include "tbsp/io/mesh_io.h"
#include "tbsp/io/mocap_io.h"

using namespace tbsp;
namespace fs = std::filesystem;

namespace {
// synth-studio names its markers "V<vertex>": the map follows from the TRC's labels.
void write_map(const fs::path& trc, const fs::path& out, const std::string& rename_first = "") {
  const MarkerTrajectories mk = read_trc(trc.string());
  nlohmann::json m;
  for (std::size_t k = 0; k < mk.names.size(); ++k)
    m["markers"].push_back({{"marker", k == 0 && !rename_first.empty() ? rename_first : mk.names[k]}, {"vertex", std::stoi(mk.names[k].substr(1))}});
  std::ofstream(out) << m.dump(1);
}
}  // namespace

TEST(CliAnimate, MarkersDriveTheTemplateIntoMeshesReportAndContactSheet) {
  const auto dir = test::temp_dir("cli_animate");
  const fs::path st = dir / "studio", out = dir / "out";
  auto r = test::run_cli("synth-studio -q --out " + st.string() + " --cameras 2 --width 64 --height 64 --frames 6 --markers 30 --detail 0", dir);
  ASSERT_EQ(r.code, 0) << r.err;
  write_map(st / "markers.trc", dir / "map.json");
  r = test::run_cli("animate -q --markers " + (st / "markers.trc").string() + " --template " + (st / "template.ply").string() + " --map " +
                        (dir / "map.json").string() + " --out " + out.string() + " --every 2 --contact-sheet 3 --tets 1000",
                    dir);
  ASSERT_EQ(r.code, 0) << r.err;
  for (const char* f : {"mesh_0000.ply", "mesh_0002.ply", "mesh_0004.ply", "animate_report.json", "contact_sheet.png"})
    EXPECT_TRUE(fs::exists(out / f)) << f;
  EXPECT_FALSE(fs::exists(out / "mesh_0001.ply"));  // --every 2
  const auto rep = test::load_json(out / "animate_report.json");
  EXPECT_EQ(rep["frames"].get<int>(), 6);
  EXPECT_EQ(rep["per_frame"].size(), 6u);
  EXPECT_EQ(rep["meshes_written"].get<int>(), 3);
  // The meshes follow the ground truth (the template's connectivity, close to gt/FFFF.ply).
  const TriMesh m4 = read_mesh((out / "mesh_0004.ply").string()), g4 = read_mesh((st / "gt/0004.ply").string());
  ASSERT_EQ(m4.V.rows(), g4.V.rows());
  const double diag = (g4.V.colwise().maxCoeff() - g4.V.colwise().minCoeff()).norm();
  EXPECT_LT((m4.V - g4.V).rowwise().norm().mean(), 0.03 * diag);

  // A map naming a marker the file does not have: exit 2 naming it; the report is not clobbered.
  write_map(st / "markers.trc", dir / "bad.json", "LFHD");
  const auto before = fs::last_write_time(out / "animate_report.json");
  r = test::run_cli("animate -q --markers " + (st / "markers.trc").string() + " --template " + (st / "template.ply").string() + " --map " +
                        (dir / "bad.json").string() + " --out " + out.string(),
                    dir);
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.err.find("'LFHD'"), std::string::npos) << r.err;
  EXPECT_EQ(fs::last_write_time(out / "animate_report.json"), before);
  // A malformed map: exit 2 naming the file and the item.
  std::ofstream(dir / "malformed.json") << R"({"markers": [{"marker": "V0", "vertex": "seven"}]})";
  r = test::run_cli("animate -q --markers " + (st / "markers.trc").string() + " --template " + (st / "template.ply").string() + " --map " +
                        (dir / "malformed.json").string() + " --out " + out.string(),
                    dir);
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.err.find("malformed.json"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("markers[0].vertex"), std::string::npos) << r.err;
  // Not a marker file.
  r = test::run_cli("animate -q --markers " + (st / "template.ply").string() + " --template " + (st / "template.ply").string() + " --map " +
                        (dir / "map.json").string() + " --out " + out.string(),
                    dir);
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.err.find(".c3d or .trc"), std::string::npos) << r.err;
  fs::remove_all(dir);
}
