// `tbsp cloth synth` (ground-truth skirted mannequin driven by a BVH clip) and `tbsp cloth
// segment` (thesis §10.3 on a mesh sequence), plus the helpers of the cloth commands.
#include "cloth_cmds.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <nlohmann/json.hpp>

#include "progress_bar.h"
#include "tbsp/cloth/cloth_segmentation.h"
#include "tbsp/core/error.h"
#include "tbsp/io/atomic_file.h"
#include "tbsp/io/bvh_skeleton.h"
#include "tbsp/io/mesh_io.h"
#include "tbsp/plugins/cloth_model_json.h"
#include "tbsp/plugins/preview_render.h"
#include "tbsp/plugins/skirted_mannequin.h"
#include "tbsp/plugins/synth_studio.h"

namespace fs = std::filesystem;

namespace tbsp::cli {

std::vector<std::string> mesh_files_in(const std::string& dir) {
  std::error_code ec;
  if (!fs::is_directory(dir, ec)) throw FileError("'" + dir + "': not a folder (expected a folder of meshes, one per frame)");
  std::vector<std::string> files;
  for (const auto& e : fs::directory_iterator(dir, ec)) {
    const std::string ext = lower_ext(e.path().string());
    if (e.is_regular_file() && (ext == ".ply" || ext == ".obj" || ext == ".off")) files.push_back(e.path().string());
  }
  std::sort(files.begin(), files.end());
  if (files.empty()) throw FileError("'" + dir + "': no .ply, .obj or .off meshes in the folder");
  return files;
}

SkeletonPose pose_by_name(const Skeleton& skeleton, const BvhMotion& clip, int frame, double scale, const std::string& clip_name) {
  require_bvh_joints(clip, skeleton.names, clip_name);
  const SkeletonPose g = bvh_pose(clip, frame, scale);
  SkeletonPose pose(std::size_t(skeleton.numJoints()));
  for (int j = 0; j < skeleton.numJoints(); ++j)
    for (std::size_t k = 0; k < clip.joints.size(); ++k)
      if (clip.joints[k].name == skeleton.names[std::size_t(j)]) pose[std::size_t(j)] = g[k];
  return pose;
}

void write_contact_sheet(const std::string& path, const std::vector<TriMesh>& meshes, const std::vector<std::string>& titles) {
  std::vector<RenderPanel> panels;
  for (std::size_t i = 0; i < meshes.size(); ++i) panels.emplace_back(meshes[i], titles[i]);
  if (panels.empty()) return;
  RenderOptions ro;
  ro.panel_width = 280;
  ro.panel_height = 360;
  ro.azimuth_deg = 25;
  ro.elevation_deg = 10;
  ro.shared_frame = false;
  render_panels_png(path, panels, ro);
}

namespace {

// ---- tbsp cloth synth

struct SynthArgs {
  std::string bvh, out;
  synth::SkirtSequenceOptions o;
  int sheet = 6;
  int studio_views = 0, studio_size = 640;
  bool quiet = false;
};

void add_synth(CLI::App& cloth, SynthArgs& a, CLI::App*& sub) {
  sub = cloth.add_subcommand("synth", "ground truth: a mannequin built from a BVH skeleton, wearing a simulated skirt, driven by the clip");
  sub->add_option("--bvh", a.bvh, "BVH clip (its skeleton builds the mannequin; CMU-style joint names)")->required();
  sub->add_option("--out", a.out, "output folder: mesh_FFFF.ply per frame, truth.json, truth_model.json (the generating model), contact_sheet.png")->required();
  sub->add_option("--frames", a.o.frames, "frames to produce (default 200)")->check(CLI::PositiveNumber);
  sub->add_option("--bvh-step", a.o.bvh_step, "BVH frames per produced frame (default 3: 120 Hz -> 40 Hz)")->check(CLI::PositiveNumber);
  sub->add_option("--first", a.o.first_bvh_frame, "first BVH frame (default 0)")->check(CLI::NonNegativeNumber);
  sub->add_option("--scale", a.o.bvh_scale, "BVH units -> metres (default 0.01: the CMU clips in ../shared/data are in cm)")
      ->check(CLI::PositiveNumber);
  sub->add_option("--d-n", a.o.material.d_n, "true normal drag d_n (default 2)")->check(CLI::NonNegativeNumber);
  sub->add_option("--d-t", a.o.material.d_t, "true tangential drag d_t (default 4)")->check(CLI::NonNegativeNumber);
  sub->add_option("--k-bend", a.o.material.k_bend, "true bending stiffness k_bend (default 0.3)")->check(CLI::Range(0.0, 1.0));
  sub->add_option("--contact-sheet", a.sheet, "frames in contact_sheet.png (default 6; 0 = none)")->check(CLI::NonNegativeNumber);
  sub->add_option("--studio-views", a.studio_views,
                  "also render the sequence into a textured studio of this many cameras: OUT/studio/studio.yaml, images, silhouettes (default 0 = none)")
      ->check(CLI::Range(0, 64));
  sub->add_option("--studio-size", a.studio_size, "studio image width = height in pixels (default 640)")->check(CLI::Range(16, 8192));
  sub->add_flag("-q,--quiet", a.quiet, "no progress bar");
}

int cmd_synth(const SynthArgs& a) {
  const BvhMotion clip = read_bvh(a.bvh);
  const Skeleton s = skeleton_from_bvh(clip, -1, a.o.bvh_scale);
  const synth::SkirtedMannequin m = synth::make_skirted_mannequin(s);
  make_out_dir(a.out);
  ProgressBar bar(!a.quiet);
  const auto cb = bar.callback();
  const std::vector<int> sheet = evenly_spread(a.sheet, a.o.frames);
  std::vector<TriMesh> meshes;
  std::vector<std::string> titles;
  std::vector<Eigen::MatrixX3d> frames;  // kept for the studio only
  synth::simulate_skirt_sequence(m, s, clip, a.o, [&](int f, const Eigen::MatrixX3d& V) {
    TriMesh t;
    t.V = V;
    t.F = m.mesh.F;
    if (a.studio_views > 0) frames.push_back(V);
    char name[32];
    std::snprintf(name, sizeof name, "mesh_%04d.ply", f);
    write_mesh((fs::path(a.out) / name).string(), t);
    if (std::binary_search(sheet.begin(), sheet.end(), f)) meshes.push_back(t), titles.push_back("frame " + std::to_string(f));
    report_progress(cb, double(f + 1) / a.o.frames, "simulating the skirt");
  });
  if (a.studio_views > 0) {
    synth::StudioOptions so;
    so.cameras = a.studio_views;
    so.width = so.height = a.studio_size;
    so.frames = a.o.frames;
    so.frame_rate = 1.0 / (a.o.bvh_step * clip.frame_time);
    so.markers = 0;
    synth::write_sequence_studio(
        (fs::path(a.out) / "studio").string(), m.mesh,
        [&](int f) {
          TriMesh t;
          t.V = frames[std::size_t(f)];
          t.F = m.mesh.F;
          return t;
        },
        so, [&](double x, const std::string&) { return !cb || cb(x, "rendering the studio"); });
  }
  bar.finish();
  nlohmann::json truth;
  truth["bvh"] = a.bvh;
  truth["frames"] = a.o.frames;
  truth["bvh_step"] = a.o.bvh_step;
  truth["first_bvh_frame"] = a.o.first_bvh_frame;
  truth["bvh_scale"] = a.o.bvh_scale;
  truth["studio"] = a.studio_views > 0 ? nlohmann::json("studio/studio.yaml") : nlohmann::json(nullptr);
  truth["material"] = {{"d_n", a.o.material.d_n}, {"d_t", a.o.material.d_t}, {"k_bend", a.o.material.k_bend}};
  truth["skirt_begin"] = m.skirt_begin;
  truth["cloth"] = std::vector<int>(m.cloth.data(), m.cloth.data() + m.cloth.size());
  nlohmann::json limbs = nlohmann::json::array();
  for (const auto& l : m.limbs)
    limbs.push_back({{"joint", s.names[std::size_t(l.bone.joint)]}, {"child", s.names[std::size_t(l.bone.child)]}, {"ra", l.cone.ra}, {"rb", l.cone.rb}});
  truth["limbs"] = limbs;
  write_text_file_atomic((fs::path(a.out) / "truth.json").string(), truth.dump(1) + "\n");
  {  // the generating model (rest pose, true weights, clothness, proxies, material): estimation runs without model error
    PbdSettings st = a.o.settings;
    st.time_step = a.o.bvh_step * clip.frame_time;
    save_animatable_model((fs::path(a.out) / "truth_model.json").string(), synth::generating_model(m, s, a.o.material, st));
  }
  write_contact_sheet((fs::path(a.out) / "contact_sheet.png").string(), meshes, titles);
  if (!a.quiet)
    std::cout << "cloth synth: " << a.o.frames << " frames of a " << m.mesh.V.rows() << "-vertex mannequin (skirt " << (m.mesh.V.rows() - m.skirt_begin)
              << " vertices) in " << a.out << "\n";
  return 0;
}

// ---- tbsp cloth segment

struct SegmentArgs {
  std::string frames, out, png;
  ClothSegmentationOptions o;
  bool quiet = false;
};

void add_segment(CLI::App& cloth, SegmentArgs& a, CLI::App*& sub) {
  sub = cloth.add_subcommand("segment", "cloth vs body per vertex from a mesh sequence with constant connectivity (thesis §10.3)");
  sub->add_option("--frames", a.frames, "folder of meshes, one per frame, same connectivity (sorted by name; .ply/.obj/.off)")->required();
  sub->add_option("--out", a.out, "segmentation JSON: sigma, clothness per vertex, thresholds")->required();
  sub->add_option("--png", a.png, "render of the first frame coloured by clothness (blue body -> red cloth)");
  sub->add_option("--t-rigid", a.o.t_rigid, "t_rigid of eq. 10.1, fraction of the bounding-box diagonal (default 0.002)")
      ->check(CLI::NonNegativeNumber);
  sub->add_option("--t-cloth", a.o.t_cloth, "t_cloth of eq. 10.1, fraction of the diagonal (default 0.008)")->check(CLI::PositiveNumber);
  sub->add_option("--diffusion", a.o.diffusion, "diffusion of the clothness, in mean edge lengths squared (default 2)")
      ->check(CLI::Range(0.0, 1e4));
  sub->add_flag("-q,--quiet", a.quiet, "no progress bar");
}

int cmd_segment(const SegmentArgs& a) {
  const std::vector<std::string> files = mesh_files_in(a.frames);
  if (files.size() < 2) throw FileError("'" + a.frames + "': one mesh only; the segmentation needs a sequence (2 or more frames)");
  ClothSegmentation seg;
  seg.setOptions(a.o);
  ProgressBar bar(!a.quiet);
  const auto cb = bar.callback();
  TriMesh first;
  for (std::size_t k = 0; k < files.size(); ++k) {
    const TriMesh m = read_mesh(files[k]);
    try {
      if (k == 0) {
        first = m;
        seg.begin(m.V, m.F);
      } else {
        if (m.F.rows() != first.F.rows() || (m.F.rows() == first.F.rows() && m.F != first.F))
          throw InvalidInput("its faces differ from the first frame's (" + files[0] + "): the sequence must keep one connectivity");
        seg.addFrame(m.V);
      }
    } catch (const InvalidInput& e) {
      throw InvalidInput(files[k] + ": " + e.what());
    }
    report_progress(cb, double(k + 1) / double(files.size()), "reading frames");
  }
  bar.finish();
  const ClothSegmentation::Result r = seg.finish();
  nlohmann::json j;
  j["frames"] = r.frames;
  j["first_frame"] = files[0];
  j["vertices"] = first.V.rows();
  j["t_rigid"] = r.t_rigid;
  j["t_cloth"] = r.t_cloth;
  nlohmann::json sigma = nlohmann::json::array();
  int hits = 0, cloth = 0;
  for (Eigen::Index i = 0; i < r.sigma.size(); ++i) {
    if (std::isnan(r.sigma(i))) sigma.push_back(nullptr);
    else sigma.push_back(r.sigma(i)), ++hits;
    cloth += r.clothness(i) > 0.5;
  }
  j["sigma"] = sigma;
  j["clothness"] = std::vector<double>(r.clothness.data(), r.clothness.data() + r.clothness.size());
  j["cloth_vertices"] = cloth;
  j["vertices_without_opposite_surface"] = int(r.sigma.size()) - hits;
  write_text_file_atomic(a.out, j.dump(1) + "\n");
  if (!a.png.empty()) {
    TriMesh c = first;
    c.C = colormap(r.clothness, 0, 1);
    RenderPanel p(c, "clothness (blue body, red cloth)");
    RenderOptions ro;
    ro.panel_width = 360;
    ro.panel_height = 440;
    ro.azimuth_deg = 25;
    ro.elevation_deg = 10;
    render_panels_png(a.png, {p}, ro);
  }
  if (!a.quiet)
    std::cout << "cloth segment: " << r.frames << " frames, " << cloth << " of " << r.clothness.size() << " vertices are cloth; " << a.out << "\n";
  return 0;
}

}  // namespace

void add_cloth_segment_commands(CLI::App& cloth, CommandTable& table) {
  register_command<SynthArgs>(cloth, table, add_synth, cmd_synth);
  register_command<SegmentArgs>(cloth, table, add_segment, cmd_segment);
}

}  // namespace tbsp::cli
