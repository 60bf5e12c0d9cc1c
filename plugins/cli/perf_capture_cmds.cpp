// `tbsp capture`: performance capture from a multi-view studio (thesis §9.2) through
// tbsp::PerformanceCapture: a mesh per frame, a report and PNG overlays (docs/performance_capture.md).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <nlohmann/json.hpp>

#include <opencv2/imgproc.hpp>
#include <pcl/PCLPointCloud2.h>
#include <pcl/conversions.h>
#include <pcl/point_types.h>

#include "command.h"
#include "progress_bar.h"
#include "studio_frames.h"
#include "tbsp/core/error.h"
#include "tbsp/core/timer.h"
#include "tbsp/io/atomic_file.h"
#include "tbsp/io/cloud_io.h"
#include "tbsp/io/mesh_io.h"
#include "tbsp/io/studio.h"
#include "tbsp/mesh/trajectory_smoother.h"
#include "tbsp/multiview/performance_capture.h"
#include "tbsp/multiview/rasterizer.h"
#include "tbsp/multiview/visual_hull.h"

namespace fs = std::filesystem;

namespace tbsp::cli {

namespace {

struct CaptureArgs {
  std::string studio, mesh, out, frames;
  PerformanceCaptureOptions o;
  int every = 1, overlays = 4;
  double smooth = 0;
  bool no_features = false, no_meshes = false, quiet = false, no_hull = false;
};

void add_capture(CLI::App& app, CaptureArgs& a, CLI::App*& sub) {
  sub = app.add_subcommand("capture", "track a template through a multi-view studio recording (thesis §9.2, docs/performance_capture.md)");
  sub->add_option("studio", a.studio, "studio.yaml (or its folder) with images and silhouettes for every camera")->required();
  sub->add_option("--template", a.mesh, "template surface mesh, posed like the performer in the first frame, in the studio's units")->required();
  sub->add_option("--out", a.out, "output folder: mesh_FFFF.ply, capture_report.json, overlay_FFFF.png")->required();
  sub->add_option("--frames", a.frames, "frames a:b (inclusive) or one frame; default all");
  sub->add_option("--every", a.every, "write every n-th mesh (default 1; every frame is still tracked)")->check(CLI::PositiveNumber);
  sub->add_option("--tets", a.o.tets, "tetrahedra of the control mesh (default 10000; 0 = the template as is)");
  sub->add_option("--handles", a.o.handles, "handle vertices on the control surface (default 150)");
  sub->add_option("--rounds", a.o.pose_rounds, "pose rounds per frame (default 3)");
  sub->add_flag("--no-features", a.no_features, "silhouettes only (no SIFT feature tracking)");
  sub->add_option("--keyframes", a.o.keyframe_interval,
                  "keyframe anchors: every N frames at most, a frame whose worst view IoU reaches --keyframe-iou adds its keypoints to "
                  "the first frame's anchors (for performers that turn away from the first frame's views; default 0 = off)")
      ->check(CLI::Range(0, 10000));
  sub->add_option("--keyframe-iou", a.o.keyframe_iou, "worst view IoU a keyframe needs (default 0.98)")->check(CLI::Range(0.0, 1.0));
  sub->add_flag("--optimize-handles", a.o.optimize_handles, "the thesis' black-box handle optimization (NLopt BOBYQA) after the pose step");
  sub->add_option("--refine-iterations", a.o.refine_iterations, "silhouette refinement iterations per frame (default 5; 0 = none)");
  sub->add_flag("--stereo", a.o.stereo_refine, "model-guided stereo after the silhouette refinement (§6.3.3: folds, concavities; ~1-2 s per frame)");
  sub->add_option("--stereo-range", a.o.stereo_search_range, "its search along each ray, +- world units (default 1 % of the template's diagonal)")
      ->check(CLI::NonNegativeNumber);
  sub->add_flag("--no-register-hull", a.no_hull,
                "take the template as posed (default: first register it to the first frame's visual hull by a similarity, applied "
                "when it raises the silhouette overlap: a template placed only roughly, within ~25 deg and ~15 % of size, starts in place)");
  sub->add_option("--hull-resolution", a.o.hull_resolution, "voxels along the longest side of the visual hull's box (default 128)")
      ->check(CLI::Range(16, 1024));
  sub->add_option("--failure-iou", a.o.failure_iou, "a frame whose worst view IoU is below this is reported as a tracking failure (default 0.85)");
  sub->add_option("--overlays", a.overlays, "frames with a PNG overlay of the mesh on the camera images (default 4; 0 = none)")
      ->check(CLI::NonNegativeNumber);
  sub->add_option("--smooth", a.smooth,
                  "temporal smoothing of the vertex trajectories: Gaussian sigma in frames (default 0 = none; meshes are written "
                  "ceil(3 sigma) frames late, overlays show the unsmoothed tracking)")
      ->check(CLI::Range(0.0, 50.0));
  sub->add_flag("--no-meshes", a.no_meshes, "track and report only, write no mesh files");
  sub->add_flag("-q,--quiet", a.quiet, "no progress bar");
}

nlohmann::json frame_json(const CaptureFrameReport& f) {
  return {{"frame", f.frame},
          {"iou", f.iou},
          {"iou_min", f.iou_min},
          {"iou_mean", f.iou_mean},
          {"iou_pose", f.iou_pose},
          {"failed", f.failed},
          {"retried", f.retried},
          {"keypoints", f.keypoints},
          {"temporal_matches", f.temporal_matches},
          {"anchor_matches", f.anchor_matches},
          {"keyframe", f.keyframe},
          {"feature_inliers", f.inliers},
          {"rim_constraints", f.rim_constraints},
          {"stereo_points", f.stereo_points},
          {"optimizer", {{"evaluations", f.evaluations}, {"iou_before", f.opt_iou_before}, {"iou_after", f.opt_iou_after}}},
          {"seconds", {{"features", f.t_features}, {"match", f.t_match}, {"pose", f.t_pose}, {"optimize", f.t_optimize},
                       {"transfer", f.t_transfer}, {"refine", f.t_refine}, {"stereo", f.t_stereo}, {"total", f.t_total}}}};
}

int cmd_capture(const CaptureArgs& a) {
  const Studio st = read_studio(a.studio);
  const auto [first, last] = parse_frames(a.frames, st);
  for (const auto& c : st.cameras) {
    if (c.silhouettes.empty())
      throw InvalidInput("camera '" + c.camera.name() + "' of " + a.studio + " has no silhouettes: performance capture needs them for every camera");
    if (!a.no_features && c.images.empty() && c.video.empty())
      throw InvalidInput("camera '" + c.camera.name() + "' of " + a.studio + " has no images: feature tracking needs them (or run with --no-features)");
  }
  const TriMesh tmpl = read_mesh(a.mesh);
  make_out_dir(a.out);
  PerformanceCaptureOptions o = a.o;
  o.features = !a.no_features;
  o.register_to_hull = !a.no_hull;
  PerformanceCapture pc;
  pc.setOptions(o);
  const std::vector<Camera> cams = st.cameraList();
  pc.setCameras(cams);
  pc.setTemplate(tmpl);
  const int n = last - first + 1;
  std::vector<int> overlay_frames;
  for (int k = 0; k < a.overlays && n > 0; ++k)
    overlay_frames.push_back(first + (a.overlays == 1 ? 0 : int(std::lround(double(k) * (n - 1) / (a.overlays - 1)))));
  overlay_frames.erase(std::unique(overlay_frames.begin(), overlay_frames.end()), overlay_frames.end());
  const auto t0 = Clock::now();
  int written = 0, done = 0;
  auto write_report = [&](const std::string& error) {
    const auto& r = pc.report();
    nlohmann::json frames = nlohmann::json::array();
    double worst = 1, mean = 0;
    for (const auto& f : r.frames) {
      frames.push_back(frame_json(f));
      worst = std::min(worst, f.iou_min);
      mean += f.iou_mean / double(r.frames.size());
    }
    nlohmann::json rep = {{"studio", a.studio},
                          {"template", a.mesh},
                          {"frames", done},
                          {"meshes_written", written},
                          {"smooth_sigma_frames", a.smooth},
                          {"failed_frames", r.failed_frames},
                          {"worst_view_iou", r.frames.empty() ? 0.0 : worst},
                          {"mean_iou", mean},
                          {"control_mesh",
                           {{"tets", r.tets}, {"tet_vertices", r.tet_vertices}, {"surface_vertices", r.control_surface_vertices},
                            {"handles", r.handles}, {"shell_tets", r.shell_tets}}},
                          {"seconds_setup", r.t_setup},
                          {"seconds", seconds_since(t0)},
                          {"per_frame", frames}};
    if (r.hull_tried) {
      const HullRegistration& h = r.hull;
      rep["hull_registration"] = {{"applied", r.hull_registered},
                                  {"message", r.hull_message},
                                  {"rotation_deg", h.icp.rotation_deg},
                                  {"scale", h.icp.scale},
                                  {"translation", {h.icp.translation.x(), h.icp.translation.y(), h.icp.translation.z()}},
                                  {"icp_iterations", h.icp.iterations},
                                  {"icp_rms", h.icp.rms},
                                  {"mean_iou_before", h.iou_before},
                                  {"mean_iou_after", h.iou_after},
                                  {"hull_samples", h.hull_points},
                                  {"voxel", h.voxel},
                                  {"seconds", h.seconds}};
    }
    if (!error.empty()) rep["error"] = error;
    write_text_file_atomic((fs::path(a.out) / "capture_report.json").string(), rep.dump(1) + "\n");
  };
  TrajectorySmoother smoother(a.smooth);
  auto write_frames = [&](const std::vector<TrajectorySmoother::Frame>& ready) {
    for (const auto& [frame, V] : ready) {
      if (a.no_meshes || (frame - first) % a.every != 0) continue;
      char name[32];
      std::snprintf(name, sizeof name, "mesh_%04d.ply", frame);
      TriMesh m;
      m.V = V;
      m.F = tmpl.F;
      write_mesh((fs::path(a.out) / name).string(), m);
      ++written;
    }
  };
  try {
    for_each_frame(st, first, last, true, a.quiet, [&](const StudioFrame& fr, const ProgressCallback& progress, ProgressBar&) {
      pc.setProgressCallback(progress);
      TriMesh m;
      pc.track(fr.images, fr.silhouettes, fr.frame, m);
      ++done;
      write_frames(smoother.push(fr.frame, m.V));
      if (std::binary_search(overlay_frames.begin(), overlay_frames.end(), fr.frame)) {
        char name[32];
        std::snprintf(name, sizeof name, "overlay_%04d.png", fr.frame);
        write_png((fs::path(a.out) / name).string(), overlay_grid(m, cams, fr));
      }
    });
  } catch (const Error& e) {
    write_frames(smoother.flush());  // what was tracked so far stays usable
    write_report(e.what());
    throw;
  }
  write_frames(smoother.flush());
  write_report("");
  const auto& r = pc.report();
  if (!a.quiet) {
    if (r.hull_tried && !r.hull_registered) std::cout << "visual hull: " << r.hull_message << "\n";
    if (r.hull_registered)
      std::cout << "visual hull: template turned by " << r.hull.icp.rotation_deg << " deg, scaled by " << r.hull.icp.scale << ", mean view IoU "
                << r.hull.iou_before << " -> " << r.hull.iou_after << "\n";
    double worst = 1;
    for (const auto& f : r.frames) worst = std::min(worst, f.iou_min);
    std::cout << "capture: " << done << " frames, worst view IoU " << worst << ", " << r.failed_frames << " tracking failure(s), "
              << seconds_since(t0) / std::max(1, done) << " s per frame; " << written << " meshes in " << a.out << "\n";
  }
  return 0;
}

struct HullArgs {
  std::string studio, out, frame, tmpl, registered;
  VisualHullOptions o;
  bool quiet = false;
};

void add_visual_hull(CLI::App& app, HullArgs& a, CLI::App*& sub) {
  sub = app.add_subcommand("visual-hull",
                           "carve the visual hull of one studio frame's silhouettes; optionally register a template to it (docs/performance_capture.md)");
  sub->add_option("studio", a.studio, "studio.yaml (or its folder) with silhouettes for every camera")->required();
  sub->add_option("--out", a.out, "hull surface samples with outward normals: a .ply or .pcd point cloud")->required();
  sub->add_option("--frame", a.frame, "the studio frame (default: the first)");
  sub->add_option("--resolution", a.o.resolution, "voxels along the longest side of the hull's box (default 128)")->check(CLI::Range(16, 1024));
  sub->add_option("--margin", a.o.margin_px, "dilate the silhouettes by this many pixels first (calibration error; default 0)")->check(CLI::Range(0, 50));
  auto* t = sub->add_option("--template", a.tmpl, "a template placed roughly like the performer: register it to the hull (similarity ICP)");
  sub->add_option("--registered", a.registered, "where to write the registered template (mesh file)")->needs(t);
  sub->add_flag("-q,--quiet", a.quiet, "no progress bar");
}

int cmd_visual_hull(const HullArgs& a) {
  const Studio st = read_studio(a.studio);
  // default: the studio's first frame (an empty --frame would otherwise mean all of them)
  const auto [first, last] = a.frame.empty() ? std::pair<int, int>(st.first_frame, st.first_frame) : parse_frames(a.frame, st, "--frame");
  if (first != last) throw InvalidInput("--frame takes one frame (not " + a.frame + ")");
  for (const auto& c : st.cameras)
    if (c.silhouettes.empty()) throw InvalidInput("camera '" + c.camera.name() + "' of " + a.studio + " has no silhouettes: the visual hull needs them for every camera");
  if (!a.tmpl.empty() && a.registered.empty()) throw InvalidInput("--template needs --registered OUT: where to write the registered template");
  const TriMesh tmpl = a.tmpl.empty() ? TriMesh{} : read_mesh(a.tmpl);
  const std::vector<Camera> cams = st.cameraList();
  for_each_frame(st, first, last, true, a.quiet, [&](const StudioFrame& fr, const ProgressCallback&, ProgressBar&) {
    const auto t0 = Clock::now();
    const VisualHull h = compute_visual_hull(cams, fr.silhouettes, a.o);
    pcl::PointCloud<pcl::PointNormal> cloud;
    for (Eigen::Index i = 0; i < h.points.rows(); ++i) {
      pcl::PointNormal p;
      p.getVector3fMap() = h.points.row(i).transpose().cast<float>();
      p.getNormalVector3fMap() = h.normals.row(i).transpose().cast<float>();
      cloud.push_back(p);
    }
    pcl::PCLPointCloud2 b;
    pcl::toPCLPointCloud2(cloud, b);
    write_cloud(a.out, b, true);
    std::cout << "visual hull of frame " << fr.frame << ": " << h.points.rows() << " surface samples, voxel " << h.voxel << ", volume " << h.volume()
              << ", " << seconds_since(t0) << " s -> " << a.out << "\n";
    if (!tmpl.V.size()) return;
    const HullRegistration r = register_to_visual_hull(tmpl, cams, fr.silhouettes, a.o);
    TriMesh m = tmpl;
    m.V = transform_points(r.icp.transform, tmpl.V);
    write_mesh(a.registered, m);
    std::cout << "registered template: turned by " << r.icp.rotation_deg << " deg, scaled by " << r.icp.scale << ", moved by "
              << r.icp.translation.norm() << "; mean view IoU " << r.iou_before << " -> " << r.iou_after << " -> " << a.registered << "\n";
  });
  return 0;
}

}  // namespace

void add_perf_capture_commands(CLI::App& app, CommandTable& table) {
  register_command<CaptureArgs>(app, table, add_capture, cmd_capture);
  register_command<HullArgs>(app, table, add_visual_hull, cmd_visual_hull);
}

}  // namespace tbsp::cli
