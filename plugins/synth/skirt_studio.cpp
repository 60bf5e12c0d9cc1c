#include "tbsp/plugins/skirt_studio.h"

#include <cmath>

#include "tbsp/cloth/cloth_segmentation.h"
#include "tbsp/cloth/collision_proxies.h"
#include "tbsp/core/error.h"
#include "tbsp/io/bvh_skeleton.h"

namespace tbsp::synth {

AnimatableModel build_animatable_model(const TriMesh& rest, const Skeleton& skeleton, const Eigen::VectorXd& sigma_in,
                                       const Eigen::VectorXd& clothness, const ProxyFitOptions& proxies, double time_step) {
  AnimatableModel m;
  m.mesh = rest;
  m.skeleton = skeleton;
  m.clothness = clothness;
  Eigen::VectorXd sigma = sigma_in;
  for (Eigen::Index i = 0; i < sigma.size(); ++i)
    if (!std::isfinite(sigma(i))) sigma(i) = 0;  // no opposite surface: no evidence of motion
  m.weights = bone_heat_weights(rest.V, rest.F, skeleton);
  m.proxies = fit_collision_proxies(rest.V, rest.F, skeleton, sigma, clothness, proxies);
  m.materials = {ClothMaterial{}};
  m.settings.time_step = time_step;
  m.validate("tbsp::synth::build_animatable_model");
  return m;
}

AnimatableModel build_animatable_model(const TriMesh& rest, const std::vector<Eigen::MatrixX3d>& frames, const Skeleton& skeleton,
                                       double time_step) {
  if (frames.size() < 2) throw InvalidInput("[tbsp::synth::build_animatable_model] at least two frames are needed to segment the cloth");
  ClothSegmentation seg;
  seg.begin(frames.front(), rest.F);
  for (std::size_t f = 1; f < frames.size(); ++f) seg.addFrame(frames[f]);
  const ClothSegmentation::Result r = seg.finish();
  return build_animatable_model(rest, skeleton, r.sigma, r.clothness, ProxyFitOptions{}, time_step);
}

SkirtStudio write_skirt_studio(const std::string& dir, const BvhMotion& clip, const SkirtStudioOptions& o, const ProgressCallback& progress) {
  SkirtStudio out;
  out.skeleton = skeleton_from_bvh(clip, -1, o.sequence.bvh_scale);
  out.mannequin = make_skirted_mannequin(out.skeleton, o.mannequin);
  std::vector<Eigen::MatrixX3d>& frames = out.frames;
  simulate_skirt_sequence(out.mannequin, out.skeleton, clip, o.sequence, [&](int f, const Eigen::MatrixX3d& V) {
    frames.push_back(V);
    report_progress(progress, 0.3 * (f + 1) / o.sequence.frames, "simulating the skirt");
  });
  for (int f = 0; f < o.sequence.frames; ++f)
    out.poses.push_back(bvh_pose(clip, o.sequence.first_bvh_frame + f * o.sequence.bvh_step, o.sequence.bvh_scale));
  const double dt = o.sequence.bvh_step * clip.frame_time;
  StudioOptions so = o.studio;
  so.frames = o.sequence.frames;
  so.frame_rate = 1.0 / dt;
  so.markers = 0;
  const TriMesh& rest = out.mannequin.mesh;
  out.studio = write_sequence_studio(
      dir, rest,
      [&](int f) {
        TriMesh t;
        t.V = frames[std::size_t(f)];
        t.F = rest.F;
        return t;
      },
      so, [&](double x, const std::string& s) { return !progress || progress(0.3 + 0.6 * x, s); });
  report_progress(progress, 0.9, "building the model");
  out.model = build_animatable_model(rest, frames, out.skeleton, dt);
  out.model.settings = o.sequence.settings;  // the simulation settings are known; the material is estimated
  out.model.settings.time_step = dt;
  report_progress(progress, 1.0, "done");
  return out;
}

}  // namespace tbsp::synth
