// tbsp-studio run for real (label ui: under xvfb-run): screenshots, the fit heatmap, a scripted
// edit replayed by `tbsp tetdeform`, responsiveness while the solver runs, bad input.
#include <gtest/gtest.h>

#include <fstream>
#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <sstream>
#include <sys/wait.h>

#include "tbsp/io/mesh_io.h"
#include "tbsp/mesh/primitives.h"
#include "test_util.h"

namespace {

using tbsp::test::sample;
using tbsp::test::temp_dir;
using tbsp::test::write_text;
namespace fs = std::filesystem;

struct Proc {
  int rc;
  std::string out, err;
};

Proc run(const std::string& exe, const std::string& args, const fs::path& dir) {
  const std::string o = (dir / "stdout.txt").string(), e = (dir / "stderr.txt").string();
  const int rc = std::system(("cd " + dir.string() + " && " + exe + " " + args + " >" + o + " 2>" + e).c_str());
  auto slurp = [](const std::string& f) {
    std::ifstream in(f);
    std::stringstream ss;
    ss << in.rdbuf();
    return ss.str();
  };
  return {WIFEXITED(rc) ? WEXITSTATUS(rc) : -1, slurp(o), slurp(e)};
}
Proc studio(const std::string& args, const fs::path& dir) { return run(TBSP_STUDIO, args, dir); }
Proc cli(const std::string& args, const fs::path& dir) { return run(TBSP_CLI, args, dir); }

struct Fg {
  int n = 0;
  double cx = 0, cy = 0;
  int x0 = 1 << 30, x1 = -1, y0 = 1 << 30, y1 = -1;
};
Fg foreground(const cv::Mat& img) {
  Fg f;
  for (int y = 0; y < img.rows; ++y)
    for (int x = 0; x < img.cols; ++x) {
      const cv::Vec3b p = img.at<cv::Vec3b>(y, x);
      if (p[0] < 240 || p[1] < 240 || p[2] < 240) {
        ++f.n;
        f.cx += x;
        f.cy += y;
        f.x0 = std::min(f.x0, x);
        f.x1 = std::max(f.x1, x);
        f.y0 = std::min(f.y0, y);
        f.y1 = std::max(f.y1, y);
      }
    }
  if (f.n) {
    f.cx /= f.n;
    f.cy /= f.n;
  }
  return f;
}

}  // namespace

TEST(StudioApp, ScreenshotShowsTheMeshWhereTheCameraLooks) {
  const auto dir = temp_dir("studio_shot");
  const Proc r = studio(sample("bumpy_bar.off") + " --size 400x300 --screenshot shot.png", dir);
  ASSERT_EQ(r.rc, 0) << r.err;
  const cv::Mat img = cv::imread((dir / "shot.png").string());
  ASSERT_EQ(img.cols, 400);
  ASSERT_EQ(img.rows, 300);
  const Fg f = foreground(img);
  EXPECT_GT(f.n, 400 * 300 / 20) << "not blank";
  EXPECT_NEAR(f.cx, 200, 15) << "the bar is centred";
  EXPECT_NEAR(f.cy, 150, 15);
  EXPECT_GT(f.x1 - f.x0, 3 * (f.y1 - f.y0)) << "the 1 x 0.22 bar lies across the view";
}

