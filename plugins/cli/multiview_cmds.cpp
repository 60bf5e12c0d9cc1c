// Multi-view commands: `tbsp stereo` (fusion of a studio's frames: fused cloud, depth PNGs, a
// PNG render, report JSON; or the disparity of one rectified pair), `tbsp refine-stereo`
// (model-guided stereo refinement of posed meshes) and `tbsp refine-silhouette` (silhouette
// refinement). docs/stereo.md, docs/silhouette_refinement.md.
#include "command.h"

#include <cmath>
#include <filesystem>
#include <functional>
#include <iostream>
#include <sstream>

#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <pcl/common/io.h>
#include <pcl/conversions.h>

#include "progress_bar.h"
#include "studio_frames.h"
#include "tbsp/core/error.h"
#include "tbsp/core/timer.h"
#include "tbsp/io/atomic_file.h"
#include "tbsp/io/camera_io.h"
#include "tbsp/io/cloud_io.h"
#include "tbsp/io/mesh_io.h"
#include "tbsp/io/studio.h"
#include "tbsp/mesh/point_mesh_distance.h"
#include "tbsp/multiview/marker_animation.h"
#include "tbsp/multiview/model_guided_stereo.h"
#include "tbsp/multiview/silhouette_refinement.h"
#include "tbsp/multiview/stereo_depth_fusion.h"
#include "tbsp/plugins/marker_map_json.h"
#include "tbsp/plugins/preview_render.h"

namespace fs = std::filesystem;

