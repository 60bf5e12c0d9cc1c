// `tbsp tetdeform` end to end: outputs, report, errors, no clobbering.
#include <gtest/gtest.h>
#include <sys/wait.h>

#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>

#include "cli_util.h"
#include "test_util.h"
#include "tbsp/io/mesh_io.h"
#include "tbsp/io/tet_mesh_io.h"
#include "tbsp/mesh/primitives.h"
#include "tbsp/mesh/tet_mesh.h"
#include "tbsp/mesh/tetrahedralize.h"

using namespace tbsp;

namespace {
using test::CliResult;
using test::run_cli;
std::string write(const std::filesystem::path& p, const std::string& text) {
  std::ofstream(p) << text;
  return p.string();
}
const char* kBend =
    R"({"handles": [
         {"box": {"min": [-1, -1, -1], "max": [0.051, 1, 1]}},
         {"box": {"min": [0.949, -1, -1], "max": [2, 1, 1]},
          "rotate": {"axis": [0, 1, 0], "degrees": 90, "center": [0.95, 0.1, 0.1]}, "translate": [-0.327, 0, -0.573]}
       ], "iterations": 80})";
}  // namespace

TEST(CliTet, BendsABarAndTransfersToTheInput) {
  const auto dir = test::temp_dir("cli_tet");
  const std::string bar = (dir / "bar.off").string();
  write_mesh(bar, make_box(40, 8, 8, 1.0, 0.2, 0.2));
  const std::string h = write(dir / "h.json", kBend);
  const std::string out = (dir / "bent.ply").string(), rep = (dir / "r.json").string(), tets = (dir / "t.mesh").string();
  const CliResult r = run_cli("tetdeform -q --mesh " + bar + " --handles " + h + " --out " + out + " --tets 3000 --report " + rep +
                              " --save-tets " + tets,
                          dir);
  ASSERT_EQ(r.code, 0) << r.err;
  const TriMesh in = read_mesh(bar), m = read_mesh(out);
  ASSERT_EQ(m.V.rows(), in.V.rows());
  ASSERT_EQ(m.F, in.F);
  nlohmann::json j;
  std::ifstream(rep) >> j;
  EXPECT_TRUE(j["tet_mesh"]["decimated"].get<bool>());
  EXPECT_GT(j["tet_mesh"]["tets"].get<int>(), 1500);
  EXPECT_EQ(j["e_nonrigid"].size(), std::size_t(j["iterations"].get<int>()));
  EXPECT_LT(std::abs(j["volume_ratio"].get<double>() - 1), 0.03);
  EXPECT_GT(j["timings_s"]["iterations_per_s"].get<double>(), 0.0);
  EXPECT_GT(j["timings_s"]["transfer_precompute"].get<double>(), 0.0);
  // the right end turned down by ~90 degrees: its end face now points along -z
  double zmin = 1e9;
  for (Eigen::Index i = 0; i < m.V.rows(); ++i) zmin = std::min(zmin, m.V(i, 2));
  EXPECT_LT(zmin, -0.4);
  const TetMesh t = read_tet_mesh(tets);
  EXPECT_EQ(t.T.rows(), j["tet_mesh"]["tets"].get<int>());

  // a (rest) tet mesh in, a tet mesh out
  const std::string rest = (dir / "rest.mesh").string(), out2 = (dir / "bent2.mesh").string();
  write_tet_mesh(rest, tetrahedralize(make_box(20, 4, 4, 1.0, 0.2, 0.2)));
  const CliResult r2 = run_cli("tetdeform -q --mesh " + rest + " --handles " + h + " --out " + out2, dir);
  ASSERT_EQ(r2.code, 0) << r2.err;
  EXPECT_EQ(read_tet_mesh(out2).V.rows(), read_tet_mesh(rest).V.rows());
  std::filesystem::remove_all(dir);
}

TEST(CliTet, BadInputGivesClearErrorsAndKeepsOutputs) {
  const auto dir = test::temp_dir("cli_tet_bad");
  const std::string bar = (dir / "bar.off").string();
  write_mesh(bar, make_box(10, 2, 2, 1.0, 0.2, 0.2));
  const std::string out = (dir / "keep.ply").string();
  write(out, "precious");
  auto expect = [&](const std::string& args, int code, const std::vector<std::string>& needles) {
    const CliResult r = run_cli("tetdeform -q " + args + " --out " + out, dir);
    EXPECT_EQ(r.code, code) << args << "\n" << r.err;
    for (const auto& n : needles) EXPECT_NE(r.err.find(n), std::string::npos) << "missing '" << n << "' in: " << r.err;
    std::ifstream in(out);
    std::string s;
    in >> s;
    EXPECT_EQ(s, "precious") << "output clobbered by: " << args;
  };
  const std::string good = write(dir / "good.json", kBend);
  // open surface
  TriMesh open = make_box(4, 2, 2);
  open.F.conservativeResize(open.F.rows() - 2, 3);
  const std::string openf = (dir / "open.off").string();
  write_mesh(openf, open);
  expect("--mesh " + openf + " --handles " + good, 2, {"open.off", "boundary"});
  // self-intersecting surface
  TriMesh a = make_box(2, 2, 2), two;
  two.V.resize(2 * a.V.rows(), 3);
  two.V << a.V, (a.V.array() + 0.37).matrix();
  two.F.resize(2 * a.F.rows(), 3);
  two.F << a.F, (a.F.array() + int(a.V.rows())).matrix();
  const std::string selff = (dir / "self.off").string();
  write_mesh(selff, two);
  expect("--mesh " + selff + " --handles " + good, 2, {"self.off", "self-intersects"});
  // handles on missing vertices, no handles, malformed JSON, unknown keys, regions selecting nothing
  expect("--mesh " + bar + " --handles " + write(dir / "missing.json", R"({"handles": [{"vertices": [0, 99999]}]})"), 2,
         {"missing.json", "handles[0].vertices[1]", "99999 does not exist"});
  expect("--mesh " + bar + " --handles " + write(dir / "none.json", R"({"handles": []})"), 2, {"none.json", "at least one handle"});
  expect("--mesh " + bar + " --handles " + write(dir / "broken.json", R"({"handles": [)"), 2, {"broken.json"});
  expect("--mesh " + bar + " --handles " + write(dir / "typo.json", R"({"handles": [{"box": {"min": [0,0,0], "max": [1,1,1]}, "rotat": 1}]})"), 2,
         {"typo.json", "unknown key \"rotat\""});
  expect("--mesh " + bar + " --handles " + write(dir / "empty_region.json", R"({"handles": [{"sphere": {"center": [5,5,5], "radius": 0.1}}]})"), 2,
         {"empty_region.json", "handles[0]", "selects no vertex"});
  expect("--mesh " + bar + " --handles " + write(dir / "overlap.json", R"({"handles": [{"box": {"min": [-1,-1,-1], "max": [2,2,2]}}, {"vertex": 0, "target": [0,0,0]}]})"), 2,
         {"overlap.json", "belongs to handle 0 and handle 1"});
  expect("--mesh " + bar + " --handles " + good + " --stiffness " + write(dir / "s.json", R"({"default": -1})"), 2, {"s.json", "default"});
  std::filesystem::remove_all(dir);
}