TEST(StudioApp, FitReportShowsTheErrorHeatmap) {
  const auto dir = temp_dir("studio_fit");
  const Proc fit = cli("fit --template " + sample("bumpy_bar.off") + " --cloud " + sample("bar_scan.ply") + " --markers " +
                          sample("bar_markers.json") + " --out fit.ply --report fit.json -q",
                      dir);
  ASSERT_EQ(fit.rc, 0) << fit.err;
  const Proc r = studio("fit.json --size 400x300 --screenshot heat.png", dir);
  ASSERT_EQ(r.rc, 0) << r.err;
  const cv::Mat img = cv::imread((dir / "heat.png").string());
  ASSERT_FALSE(img.empty());
  // viridis: the well-fitted scan points are dark purple/blue (low), the 5 % outliers saturate
  // at yellow (high); count pixels whose colour is close to each end
  int low = 0, high = 0;
  for (int y = 0; y < img.rows; ++y)
    for (int x = 0; x < img.cols * 8 / 10; ++x) {  // left of the colour bar
      const cv::Vec3b p = img.at<cv::Vec3b>(y, x);  // BGR
      if (p[2] < 110 && p[1] < 110 && p[0] > 70 && p[0] > p[1] + 20) ++low;
      if (p[2] > 200 && p[1] > 190 && p[0] < 90) ++high;
    }
  EXPECT_GT(low, 3000) << "low-error (dark purple) scan points";
  EXPECT_GT(high, 50) << "outliers at the top colour";
  // the colour bar itself: a yellow top and a purple bottom right of x = 80 %
  int bar_low = 0, bar_high = 0;
  for (int y = 0; y < img.rows; ++y)
    for (int x = img.cols * 8 / 10; x < img.cols; ++x) {
      const cv::Vec3b p = img.at<cv::Vec3b>(y, x);
      bar_low += p[2] < 110 && p[1] < 60 && p[0] > 70;
      bar_high += p[2] > 200 && p[1] > 190 && p[0] < 90;
    }
  EXPECT_GT(bar_low, 50);
  EXPECT_GT(bar_high, 50);
}

TEST(StudioApp, ScriptedDragEqualsTetdeformAndTheViewKeepsUp) {
  const auto dir = temp_dir("studio_edit");
  write_text(dir / "script.json", R"({"actions": [
    {"edit": {"mesh": ")" + sample("bumpy_bar.off") + R"(", "tets": 5000}},
    {"select": {"rect": [0, 0, 140, 600]}},
    {"add_handle": "selection"},
    {"select": {"rect": [660, 0, 800, 600]}},
    {"add_handle": "selection"},
    {"iterate": 5},
    {"reset_measurements": 0},
    {"drag": {"handle": 1, "translate": [-0.2, 0.35, 0], "rotate": {"axis": [0, 0, 1], "degrees": 80, "center": [0.95, 0, 0]}}},
    {"iterate": 300},
    {"report": "session.json"},
    {"screenshot": "dragged.png"},
    {"save": {"mesh": "edited.ply", "handles": "handles.json", "iterations": 120}},
    {"undo": 1},
    {"iterate": 300},
    {"save": {"mesh": "undone.ply", "handles": "undone_handles.json", "iterations": 120}}
  ]})");
  const Proc r = studio("--script script.json", dir);
  ASSERT_EQ(r.rc, 0) << r.err;
  // the saved edit is what `tbsp tetdeform` computes from the saved handles
  const Proc c = cli("tetdeform --mesh " + sample("bumpy_bar.off") + " --tets 5000 --handles handles.json --out cli.ply -q", dir);
  ASSERT_EQ(c.rc, 0) << c.err;
  const tbsp::TriMesh rest = tbsp::read_mesh(sample("bumpy_bar.off"));
  const tbsp::TriMesh app = tbsp::read_mesh((dir / "edited.ply").string());
  const tbsp::TriMesh ref = tbsp::read_mesh((dir / "cli.ply").string());
  ASSERT_EQ(app.V.rows(), ref.V.rows());
  EXPECT_LT((app.V - ref.V).cwiseAbs().maxCoeff(), 1e-9);
  EXPECT_EQ(app.F, ref.F);
  // the drag moved the right end up by ~0.35 and left the left end
  EXPECT_GT((app.V - rest.V).rowwise().norm().maxCoeff(), 0.3);
  nlohmann::json h;
  std::ifstream(dir / "handles.json") >> h;
  ASSERT_EQ(h["handles"].size(), 2u);
  ASSERT_GT(h["handles"][0]["vertices"].size(), 20u) << "the rubber band selected the visible left end";
  for (int v : h["handles"][0]["vertices"]) {
    EXPECT_LT(rest.V(v, 0), 0.2) << "selected from the left end of the view";
    // the tet mesh is decimated: surface vertices follow by DeformationTransfer, within ~0.1 %
    EXPECT_LT((app.V.row(v) - rest.V.row(v)).norm(), 1e-3) << "fixed handle, vertex " << v;
  }
  // undo: back to the handles before the drag, i.e. the rest shape
  const tbsp::TriMesh undone = tbsp::read_mesh((dir / "undone.ply").string());
  EXPECT_LT((undone.V - rest.V).cwiseAbs().maxCoeff(), 1e-3);
  // the view followed the solver and the UI thread stayed responsive (~5k tets)
  nlohmann::json s;
  std::ifstream(dir / "session.json") >> s;
  EXPECT_GE(s["mesh"]["tets"].get<int>(), 4000);
  EXPECT_LE(s["mesh"]["tets"].get<int>(), 8000);
  EXPECT_GE(s["view_updates"].get<int>(), 20) << "the view is updated after iterations";
  EXPECT_GE(s["event_loop_latency_ms"]["samples"].get<int>(), 20);
  // Timing on a shared CI machine is noisy: the test asserts what cannot be a scheduling accident,
  // that the UI thread is never held for a solve (~1 s here): median within 100 ms, no stall over
  // 250 ms. The ≤ 33 ms frame target is a benchmark's: bench/bench_studio.sh measures it over
  // repeated runs (docs/benchmarks.md). (A CI run with two benchmarks beside ctest -j2 measured a
  // median of 33.6 ms, max 67 ms; a quiet run 7 ms, max 20 ms.)
  EXPECT_LE(s["event_loop_latency_ms"]["median"].get<double>(), 100.0) << s.dump(2);
  EXPECT_LE(s["event_loop_latency_ms"]["max"].get<double>(), 250.0) << s.dump(2);
  const Fg f = foreground(cv::imread((dir / "dragged.png").string()));
  EXPECT_LT(f.cy, 300) << "the bent bar rises in the view";
}