namespace tbsp::cli {

namespace {

struct StereoArgs {
  std::string studio, out, frames, format = "ply";
  std::string left, right, calib, gt;
  double gt_scale = 1.0;
  int disparities = 0, min_disparity = 0;
  StereoFusionOptions o;
  bool no_silhouettes = false, no_render = false, quiet = false;
  double depth_unit = 1e-4;
};

void add_stereo(CLI::App& app, StereoArgs& a, CLI::App*& sub) {
  sub = app.add_subcommand("stereo", "multi-view stereo: fused cloud per studio frame, or the disparity of one rectified pair (docs/stereo.md)");
  sub->add_option("studio", a.studio, "studio.yaml (or its folder): fuse every frame's calibrated views");
  sub->add_option("--out", a.out, "output folder (created)")->required();
  sub->add_option("--frames", a.frames, "studio frames a:b (inclusive) or a single frame; default all");
  sub->add_option("--format", a.format, "cloud format: ply (default) or pcd")->check(CLI::IsMember({"ply", "pcd"}));
  sub->add_option("--scale", a.o.image_scale, "matching resolution relative to the images, (0, 1] (default 0.5)");
  sub->add_option("--partners", a.o.partners, "partner views per view (default 2)");
  sub->add_option("--min-agree", a.o.min_agreeing_views, "cameras of other pairs that must confirm a depth (default 1)");
  sub->add_option("--near", a.o.near, "nearest depth, world units (with --far; default: automatic)");
  sub->add_option("--far", a.o.far, "farthest depth, world units");
  sub->add_flag("--no-silhouettes", a.no_silhouettes, "ignore the studio's silhouettes");
  sub->add_option("--depth-unit", a.depth_unit, "world units per count of the 16-bit depth PNGs (default 1e-4: 0.1 mm for metres)");
  sub->add_flag("--no-render", a.no_render, "do not write the PNG render of each cloud");
  sub->add_option("--left", a.left, "rectified pair: left image");
  sub->add_option("--right", a.right, "rectified pair: right image");
  sub->add_option("--calib", a.calib, "rectified pair: Middlebury 2014 calib.txt (adds cloud.ply)");
  sub->add_option("--disparities", a.disparities, "rectified pair: disparities searched, multiple of 16 (default: calib ndisp or 64)");
  sub->add_option("--min-disparity", a.min_disparity, "rectified pair: smallest disparity (default 0)");
  sub->add_option("--gt", a.gt, "rectified pair: ground-truth disparity image (0 = unknown) to evaluate against");
  sub->add_option("--gt-scale", a.gt_scale, "ground truth: stored value per pixel of disparity (default 1)");
  sub->add_flag("-q,--quiet", a.quiet, "no progress bar");
}


// A float map as a 16-bit PNG image: value = round(v * factor) clamped to 65535; NaN and v <= 0 -> 0.
cv::Mat to_u16(const cv::Mat& f, double factor) {
  cv::Mat u(f.size(), CV_16U);
  for (int y = 0; y < f.rows; ++y)
    for (int x = 0; x < f.cols; ++x) {
      const float v = f.at<float>(y, x);
      u.at<std::uint16_t>(y, x) = std::isnan(v) || v <= 0 ? 0 : static_cast<std::uint16_t>(std::min(65535L, std::lround(v * factor)));
    }
  return u;
}

// A cloud with a "confidence" float field after the XYZRGBNormal fields.
void write_cloud_with_confidence(const std::string& path, const pcl::PointCloud<pcl::PointXYZRGBNormal>& c, const std::vector<float>& conf) {
  pcl::PCLPointCloud2 a, b, out;
  pcl::toPCLPointCloud2(c, a);
  pcl::PointCloud<pcl::Intensity> ci;
  ci.resize(conf.size());
  for (std::size_t i = 0; i < conf.size(); ++i) ci[i].intensity = conf[i];
  ci.width = static_cast<std::uint32_t>(conf.size());
  ci.height = 1;
  pcl::toPCLPointCloud2(ci, b);
  for (auto& f : b.fields)
    if (f.name == "intensity") f.name = "confidence";
  pcl::concatenateFields(a, b, out);
  write_cloud(path, out, true);
}

cv::Mat colour_disparity(const cv::Mat& d, double lo, double hi) {
  cv::Mat u8(d.size(), CV_8U, cv::Scalar(0));
  for (int y = 0; y < d.rows; ++y)
    for (int x = 0; x < d.cols; ++x) {
      const float v = d.at<float>(y, x);
      if (!std::isnan(v)) u8.at<std::uint8_t>(y, x) = static_cast<std::uint8_t>(std::clamp(1 + 254 * (v - lo) / std::max(1e-9, hi - lo), 1.0, 255.0));
    }
  cv::Mat c;
  cv::applyColorMap(u8, c, cv::COLORMAP_TURBO);
  c.setTo(cv::Scalar(0, 0, 0), u8 == 0);
  return c;
}

int run_pair(const StereoArgs& a) {
  const cv::Mat L = cv::imread(a.left, cv::IMREAD_COLOR), R = cv::imread(a.right, cv::IMREAD_COLOR);
  if (L.empty()) throw FileError("'" + a.left + "': cannot read the left image (missing or not an image)");
  if (R.empty()) throw FileError("'" + a.right + "': cannot read the right image (missing or not an image)");
  RectifiedPairCalibration calib;
  if (!a.calib.empty()) {
    calib = read_middlebury_stereo_calib(a.calib);
    if ((calib.width > 0 && calib.width != L.cols) || (calib.height > 0 && calib.height != L.rows))
      throw InvalidInput("'" + a.calib + "' is for " + std::to_string(calib.width) + "x" + std::to_string(calib.height) + " images but '" +
                         a.left + "' is " + std::to_string(L.cols) + "x" + std::to_string(L.rows) + ": use the calibration of these images");
  }
  StereoMatchOptions mo;
  mo.min_disparity = a.min_disparity;
  mo.num_disparities = a.disparities > 0 ? a.disparities : (calib.ndisp > 0 ? ((calib.ndisp + 15) / 16) * 16 : 64);
  mo.fill_invalid = true;
  std::string why;
  if (!mo.isValid(&why)) throw InvalidInput("stereo: " + why);
  const DisparityMap d = compute_disparity(L, R, mo);
  fs::create_directories(a.out);
  const fs::path out(a.out);
  write_png((out / "disparity.png").string(), to_u16(d.disparity, 256.0));  // KITTI convention: disparity * 256, 0 = none
  write_png((out / "disparity_color.png").string(), colour_disparity(d.disparity, mo.min_disparity, mo.min_disparity + mo.num_disparities));
  nlohmann::json rep = {{"left", a.left}, {"right", a.right}, {"width", L.cols}, {"height", L.rows},
                        {"min_disparity", mo.min_disparity}, {"num_disparities", mo.num_disparities},
                        {"matched_pixels", d.matched_pixels}, {"consistent_pixels", d.consistent_pixels}, {"seconds", d.seconds},
                        {"disparity_png", "disparity.png: 16-bit, disparity * 256, 0 = none"}};
  std::cout << "disparity: " << L.cols << "x" << L.rows << ", " << mo.num_disparities << " disparities from " << mo.min_disparity << "; "
            << 100.0 * d.consistent_pixels / d.pixels << " % matched and left-right consistent; " << d.seconds << " s\n";
  if (!a.gt.empty()) {
    const cv::Mat G = cv::imread(a.gt, cv::IMREAD_ANYDEPTH | cv::IMREAD_GRAYSCALE);
    if (G.empty()) throw FileError("'" + a.gt + "': cannot read the ground-truth disparity image");
    if (G.size() != L.size())
      throw InvalidInput("'" + a.gt + "' is " + std::to_string(G.cols) + "x" + std::to_string(G.rows) + ", the images " + std::to_string(L.cols) + "x" +
                         std::to_string(L.rows) + ": give the ground truth of this pair");
    const double bad = bad_pixel_rate(d.disparity, G, a.gt_scale);
    rep["bad_pixels_1px_percent"] = bad;
    std::cout << "bad pixels (> 1 px) against " << a.gt << ": " << bad << " %\n";
  }
  if (!a.calib.empty()) {
    pcl::PointCloud<pcl::PointXYZRGB> cloud;
    for (int y = 0; y < L.rows; ++y)
      for (int x = 0; x < L.cols; ++x) {
        if (!d.matched.at<std::uint8_t>(y, x)) continue;  // only checked matches
        const double disp = d.disparity.at<float>(y, x) + calib.doffs;
        if (!(disp > 0)) continue;
        const double Z = calib.baseline * calib.f / disp;
        pcl::PointXYZRGB p;
        p.x = static_cast<float>((x - calib.cx0) * Z / calib.f);
        p.y = static_cast<float>((y - calib.cy) * Z / calib.f);
        p.z = static_cast<float>(Z);
        const cv::Vec3b c = L.at<cv::Vec3b>(y, x);
        p.b = c[0];
        p.g = c[1];
        p.r = c[2];
        cloud.push_back(p);
      }
    if (cloud.empty())  // (an empty cloud made the writer fail with "cannot write")
      throw InvalidInput("'" + a.left + "' / '" + a.right + "': no matched pixel has a positive disparity + doffs (" +
                         std::to_string(calib.doffs) + "), so no point has a finite depth and no cloud is written: the images show "
                         "no parallax (the same image twice? left and right swapped?)");
    pcl::PCLPointCloud2 b;
    pcl::toPCLPointCloud2(cloud, b);
    const std::string cp = (out / ("cloud." + a.format)).string();
    write_cloud(cp, b, true);
    rep["points"] = cloud.size();
    std::cout << "cloud: " << cloud.size() << " points -> " << cp << "\n";
  }
  write_text_file_atomic((out / "stereo_report.json").string(), rep.dump(2) + "\n");
  return 0;
}



int run_studio(const StereoArgs& a) {
  const Studio st = read_studio(a.studio);
  const auto [first, last] = parse_frames(a.frames, st);
  StereoFusionOptions o = a.o;
  o.use_silhouettes = !a.no_silhouettes;
  StereoDepthFusion<pcl::PointXYZRGBNormal> fusion;
  fusion.setOptions(o);
  if (!(a.depth_unit > 0)) throw InvalidInput("--depth-unit must be > 0");
  const fs::path out(a.out);
  fs::create_directories(out / "depth");
  const std::vector<Camera> cams = st.cameraList();
  nlohmann::json frames = nlohmann::json::array();
  const auto t0 = Clock::now();
  const int done = for_each_frame(st, first, last, !a.no_silhouettes, a.quiet, [&](const StudioFrame& fr, const ProgressCallback& progress, ProgressBar& bar) {
    fusion.setProgressCallback(progress);
    std::vector<cv::Mat> sil = a.no_silhouettes ? std::vector<cv::Mat>{} : fr.silhouettes;
    bool any = false;
    for (const auto& m : sil) any = any || !m.empty();
    if (!any) sil.clear();
    fusion.setInputFrame(cams, fr.images, sil, fr.frame);
    pcl::PointCloud<pcl::PointXYZRGBNormal> cloud;
    fusion.compute(cloud);
    const auto& r = fusion.report();
    const std::string id = expand_frame_pattern("%04d", fr.frame);
    write_cloud_with_confidence((out / ("cloud_" + id + "." + a.format)).string(), cloud, fusion.getConfidence());
    for (const ViewDepth& v : fusion.getDepthMaps())
      write_png((out / "depth" / (cams[v.camera].name() + "_" + cams[v.partner].name() + "_" + id + ".png")).string(),
                to_u16(v.depth, 1.0 / a.depth_unit));
    nlohmann::json fj = {{"frame", fr.frame}, {"pairs", r.pair_names}, {"skipped_pairs", r.skipped_pairs},
                         {"points", {{"depth", r.depth_points}, {"consistent", r.consistent_points}, {"fused", r.fused_points}, {"output", r.output_points}}},
                         {"seconds", {{"rectify", r.seconds_rectify}, {"match", r.seconds_match}, {"fusion", r.seconds_fusion},
                                      {"outliers", r.seconds_outliers}, {"total", r.seconds_total}}}};
    // Render: colour, and the error against the ground truth when the studio has one.
    if (!a.no_render && !cloud.empty()) {
      std::vector<RenderPanel> panels(1);
      panels[0].title = "frame " + std::to_string(fr.frame) + ": " + std::to_string(cloud.size()) + " points";
      panels[0].points.resize(static_cast<Eigen::Index>(cloud.size()), 3);
      panels[0].point_colors.resize(static_cast<Eigen::Index>(cloud.size()), 3);
      for (std::size_t i = 0; i < cloud.size(); ++i) {
        panels[0].points.row(static_cast<Eigen::Index>(i)) << cloud[i].x, cloud[i].y, cloud[i].z;
        panels[0].point_colors.row(static_cast<Eigen::Index>(i)) << cloud[i].r / 255.0, cloud[i].g / 255.0, cloud[i].b / 255.0;
      }
      if (!st.ground_truth.empty() && fs::exists(st.groundTruthPath(fr.frame))) {
        const TriMesh gt = read_mesh(st.groundTruthPath(fr.frame));
        const double diag = (gt.V.colwise().maxCoeff() - gt.V.colwise().minCoeff()).norm();
        const Eigen::VectorXd dist = point_mesh_distances(gt.V, gt.F, panels[0].points) / diag * 100.0;
        RenderPanel e;
        e.title = "distance to ground truth";
        e.points = panels[0].points;
        e.point_colors = colormap(dist, 0.0, 1.0);
        e.colorbar = true;
        e.colorbar_lo = 0;
        e.colorbar_hi = 1.0;
        e.colorbar_label = "% of diagonal";
        panels.push_back(e);
        std::vector<double> v(dist.data(), dist.data() + dist.size());
        std::nth_element(v.begin(), v.begin() + v.size() * 9 / 10, v.end());
        fj["accuracy90_percent_of_diagonal"] = v[v.size() * 9 / 10];
      }
      RenderOptions ro;
      ro.azimuth_deg = 20;
      ro.elevation_deg = 10;
      render_panels_png((out / ("cloud_" + id + ".png")).string(), panels, ro);
    }
    frames.push_back(fj);
    if (a.quiet) return;
    bar.finish();
    std::cout << "frame " << fr.frame << ": " << r.pairs << " pairs, " << r.output_points << " points ("
              << r.depth_points << " depths, " << r.consistent_points << " confirmed), " << r.seconds_total << " s"
              << (fj.contains("accuracy90_percent_of_diagonal") ? ", 90 % within " + std::to_string(fj["accuracy90_percent_of_diagonal"].get<double>()) + " % of the diagonal" : "")
              << "\n";
    for (const auto& sk : r.skipped_pairs) std::cout << "  skipped " << sk << "\n";
  });
  nlohmann::json rep = {{"studio", a.studio}, {"frames", frames}, {"seconds", seconds_since(t0)}, {"depth_png_unit", a.depth_unit},
                        {"options", {{"image_scale", o.image_scale}, {"partners", o.partners}, {"min_agreeing_views", o.min_agreeing_views},
                                     {"depth_tolerance", o.depth_tolerance}, {"use_silhouettes", o.use_silhouettes}}}};
  write_text_file_atomic((out / "stereo_report.json").string(), rep.dump(2) + "\n");
  if (!a.quiet) std::cout << done << " frames in " << seconds_since(t0) << " s -> " << a.out << "\n";
  return 0;
}

int cmd_stereo(const StereoArgs& a) {
  const bool pair = !a.left.empty() || !a.right.empty();
  if (pair && !a.studio.empty()) throw InvalidInput("stereo: give either a studio or --left/--right, not both");
  if (pair) {
    if (a.left.empty() || a.right.empty()) throw InvalidInput("stereo: a rectified pair needs both --left and --right");
    return run_pair(a);
  }
  if (a.studio.empty()) throw InvalidInput("stereo: give a studio.yaml, or --left L --right R for a rectified pair");
  return run_studio(a);
}

std::string mesh_pattern(const std::string& meshes, int first, int last);

struct RefineStereoArgs {
  std::string studio, meshes, out, frames;
  ModelGuidedStereoOptions o;
  bool no_silhouettes = false, quiet = false;
};

void add_refine_stereo(CLI::App& app, RefineStereoArgs& a, CLI::App*& sub) {
  sub = app.add_subcommand("refine-stereo", "refine posed meshes by model-guided multi-view stereo (thesis §6.3.3, docs/stereo.md)");
  sub->add_option("studio", a.studio, "studio.yaml (or its folder)")->required();
  sub->add_option("--meshes", a.meshes, "posed mesh per frame: a pattern with %d / %04d, or a folder holding FFFF.ply")->required();
  sub->add_option("--out", a.out, "output folder: refined_FFFF.ply + refine_report.json")->required();
  sub->add_option("--frames", a.frames, "frames a:b (inclusive) or one frame; default all");
  sub->add_option("--range", a.o.search_range, "± search along each ray, world units (default 0.02)");
  sub->add_option("--weight", a.o.constraint_weight, "weight of the stereo constraints (default 0.3)");
  sub->add_option("--scale", a.o.image_scale, "matching resolution relative to the images (default 0.5)");
  sub->add_option("--stride", a.o.pixel_stride, "search every n-th pixel (default 2)");
  sub->add_option("--detail-rounds", a.o.detail_rounds, "detail rounds after the fit, 0..10 (default 1; they bring back folds)");
  sub->add_option("--normal-tilt", a.o.normal_tilt_deg, "patch orientations tried around the mesh normal, degrees (default 20; 0 = mesh normal only)");
  sub->add_flag("--no-silhouettes", a.no_silhouettes, "ignore the studio's silhouettes");
  sub->add_flag("-q,--quiet", a.quiet, "no progress bar");
}

int cmd_refine_stereo(const RefineStereoArgs& a) {
  const Studio st = read_studio(a.studio);
  const auto [first, last] = parse_frames(a.frames, st);
  ModelGuidedStereoOptions o = a.o;
  o.use_silhouettes = !a.no_silhouettes;
  ModelGuidedStereo mvs;
  mvs.setOptions(o);
  const std::string pattern = mesh_pattern(a.meshes, first, last);
  fs::create_directories(a.out);
  nlohmann::json frames = nlohmann::json::array();
  const auto t0 = Clock::now();
  for_each_frame(st, first, last, !a.no_silhouettes, a.quiet, [&](const StudioFrame& fr, const ProgressCallback& progress, ProgressBar& bar) {
    mvs.setProgressCallback(progress);
    mvs.setInputFrame(st.cameraList(), fr.images, a.no_silhouettes ? std::vector<cv::Mat>{} : fr.silhouettes, fr.frame);
    mvs.setInputMesh(read_mesh(expand_frame_pattern(pattern, fr.frame)));
    TriMesh refined;
    mvs.refine(refined);
    write_mesh((fs::path(a.out) / ("refined_" + expand_frame_pattern("%04d", fr.frame) + ".ply")).string(), refined);
    const auto& r = mvs.report();
    frames.push_back({{"frame", fr.frame}, {"samples", r.samples}, {"points", r.points}, {"points_per_view", r.points_per_view},
                      {"mean_ncc", r.mean_score}, {"mean_vertex_move", r.mean_vertex_move}, {"max_vertex_move", r.max_vertex_move},
                      {"seconds", {{"stereo", r.seconds_stereo}, {"fit", r.seconds_fit}, {"total", r.seconds_total}}}});
    if (a.quiet) return;
    bar.finish();
    std::cout << "frame " << fr.frame << ": " << r.points << " stereo points of " << r.samples << " searched pixels, mean move "
              << r.mean_vertex_move << ", " << r.seconds_total << " s\n";
  });
  write_text_file_atomic((fs::path(a.out) / "refine_report.json").string(),
                         nlohmann::json({{"studio", a.studio}, {"frames", frames}, {"seconds", seconds_since(t0)}}).dump(2) + "\n");
  return 0;
}

// Posed meshes per frame: a pattern with %d / %04d, or a folder holding FFFF.ply; every frame's
// mesh is checked before anything runs.
std::string mesh_pattern(const std::string& meshes, int first, int last) {
  std::string pattern = meshes;
  if (fs::is_directory(pattern)) pattern = (fs::path(pattern) / "%04d.ply").string();
  for (int f = first; f <= last; ++f)
    if (!fs::exists(expand_frame_pattern(pattern, f)))
      throw FileError("'" + expand_frame_pattern(pattern, f) + "': no posed mesh for frame " + std::to_string(f) + " (--meshes " + meshes + ")");
  return pattern;
}

struct RefineSilhouetteArgs {
  std::string studio, meshes, out, frames, tmpl, pose;
  SilhouetteRefinementOptions o;
  Eigen::Index tets = 5000;
  bool quiet = false, overlays = false;
};

void add_refine_silhouette(CLI::App& app, RefineSilhouetteArgs& a, CLI::App*& sub) {
  sub = app.add_subcommand("refine-silhouette", "refine posed meshes to the studio's silhouettes (thesis §6.3.1-2, docs/silhouette_refinement.md)");
  sub->add_option("studio", a.studio, "studio.yaml (or its folder) with silhouettes")->required();
  auto* meshes = sub->add_option("--meshes", a.meshes, "posed mesh per frame: a pattern with %d / %04d, or a folder holding FFFF.ply");
  auto* pose = sub->add_option("--pose", a.pose,
                               "instead of --meshes: pose --template by the hand-placed markers of this JSON (marker map with \"pixels\" per "
                               "camera, triangulated; one frame), then refine (docs/silhouette_refinement.md)");
  sub->add_option("--template", a.tmpl, "template mesh for --pose (default: the studio's template)")->needs(pose);
  sub->add_option("--tets", a.tets, "control tetrahedra of the --pose deformation (default 5000)")->needs(pose)->check(CLI::Range(100, 1000000));
  meshes->excludes(pose);
  sub->add_option("--out", a.out, "output folder: refined_FFFF.ply + silhouette_report.json (+ posed_FFFF.ply with --pose)")->required();
  sub->add_flag("--overlays", a.overlays, "write overlay_FFFF_before.png / _after.png: the mesh on every view (green: agrees with the silhouette, "
                                          "blue: mesh only, red: silhouette only)");
  sub->add_option("--frames", a.frames, "frames a:b (inclusive) or one frame; default all");
  sub->add_flag("--lines", a.o.line_constraints, "line constraints (§6.3.2) instead of back-projected points (§6.3.1)");
  sub->add_option("--weight", a.o.weight, "constraint weight (default 0.35; thesis 0.25-0.5)");
  sub->add_option("--iterations", a.o.max_iterations, "at most this many iterations (default 20)");
  sub->add_option("--max-distance", a.o.max_distance_px, "ε: farthest contour point used, pixels (default 20)");
  sub->add_flag("-q,--quiet", a.quiet, "no progress bar");
}

// --pose: the template posed by triangulated hand-placed markers (MarkerAnimation, one frame).
struct PosedTemplate {
  TriMesh mesh;
  nlohmann::json report;
};
PosedTemplate pose_template(const RefineSilhouetteArgs& a, const Studio& st) {
  const std::string tpath = a.tmpl.empty() ? (st.template_mesh.empty() ? "" : st.resolve(st.template_mesh)) : a.tmpl;
  if (tpath.empty()) throw InvalidInput("--pose needs a template: give --template T (the studio " + a.studio + " names none)");
  const TriMesh tmpl = read_mesh(tpath);
  const MarkerMap map = load_marker_map(a.pose);
  if (map.image_markers.size() < 3)
    throw FileError(a.pose + ": " + std::to_string(map.image_markers.size()) +
                    " markers have \"pixels\": --pose needs at least 3 markers placed in the images (\"pixels\": {\"CAMERA\": [x, y], ...})");
  MarkerAnimationOptions mo;
  mo.tets = a.tets;
  PosedTemplate out;
  ImagePoseReport pr;
  try {
    out.mesh = pose_template_to_image_markers(tmpl, map.markers, map.image_markers, st.cameraList(), mo, rigid_region_vertices(map, tmpl), &pr);
  } catch (const InvalidInput& e) {
    throw FileError(a.pose + ": " + e.what());
  }
  const auto& tri = pr.markers;
  const auto& r = pr.animation;
  nlohmann::json mk = nlohmann::json::array();
  for (const auto& t : tri)
    mk.push_back({{"marker", t.marker}, {"views", t.views}, {"rms_px", t.rms_px}, {"position", {t.position.x(), t.position.y(), t.position.z()}}});
  out.report = {{"template", tpath},
                {"markers", mk},
                {"alignment_scale", r.scale},
                {"alignment_rms", r.alignment_rms},
                {"tets", r.tets},
                {"median_residual", r.frames.front().median_residual},
                {"max_residual", r.frames.front().max_residual},
                {"seconds", r.seconds_setup + r.frames.front().seconds_deform + r.frames.front().seconds_transfer}};
  return out;
}

int cmd_refine_silhouette(const RefineSilhouetteArgs& a) {
  const Studio st = read_studio(a.studio);
  auto [first, last] = parse_frames(a.frames, st);
  for (const auto& c : st.cameras)
    if (c.silhouettes.empty())
      throw InvalidInput("camera '" + c.camera.name() + "' of " + a.studio + " has no silhouettes: silhouette refinement needs them for every camera");
  if (a.meshes.empty() && a.pose.empty()) throw InvalidInput("give the posed meshes (--meshes) or a template and its hand-placed markers (--pose)");
  if (!a.pose.empty() && first != last) {
    if (!a.frames.empty()) throw InvalidInput("--pose places markers in one frame: give --frames with one frame (not " + a.frames + ")");
    last = first;
  }
  SilhouetteRefinement sr;
  sr.setOptions(a.o);
  PosedTemplate posed;
  if (!a.pose.empty()) posed = pose_template(a, st);
  const std::string pattern = a.pose.empty() ? mesh_pattern(a.meshes, first, last) : "";
  fs::create_directories(a.out);
  if (!a.pose.empty()) write_mesh((fs::path(a.out) / ("posed_" + expand_frame_pattern("%04d", first) + ".ply")).string(), posed.mesh);
  nlohmann::json frames = nlohmann::json::array();
  const auto t0 = Clock::now();
  for_each_frame(st, first, last, true, a.quiet, [&](const StudioFrame& fr, const ProgressCallback& progress, ProgressBar& bar) {
    sr.setProgressCallback(progress);
    sr.setInputFrame(st.cameraList(), fr.silhouettes, fr.frame);
    const TriMesh input = a.pose.empty() ? read_mesh(expand_frame_pattern(pattern, fr.frame)) : posed.mesh;
    sr.setInputMesh(input);
    TriMesh refined;
    sr.refine(refined);
    const std::string ff = expand_frame_pattern("%04d", fr.frame);
    write_mesh((fs::path(a.out) / ("refined_" + ff + ".ply")).string(), refined);
    if (a.overlays) {
      write_png((fs::path(a.out) / ("overlay_" + ff + "_before.png")).string(), overlay_grid(input, st.cameraList(), fr));
      write_png((fs::path(a.out) / ("overlay_" + ff + "_after.png")).string(), overlay_grid(refined, st.cameraList(), fr));
    }
    const auto& r = sr.report();
    nlohmann::json views = nlohmann::json::array();
    for (const auto& v : r.views)
      views.push_back({{"camera", v.camera}, {"iou_before", v.iou_before}, {"iou_after", v.iou_after}, {"xor_before", v.xor_before},
                       {"xor_after", v.xor_after}, {"constraints", v.constraints}});
    frames.push_back({{"frame", fr.frame}, {"iterations", r.iterations}, {"best_iteration", r.best_iteration}, {"xor_before", r.xor_before},
                      {"xor_after", r.xor_after}, {"views", views}, {"seconds", r.seconds}});
    if (a.quiet) return;
    bar.finish();
    std::cout << "frame " << fr.frame << ": silhouette mismatch " << r.xor_before << " -> " << r.xor_after << " pixels in " << r.iterations
              << " iterations, " << r.seconds << " s\n";
  });
  nlohmann::json report = {{"studio", a.studio}, {"frames", frames}, {"seconds", seconds_since(t0)}};
  if (!a.pose.empty()) report["pose"] = posed.report;
  write_text_file_atomic((fs::path(a.out) / "silhouette_report.json").string(), report.dump(2) + "\n");
  return 0;
}

}  // namespace

void add_stereo_commands(CLI::App& app, CommandTable& table) {
  register_command<StereoArgs>(app, table, add_stereo, cmd_stereo);
  register_command<RefineStereoArgs>(app, table, add_refine_stereo, cmd_refine_stereo);
  register_command<RefineSilhouetteArgs>(app, table, add_refine_silhouette, cmd_refine_silhouette);
}

}  // namespace tbsp::cli
