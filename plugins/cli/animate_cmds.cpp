// `tbsp animate`: marker trajectories (C3D/TRC) drive a template through MarkerAnimation
// (thesis §6.2, §9.1): a mesh per frame, a report, a contact sheet (docs/performance_capture.md).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <nlohmann/json.hpp>
#include <sstream>

#include <Eigen/Geometry>

#include "command.h"
#include "progress_bar.h"
#include "tbsp/core/error.h"
#include "tbsp/io/atomic_file.h"
#include "tbsp/io/mesh_io.h"
#include "tbsp/io/mocap_io.h"
#include "tbsp/multiview/marker_animation.h"
#include "tbsp/plugins/marker_map_json.h"
#include "tbsp/plugins/preview_render.h"

namespace fs = std::filesystem;

namespace tbsp::cli {

namespace {

struct AnimateArgs {
  std::string markers, mesh, map, out, frames;
  MarkerAnimationOptions o;
  int every = 1, sheet = 8;
  bool no_meshes = false, no_align = false, quiet = false;
};

void add_animate(CLI::App& app, AnimateArgs& a, CLI::App*& sub) {
  sub = app.add_subcommand("animate", "drive a template with motion-capture markers (thesis §6.2/§9.1, docs/performance_capture.md)");
  sub->add_option("--markers", a.markers, "marker trajectories: .c3d or .trc")->required();
  sub->add_option("--template", a.mesh, "template surface mesh (closed for a volumetric control mesh)")->required();
  sub->add_option("--map", a.map, "marker map JSON: {\"markers\": [{\"marker\": NAME, \"vertex\": INDEX, \"align\": true}]}")->required();
  sub->add_option("--out", a.out, "output folder: mesh_FFFF.ply (FFFF = the file's frame number), animate_report.json, contact_sheet.png")
      ->required();
  sub->add_option("--frames", a.frames, "frames a:b of the file (its own numbering, inclusive) or one frame; default all");
  sub->add_option("--every", a.every, "write every n-th mesh (default 1; all frames are still tracked)")->check(CLI::PositiveNumber);
  sub->add_option("--tets", a.o.tets, "tetrahedra of the control mesh (default 5000; 0 = full resolution)");
  sub->add_option("--iterations", a.o.iterations, "deformer iterations per frame, warm-started (default 3)");
  sub->add_option("--start-iterations", a.o.start_iterations, "iterations for the first frame of a set of present markers (default 40)");
  sub->add_flag("--no-align", a.no_align, "the template is already posed in the markers' frame and units (no similarity alignment)");
  sub->add_option("--contact-sheet", a.sheet, "frames in contact_sheet.png (default 8; 0 = none)")->check(CLI::NonNegativeNumber);
  sub->add_flag("--no-meshes", a.no_meshes, "track and report only, write no mesh files");
  sub->add_flag("-q,--quiet", a.quiet, "no progress bar");
}

std::pair<int, int> parse_range(const std::string& s, const MarkerTrajectories& m) {
  const int lo = m.first_frame, hi = m.first_frame + m.numFrames() - 1;
  if (s.empty()) return {lo, hi};
  std::istringstream is(s);
  int a = 0, b = 0;
  char c = 0;
  if (!(is >> a)) throw InvalidInput("--frames '" + s + "': expected a or a:b (frame numbers of the file)");
  b = a;
  if (is >> c) {
    if (c != ':' || !(is >> b)) throw InvalidInput("--frames '" + s + "': expected a or a:b (frame numbers of the file)");
  }
  if (a > b || a < lo || b > hi)
    throw InvalidInput("--frames " + s + " is outside the file's frames " + std::to_string(lo) + ".." + std::to_string(hi));
  return {a, b};
}

// The markers' up axis is the template's +y after the alignment; the contact sheet turns it to +y.
TriMesh y_up(const TriMesh& m, const Eigen::Matrix4d& alignment) {
  const Eigen::Vector3d up = alignment.block<3, 3>(0, 0) * Eigen::Vector3d::UnitY();
  const Eigen::Matrix3d R = Eigen::Quaterniond::FromTwoVectors(up.normalized(), Eigen::Vector3d::UnitY()).toRotationMatrix();
  TriMesh r = m;
  r.V = m.V * R.transpose();
  return r;
}

int cmd_animate(const AnimateArgs& a) {
  const MarkerTrajectories mk = read_markers(a.markers);
  const auto [f0, f1] = parse_range(a.frames, mk);
  const TriMesh tmpl = read_mesh(a.mesh);
  const MarkerMap map = load_marker_map(a.map);
  std::vector<std::vector<int>> rigid;
  try {
    rigid = rigid_region_vertices(map, tmpl);
  } catch (const InvalidInput& e) {
    throw InvalidInput(a.map + ": " + e.what());
  }
  make_out_dir(a.out);

  MarkerAnimation anim;
  MarkerAnimationOptions o = a.o;
  o.align = !a.no_align;
  anim.setOptions(o);
  anim.setTemplate(tmpl);
  anim.setMarkerMap(map.markers);
  anim.setRigidRegions(rigid);
  anim.setMarkers(mk.names, mk.data.middleRows(f0 - mk.first_frame, f1 - f0 + 1));
  ProgressBar bar(!a.quiet);
  anim.setProgressCallback(bar.callback());
  try {
    anim.start();
  } catch (const InvalidInput& e) {
    throw InvalidInput(a.map + " / " + a.markers + ": " + e.what());
  }
  const int n = f1 - f0 + 1;
  const std::vector<int> sheet_frames = evenly_spread(a.sheet, n);
  std::vector<RenderPanel> panels;
  TriMesh m;
  int written = 0, i = 0;
  while (anim.next(m)) {
    const int frame = f0 + i;
    if (!a.no_meshes && i % a.every == 0) {
      char name[32];
      std::snprintf(name, sizeof name, "mesh_%04d.ply", frame);
      write_mesh((fs::path(a.out) / name).string(), m);
      ++written;
    }
    if (std::binary_search(sheet_frames.begin(), sheet_frames.end(), i))
      panels.emplace_back(y_up(m, anim.report().alignment), "frame " + std::to_string(frame));
    ++i;
  }
  bar.finish();
  const auto& r = anim.report();
  // Report: summary + per frame.
  std::vector<double> med;
  double worst = 0;
  int with_gaps = 0;
  nlohmann::json frames = nlohmann::json::array();
  for (const auto& fr : r.frames) {
    med.push_back(fr.median_residual);
    worst = std::max(worst, fr.max_residual);
    with_gaps += !fr.missing.empty();
    frames.push_back({{"frame", f0 + fr.frame}, {"markers_used", fr.markers_used}, {"missing", fr.missing},
                      {"median_residual", fr.median_residual}, {"max_residual", fr.max_residual}, {"rebuilt", fr.rebuilt},
                      {"seconds_deform", fr.seconds_deform}, {"seconds_transfer", fr.seconds_transfer}});
  }
  std::vector<double> sorted = med;
  std::sort(sorted.begin(), sorted.end());
  nlohmann::json rep;
  rep["markers"] = a.markers;
  rep["template"] = a.mesh;
  rep["map"] = a.map;
  rep["units"] = mk.units;
  rep["frames"] = n;
  rep["meshes_written"] = written;
  rep["alignment"] = {{"frame", f0 + r.alignment_frame}, {"scale", r.scale}, {"rms", r.alignment_rms}};
  rep["control_mesh"] = {{"tet_vertices", r.tet_vertices}, {"tets", r.tets}, {"shell_tets", r.shell_tets}};
  if (r.shell_tets) rep["control_mesh"]["tetrahedralize_error"] = r.tetrahedralize_error;
  rep["deformers_built"] = r.deformers_built;
  rep["rigid_region_tets"] = r.rigid_region_tets;
  rep["frames_with_gaps"] = with_gaps;
  rep["median_of_frame_median_residuals"] = sorted.empty() ? 0.0 : sorted[sorted.size() / 2];
  rep["max_residual"] = worst;
  rep["seconds_setup"] = r.seconds_setup;
  rep["per_frame"] = frames;
  write_text_file_atomic((fs::path(a.out) / "animate_report.json").string(), rep.dump(1) + "\n");
  if (!panels.empty()) {
    RenderOptions ro;
    ro.panel_width = ro.panel_height = 320;
    ro.azimuth_deg = 30;
    ro.elevation_deg = 10;
    ro.shared_frame = false;  // the performer moves across the capture volume
    render_panels_png((fs::path(a.out) / "contact_sheet.png").string(), panels, ro);
  }
  if (!a.quiet)
    std::cout << "animate: " << n << " frames (" << with_gaps << " with gaps), median marker residual "
              << (sorted.empty() ? 0.0 : sorted[sorted.size() / 2]) << " " << mk.units << ", max " << worst << "; " << written
              << " meshes in " << a.out << "\n";
  return 0;
}

}  // namespace

void add_animate_commands(CLI::App& app, CommandTable& table) { register_command<AnimateArgs>(app, table, add_animate, cmd_animate); }

}  // namespace tbsp::cli