TEST(StudioApp, BadInputShowsAMessageAndKeepsTheSession) {
  const auto dir = temp_dir("studio_bad");
  write_text(dir / "garbage.ply", "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nend_header\n1\n");
  tbsp::write_mesh((dir / "open.off").string(), tbsp::make_grid(4, 4));  // not closed: cannot be edited
  // two closed tetrahedra sharing one vertex: closed but not a manifold
  write_text(dir / "bowtie.off", "OFF\n7 8 0\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n-1 0 0\n0 -1 0\n0 0 2\n"
                             "3 0 2 1\n3 0 1 3\n3 0 3 2\n3 1 2 3\n3 4 5 0\n3 4 0 6\n3 4 6 5\n3 0 5 6\n");
  write_text(dir / "bad_handles.json", R"({"handles": [{"vertices": [1, 99999]}]})");
  write_text(dir / "script.json", R"({"actions": [
    {"open": "missing.ply"},
    {"open": "garbage.ply"},
    {"edit": {"mesh": "open.off", "tets": 0}},
    {"edit": {"mesh": "bowtie.off", "tets": 0}},
    {"edit": {"mesh": ")" + sample("bumpy_bar.off") + R"(", "tets": 0}},
    {"load_handles": "bad_handles.json"},
    {"add_handle": {"vertices": [0, 999999]}},
    {"add_handle": {"sphere": {"center": [50, 50, 50], "radius": 0.01}}},
    {"add_handle": {"box": {"min": [-1, -1, -1], "max": [0.05, 1, 1]}}},
    {"save": {"mesh": "good.ply", "handles": "good.json", "iterations": 10}},
    {"drag": {"handle": 0, "translate": [0, 0.3, 0]}},
    {"save": {"mesh": "good.ply", "handles": "no_such_dir/h.json", "iterations": 10}},
    {"drag": {"handle": 7, "translate": [0, 0.3, 0]}},
    {"screenshot": "alive.png"}
  ]})");
  const Proc r = studio("--script script.json", dir);
  EXPECT_EQ(r.rc, 2) << "a script with failed actions exits 2";
  EXPECT_NE(r.err.find("missing.ply"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("garbage.ply"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("open.off"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("bowtie.off"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("bad_handles.json: handles[0].vertices[1]"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("999999"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("selects no vertex"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("no_such_dir"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("handle 7 does not exist"), std::string::npos) << r.err;
  // the session lived on: the last screenshot shows the mesh
  EXPECT_GT(foreground(cv::imread((dir / "alive.png").string())).n, 1000);
  // what was saved is intact: the failed save did not touch good.ply (the undeformed bar)
  const tbsp::TriMesh good = tbsp::read_mesh((dir / "good.ply").string());
  const tbsp::TriMesh rest = tbsp::read_mesh(sample("bumpy_bar.off"));
  EXPECT_LT((good.V - rest.V).cwiseAbs().maxCoeff(), 1e-6);
  for (const auto& e : fs::directory_iterator(dir))
    EXPECT_EQ(e.path().string().find(".tmp"), std::string::npos) << "temporary file left: " << e.path();
}

TEST(StudioApp, MalformedScriptOrArgumentsAreRefusedUpFront) {
  const auto dir = temp_dir("studio_script");
  write_text(dir / "s.json", R"({"actions": [{"open": "a.ply"}, {"rotate_everything": 1}]})");
  Proc r = studio("--script s.json", dir);
  EXPECT_EQ(r.rc, 2);
  EXPECT_NE(r.err.find("actions[1]"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("rotate_everything"), std::string::npos) << r.err;
  write_text(dir / "t.json", R"({"actions": [{"drag": {"handle": 0, "translate": [1, 2]}}]})");
  r = studio("--script t.json", dir);
  EXPECT_EQ(r.rc, 2);
  EXPECT_NE(r.err.find("translate"), std::string::npos) << r.err;
  write_text(dir / "u.json", "{not json");
  r = studio("--script u.json", dir);
  EXPECT_EQ(r.rc, 2);
  EXPECT_NE(r.err.find("u.json"), std::string::npos) << r.err;
  r = studio("--size 10x10 --screenshot x.png", dir);
  EXPECT_EQ(r.rc, 2);
  r = run("env -u DISPLAY " + std::string(TBSP_STUDIO), "--screenshot x.png", dir);
  EXPECT_EQ(r.rc, 2);
  EXPECT_NE(r.err.find("xvfb-run"), std::string::npos) << r.err;
}

TEST(StudioApp, StudioCamerasWithImagesAndASequenceOnTheTimeline) {
  const auto dir = temp_dir("studio_seq");
  const Proc g = cli("synth-studio --out studio --cameras 4 --width 200 --height 200 --frames 3 -q", dir);
  ASSERT_EQ(g.rc, 0) << g.err;
  write_text(dir / "script.json", R"({"actions": [
    {"open": "studio/studio.yaml"},
    {"frame": 2},
    {"screenshot": "studio.png"},
    {"add": "studio/gt"},
    {"screenshot": "f0.png"},
    {"frame": 2},
    {"screenshot": "f2.png"}
  ]})");
  const Proc r = studio("--size 400x300 --script script.json", dir);
  ASSERT_EQ(r.rc, 0) << r.err;
  // the camera frustums (blue lines) and the textured camera images (colourful) are drawn
  const cv::Mat img = cv::imread((dir / "studio.png").string());
  int blue = 0, colourful = 0;
  for (int y = 0; y < img.rows; ++y)
    for (int x = 0; x < img.cols; ++x) {
      const cv::Vec3b p = img.at<cv::Vec3b>(y, x);
      blue += p[0] > 150 && p[2] < 80 && p[1] < 120;
      const int mx = std::max({p[0], p[1], p[2]}), mn = std::min({p[0], p[1], p[2]});
      colourful += mx - mn > 60 && !(p[0] > 150 && p[2] < 80 && p[1] < 120);
    }
  EXPECT_GT(blue, 100) << "camera frustums";
  EXPECT_GT(colourful, 20) << "camera images on the image planes";
  // the sequence plays: frame 2 differs from frame 0 where the performer moved
  const cv::Mat f0 = cv::imread((dir / "f0.png").string()), f2 = cv::imread((dir / "f2.png").string());
  ASSERT_FALSE(f0.empty());
  ASSERT_FALSE(f2.empty());
  EXPECT_GT(foreground(f0).n, 1000);
  cv::Mat diff;
  cv::absdiff(f0, f2, diff);
  EXPECT_GT(cv::countNonZero(diff.reshape(1) > 40), 100);
}

TEST(StudioApp, SurfaceEditingWithAndWithoutTheRotationFieldEqualsTbspDeform) {
  const auto dir = temp_dir("studio_surface");
  write_text(dir / "script.json", R"({"actions": [
    {"edit": {"mesh": ")" + sample("bumpy_bar.off") + R"(", "solver": "surface"}},
    {"select": {"rect": [0, 0, 140, 600]}},
    {"add_handle": "selection"},
    {"select": {"rect": [660, 0, 800, 600]}},
    {"add_handle": "selection"},
    {"drag": {"handle": 1, "translate": [-0.2, 0.35, 0], "rotate": {"axis": [0, 0, 1], "degrees": 80, "center": [0.95, 0, 0]}}},
    {"wait": true},
    {"screenshot": "off.png"},
    {"save": {"mesh": "off.ply", "handles": "off_h.json", "constraints": "off_c.json"}},
    {"rotation_field": true},
    {"wait": true},
    {"save": {"mesh": "on.ply", "handles": "on_h.json", "constraints": "on_c.json"}},
    {"add_rigid": "selection"}
  ]})");
  const Proc r = studio("--script script.json", dir);
  EXPECT_EQ(r.rc, 2) << "the rigid region is refused for surface editing";
  EXPECT_NE(r.err.find("rigid regions belong to the tet solver"), std::string::npos) << r.err;
  const tbsp::TriMesh rest = tbsp::read_mesh(sample("bumpy_bar.off"));
  tbsp::TriMesh on, off;
  for (const std::string m : {"off", "on"}) {
    const Proc c = cli("deform --mesh " + sample("bumpy_bar.off") + " --constraints " + m + "_c.json --out cli_" + m + ".ply -q", dir);
    ASSERT_EQ(c.rc, 0) << c.err;
    const tbsp::TriMesh app = tbsp::read_mesh((dir / (m + ".ply")).string());
    const tbsp::TriMesh ref = tbsp::read_mesh((dir / ("cli_" + m + ".ply")).string());
    EXPECT_LT((app.V - ref.V).cwiseAbs().maxCoeff(), 1e-9) << m;
    EXPECT_GT((app.V - rest.V).rowwise().norm().maxCoeff(), 0.3) << m;
    (m == "on" ? on : off) = app;
  }
  // the rotation field turns the bar's cross-sections with the handle: a visibly different shape
  EXPECT_GT((on.V - off.V).rowwise().norm().maxCoeff(), 0.01);
  // and the view showed the dragged shape (not the rest shape) when the first screenshot was taken
  EXPECT_LT(foreground(cv::imread((dir / "off.png").string())).cy, 290);
}

TEST(StudioApp, TetdeformAndTextureReportsOpenAsDisplacementMapAndTexturedMesh) {
  const auto dir = temp_dir("studio_reports");
  // a tetdeform run and its report
  const Proc t = cli("tetdeform --mesh " + sample("bumpy_bar.off") + " --tets 3000 --handles " + sample("bar_twist_tet.json") +
                         " --iterations 30 --out twisted.ply --report tet.json -q",
                     dir);
  ASSERT_EQ(t.rc, 0) << t.err;
  // a textured OBJ with a red / blue texture as tbsp texture writes it, and its report
  tbsp::TriMesh m = tbsp::make_icosphere(3);
  Eigen::MatrixX2d uv(m.V.rows(), 2);
  for (Eigen::Index i = 0; i < m.V.rows(); ++i) uv.row(i) << (m.V(i, 0) > 0 ? 0.75 : 0.25), 0.5;
  tbsp::write_textured_obj((dir / "tex.obj").string(), m, uv, (dir / "tex.mtl").string(), "texture", "tex.png");
  cv::Mat img(64, 64, CV_8UC3, cv::Scalar(255, 0, 0));              // BGR: blue ...
  img(cv::Rect(32, 0, 32, 64)).setTo(cv::Scalar(0, 0, 255));        // ... left, red right
  cv::imwrite((dir / "tex.png").string(), img);
  write_text(dir / "texture.json", R"({"mesh": "sphere.off", "output": "tex.obj", "image": {"path": "x.png"}, "constraints": 3})");
  write_text(dir / "script.json", R"({"actions": [
    {"open": "tet.json"}, {"screenshot": "tet.png"},
    {"open": "texture.json"}, {"camera": {"eye": [0, 0, 5], "focal": [0, 0, 0], "up": [0, 1, 0]}}, {"screenshot": "tex.png.png"}
  ]})");
  const Proc r = studio("--size 400x300 --script script.json", dir);
  ASSERT_EQ(r.rc, 0) << r.err;
  // the twisted bar: displacement heatmap (viridis yellow at the twisted end, purple at the fixed end)
  const cv::Mat tet = cv::imread((dir / "tet.png").string());
  int yellow = 0, purple = 0;
  for (int y = 0; y < tet.rows; ++y)
    for (int x = 0; x < tet.cols * 8 / 10; ++x) {
      const cv::Vec3b p = tet.at<cv::Vec3b>(y, x);
      yellow += p[2] > 170 && p[1] > 160 && p[0] < 110;
      purple += p[2] > 40 && p[2] < 130 && p[1] < 70 && p[0] > 60;
    }
  EXPECT_GT(yellow, 100);
  EXPECT_GT(purple, 100);
  // the textured sphere: red on its +x half (right in this view), blue on the left, unlit
  const cv::Mat tex = cv::imread((dir / "tex.png.png").string());
  int red_right = 0, blue_left = 0, red_left = 0;
  for (int y = 0; y < tex.rows; ++y)
    for (int x = 0; x < tex.cols; ++x) {
      const cv::Vec3b p = tex.at<cv::Vec3b>(y, x);
      const bool red = p[2] > 200 && p[1] < 60 && p[0] < 60, blue = p[0] > 200 && p[1] < 60 && p[2] < 60;
      red_right += red && x > tex.cols / 2;
      red_left += red && x < tex.cols / 2 - 10;
      blue_left += blue && x < tex.cols / 2;
    }
  EXPECT_GT(red_right, 2000);
  EXPECT_GT(blue_left, 2000);
  EXPECT_LT(red_left, 50);
  // the previous file's colour bar went with it: nothing viridis-yellow is left on the right
  int bar_yellow = 0;
  for (int y = 0; y < tex.rows; ++y)
    for (int x = tex.cols * 8 / 10; x < tex.cols; ++x) {
      const cv::Vec3b p = tex.at<cv::Vec3b>(y, x);
      bar_yellow += p[2] > 200 && p[1] > 190 && p[0] < 90;
    }
  EXPECT_EQ(bar_yellow, 0);
}
