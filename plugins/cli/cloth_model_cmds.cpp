// `tbsp cloth proxies` (collision proxies alone, thesis §10.4), `tbsp cloth build` (skeleton +
// bone-heat weights + proxies + clothness -> an AnimatableModel, thesis §10.1/§10.4/§10.6) and
// `tbsp cloth animate` (a model driven by a BVH clip -> meshes).
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <memory>
#include <nlohmann/json.hpp>
#include <sstream>

#include "cloth_cmds.h"
#include "progress_bar.h"
#include "tbsp/cloth/animatable_model.h"
#include "tbsp/cloth/collision_proxies.h"
#include "tbsp/core/error.h"
#include "tbsp/io/atomic_file.h"
#include "tbsp/cloth/retarget.h"
#include "tbsp/io/bvh_skeleton.h"
#include "tbsp/io/mesh_io.h"
#include "tbsp/plugins/cloth_model_json.h"
#include "tbsp/plugins/skirt_studio.h"
#include "tbsp/plugins/json_file.h"

namespace fs = std::filesystem;

namespace tbsp::cli {

namespace {

// ---- tbsp cloth build

// The inputs `cloth build` and `cloth proxies` share: a template posed as a BVH frame, the clip,
// the segmentation of the template's sequence and the bones that get proxies.
struct ModelInputs {
  std::string mesh, bvh, segmentation, joints = "Thigh,Shin,UpLeg,Leg,Buttock,hip,abdomen,Hips,Spine";
  int bvh_frame = 0;
  double scale = 0.01;
};

void add_model_inputs(CLI::App* sub, ModelInputs& a) {
  sub->add_option("--template", a.mesh, "template mesh in the pose of the BVH frame --bvh-frame (e.g. frame 0 of the reference sequence)")
      ->required();
  sub->add_option("--bvh", a.bvh, "BVH clip whose skeleton drives the model")->required();
  sub->add_option("--bvh-frame", a.bvh_frame, "BVH frame the template is posed in (default 0; -1 = the BVH zero pose)");
  sub->add_option("--scale", a.scale, "BVH units -> metres (default 0.01)")->check(CLI::PositiveNumber);
  sub->add_option("--segmentation", a.segmentation, "output of `tbsp cloth segment` for this template's sequence")->required();
  sub->add_option("--proxy-joints", a.joints, "comma-separated joint-name parts that get collision proxies (default: legs, hips, spine)");
}

struct BuildArgs {
  ModelInputs in;
  std::string out;
  ClothMaterial material;
  bool quiet = false;
};

void add_build(CLI::App& cloth, BuildArgs& a, CLI::App*& sub) {
  sub = cloth.add_subcommand("build", "an animatable model: skeleton from a BVH, bone-heat weights, clothness, collision proxies (thesis §10.6)");
  add_model_inputs(sub, a.in);
  sub->add_option("--d-n", a.material.d_n, "cloth material d_n (default 2; `tbsp cloth estimate` finds it from a recording)")->check(CLI::NonNegativeNumber);
  sub->add_option("--d-t", a.material.d_t, "cloth material d_t (default 4)")->check(CLI::NonNegativeNumber);
  sub->add_option("--k-bend", a.material.k_bend, "cloth material k_bend (default 0.3)")->check(CLI::Range(0.0, 1.0));
  sub->add_option("--out", a.out, "model JSON (format tbsp-animatable-model)")->required();
  sub->add_flag("-q,--quiet", a.quiet, "no summary line");
}

void read_segmentation(const std::string& path, Eigen::Index n, Eigen::VectorXd& sigma, Eigen::VectorXd& clothness) {
  const nlohmann::json j = load_json_file(path);
  const JsonReader r(path);
  try {
    if (!j.is_object() || !j.contains("clothness") || !j.contains("sigma")) r.fail("(top)", "expected \"sigma\" and \"clothness\" (written by `tbsp cloth segment`)");
    const auto& c = j["clothness"];
    const auto& s = j["sigma"];
    if (!c.is_array() || Eigen::Index(c.size()) != n || !s.is_array() || Eigen::Index(s.size()) != n)
      r.fail("clothness", "expected one value per template vertex (" + std::to_string(n) + "): was the segmentation made for this template?");
    sigma.resize(n);
    clothness.resize(n);
    for (Eigen::Index i = 0; i < n; ++i) {
      clothness(i) = r.number(c[std::size_t(i)], "clothness[" + std::to_string(i) + "]");
      if (!(clothness(i) >= 0 && clothness(i) <= 1)) r.fail("clothness[" + std::to_string(i) + "]", "must be in [0, 1]");
      sigma(i) = s[std::size_t(i)].is_null() ? 0.0 : r.number(s[std::size_t(i)], "sigma[" + std::to_string(i) + "]");
      if (sigma(i) < 0) r.fail("sigma[" + std::to_string(i) + "]", "must be ≥ 0");
    }
  } catch (const nlohmann::json::exception& e) {
    throw_json_structure_error(path, e);
  }
}

struct LoadedInputs {
  TriMesh mesh;
  Skeleton skeleton;
  Eigen::VectorXd sigma, clothness;
  ProxyFitOptions proxies;
};

LoadedInputs load_model_inputs(const ModelInputs& a) {
  LoadedInputs l;
  l.mesh = read_mesh(a.mesh);
  l.skeleton = skeleton_from_bvh(read_bvh(a.bvh), a.bvh_frame, a.scale);
  read_segmentation(a.segmentation, l.mesh.V.rows(), l.sigma, l.clothness);
  std::stringstream ss(a.joints);
  for (std::string part; std::getline(ss, part, ',');)
    if (!part.empty()) l.proxies.joints.push_back(part);
  return l;
}

int cmd_build(const BuildArgs& a) {
  const LoadedInputs in = load_model_inputs(a.in);
  const TriMesh& mesh = in.mesh;
  // 40 Hz; `cloth animate` steps by the clip's frame time
  AnimatableModel m = synth::build_animatable_model(mesh, in.skeleton, in.sigma, in.clothness, in.proxies, 1.0 / 40);
  m.materials = {a.material};
  save_animatable_model(a.out, m);
  if (!a.quiet) {
    int cloth = 0;
    for (Eigen::Index i = 0; i < m.clothness.size(); ++i) cloth += m.clothness(i) > 0;
    std::cout << "cloth build: " << mesh.V.rows() << " vertices (" << cloth << " simulated), " << m.skeleton.numJoints() << " joints, "
              << m.proxies.size() << " proxies -> " << a.out << "\n";
  }
  return 0;
}

// ---- tbsp cloth proxies

struct ProxiesArgs {
  ModelInputs in;
  std::string out;
  bool quiet = false;
};

void add_proxies(CLI::App& cloth, ProxiesArgs& a, CLI::App*& sub) {
  sub = cloth.add_subcommand("proxies", "collision proxies alone: one capped cone per bone fitted inside the body (thesis §10.4)");
  add_model_inputs(sub, a.in);
  sub->add_option("--out", a.out, "proxies JSON (format tbsp-collision-proxies; the same entries as a model's \"proxies\")")->required();
  sub->add_flag("-q,--quiet", a.quiet, "no table");
}

int cmd_proxies(const ProxiesArgs& a) {
  const LoadedInputs in = load_model_inputs(a.in);
  const std::vector<CollisionProxy> px = fit_collision_proxies(in.mesh.V, in.mesh.F, in.skeleton, in.sigma, in.clothness, in.proxies);
  if (px.empty())
    throw InvalidInput("cloth proxies: no bone of " + a.in.bvh + " matching --proxy-joints '" + a.in.joints +
                       "' has enough body vertices of " + a.in.mesh + " nearest it; name other joints");
  nlohmann::json list = nlohmann::json::array();
  for (const CollisionProxy& p : px)
    list.push_back({{"joint", p.bone.joint},
                    {"name", in.skeleton.names[std::size_t(p.bone.joint)]},
                    {"child", p.bone.child},
                    {"a", {p.cone.a.x(), p.cone.a.y(), p.cone.a.z()}},
                    {"b", {p.cone.b.x(), p.cone.b.y(), p.cone.b.z()}},
                    {"ra", p.cone.ra},
                    {"rb", p.cone.rb},
                    {"vertices", p.vertices},
                    {"penetration", p.penetration}});
  const nlohmann::json j = {{"format", "tbsp-collision-proxies"}, {"version", 1}, {"template", a.in.mesh}, {"proxies", list}};
  write_text_file_atomic(a.out, j.dump(1) + "\n");
  if (!a.quiet) {
    std::printf("%-28s %9s %9s %9s %8s %12s\n", "bone (joint -> child)", "length", "r start", "r end", "vertices", "max inside");
    for (const CollisionProxy& p : px) {
      const std::string bone = in.skeleton.names[std::size_t(p.bone.joint)] + " -> " + in.skeleton.names[std::size_t(p.bone.child)];
      std::printf("%-28s %9.4f %9.4f %9.4f %8d %12.5f\n", bone.c_str(), (p.cone.b - p.cone.a).norm(), p.cone.ra, p.cone.rb, p.vertices,
                  p.penetration);
    }
    std::cout << "(lengths and radii in the template's units; max inside: the deepest body vertex inside the cone's side)\n";
    std::cout << "cloth proxies: " << px.size() << " proxies -> " << a.out << "\n";
  }
  return 0;
}

// ---- tbsp cloth animate

struct ClothAnimateArgs {
  std::string model, bvh, out, frames, joint_map;
  double scale = 0.01;
  int step = 3, every = 1, sheet = 8, settle = 40;
  bool no_meshes = false, quiet = false;
};

void add_cloth_animate(CLI::App& cloth, ClothAnimateArgs& a, CLI::App*& sub) {
  sub = cloth.add_subcommand("animate", "a new animation: an animatable model driven by a BVH clip (skinning + cloth simulation)");
  sub->add_option("--model", a.model, "model JSON from `tbsp cloth build`")->required();
  sub->add_option("--bvh", a.bvh, "BVH clip with the model's joint names (or any clip with --joint-map)")->required();
  sub->add_option("--joint-map", a.joint_map,
                  "retarget a clip of another skeleton: \"model=clip,model=clip,...\" (joint names; the roots and the limbs at least; "
                  "docs/cloth.md lists the CMU <- Bandai-Namco map)");
  sub->add_option("--out", a.out, "output folder: mesh_FFFF.ply (FFFF = BVH frame), animate_report.json, contact_sheet.png")->required();
  sub->add_option("--frames", a.frames, "BVH frames a:b (inclusive; default all)");
  sub->add_option("--step", a.step, "BVH frames per simulated frame (default 3: a 120 Hz clip at 40 Hz); the simulation step is step × the clip's frame time")->check(CLI::PositiveNumber);
  sub->add_option("--scale", a.scale, "BVH units -> metres (default 0.01)")->check(CLI::PositiveNumber);
  sub->add_option("--settle", a.settle, "frames the cloth settles in the first pose (default 40)")->check(CLI::NonNegativeNumber);
  sub->add_option("--every", a.every, "write every n-th mesh (default 1)")->check(CLI::PositiveNumber);
  sub->add_option("--contact-sheet", a.sheet, "frames in contact_sheet.png (default 8; 0 = none)")->check(CLI::NonNegativeNumber);
  sub->add_flag("--no-meshes", a.no_meshes, "simulate and report only");
  sub->add_flag("-q,--quiet", a.quiet, "no progress bar");
}

int cmd_cloth_animate(const ClothAnimateArgs& a) {
  AnimatableModel model = load_animatable_model(a.model);
  const BvhMotion clip = read_bvh(a.bvh);
  // the simulation advances by the clip's time between two simulated frames (a 30 Hz clip at
  // --step 1 and a 120 Hz clip at --step 4 both step 1/30 s)
  model.settings.time_step = a.step * clip.frame_time;
  if (a.joint_map.empty()) require_bvh_joints(clip, model.skeleton.names, a.bvh);
  int f0 = 0, f1 = clip.numFrames() - 1;
  if (!a.frames.empty()) {
    std::istringstream is(a.frames);
    char c = 0;
    if (!(is >> f0) || !(is >> c) || c != ':' || !(is >> f1) || f0 < 0 || f1 < f0 || f1 >= clip.numFrames())
      throw InvalidInput("--frames '" + a.frames + "': expected a:b with 0 <= a <= b < " + std::to_string(clip.numFrames()));
  }
  // --joint-map: the clip's joint positions drive the model's skeleton (PoseRetargeter)
  std::unique_ptr<PoseRetargeter> retarget;
  auto clip_positions = [&](int f) {
    return joint_positions(bvh_pose(clip, f, a.scale));
  };
  if (!a.joint_map.empty()) {
    try {
      retarget = std::make_unique<PoseRetargeter>(model.skeleton, parse_joint_map(a.joint_map, model.skeleton.names, skeleton_from_bvh(clip).names),
                                                  clip_positions(f0));
    } catch (const InvalidInput& e) {
      throw InvalidInput("--joint-map for " + a.bvh + ": " + e.what());
    }
  }
  make_out_dir(a.out);
  ModelAnimator anim(model);
  std::vector<int> bvh_frames;
  for (int f = f0; f <= f1; f += a.step) bvh_frames.push_back(f);
  const int n = int(bvh_frames.size());
  const std::vector<int> sheet = evenly_spread(a.sheet, n);
  ProgressBar bar(!a.quiet);
  const auto cb = bar.callback();
  nlohmann::json per_frame = nlohmann::json::array();
  std::vector<TriMesh> meshes;
  std::vector<std::string> titles;
  double worst_strain = 0, total = 0;
  int written = 0;
  for (int k = 0; k < n; ++k) {
    const auto t0 = std::chrono::steady_clock::now();
    const int bf = bvh_frames[std::size_t(k)];
    const SkeletonPose pose = retarget ? retarget->retarget(clip_positions(bf)) : pose_by_name(model.skeleton, clip, bf, a.scale, a.bvh);
    const Eigen::MatrixX3d& V = k == 0 ? anim.start(pose, a.settle) : anim.step(pose);
    const double sec = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    total += k ? sec : 0;
    const double strain = anim.simulator().strainQuantile(0.99);
    worst_strain = std::max(worst_strain, strain);
    per_frame.push_back({{"bvh_frame", bvh_frames[std::size_t(k)]}, {"strain_p99", strain}, {"proxy_contacts", anim.simulator().numProxyContacts()},
                         {"self_contacts", anim.simulator().numSelfContacts()}, {"seconds", sec}});
    TriMesh t;
    t.V = V;
    t.F = model.mesh.F;
    if (!a.no_meshes && k % a.every == 0) {
      char name[32];
      std::snprintf(name, sizeof name, "mesh_%04d.ply", bvh_frames[std::size_t(k)]);
      write_mesh((fs::path(a.out) / name).string(), t);
      ++written;
    }
    if (std::binary_search(sheet.begin(), sheet.end(), k))
      meshes.push_back(t), titles.push_back("BVH frame " + std::to_string(bvh_frames[std::size_t(k)]));
    report_progress(cb, double(k + 1) / n, "animating");
  }
  bar.finish();
  nlohmann::json rep;
  rep["model"] = a.model;
  rep["bvh"] = a.bvh;
  rep["frames"] = n;
  rep["bvh_frames"] = {f0, f1, a.step};
  rep["time_step"] = model.settings.time_step;
  if (retarget) {
    rep["joint_map"] = a.joint_map;
    rep["retarget_scale"] = retarget->scale();
  }
  rep["meshes_written"] = written;
  rep["frames_per_second"] = n > 1 ? (n - 1) / std::max(total, 1e-9) : 0.0;
  rep["worst_strain_p99"] = worst_strain;
  rep["per_frame"] = per_frame;
  write_text_file_atomic((fs::path(a.out) / "animate_report.json").string(), rep.dump(1) + "\n");
  write_contact_sheet((fs::path(a.out) / "contact_sheet.png").string(), meshes, titles);
  if (!a.quiet)
    std::cout << "cloth animate: " << n << " frames at " << (n > 1 ? (n - 1) / std::max(total, 1e-9) : 0.0) << " frames/s, " << written
              << " meshes in " << a.out << "\n";
  return 0;
}

}  // namespace

void add_cloth_model_commands(CLI::App& cloth, CommandTable& table) {
  register_command<BuildArgs>(cloth, table, add_build, cmd_build);
  register_command<ProxiesArgs>(cloth, table, add_proxies, cmd_proxies);
  register_command<ClothAnimateArgs>(cloth, table, add_cloth_animate, cmd_cloth_animate);
}

void add_cloth_commands(CLI::App& app, CommandTable& table) {
  CLI::App* cloth = app.add_subcommand("cloth", "cloth estimation (thesis ch. 10, docs/cloth.md): synth, segment, proxies, build, animate, estimate");
  cloth->require_subcommand(1);
  add_cloth_segment_commands(*cloth, table);
  add_cloth_model_commands(*cloth, table);
  add_cloth_estimate_commands(*cloth, table);
}

}  // namespace tbsp::cli
