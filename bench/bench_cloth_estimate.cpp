// bench_cloth_estimate: cloth parameter estimation (thesis §10.7, issue 26) on a rendered ground
// truth. The skirted mannequin is driven by a CMU clip with a known material, rendered into an
// 8-view studio (textured), the model is built from the simulated meshes by our pipeline, and the
// material is estimated from the images alone by the thesis' search (K³ grid + 192 greedy samples)
// and by ours (start design + NLopt BOBYQA), in the same run. Prints a table: simulations, wall
// time, E_fit, the estimate and its error against the truth; optionally a landscape slice.
//
//   bench_cloth_estimate [--clip FILE] [--frames N] [--bvh-step S (3)] [--size PX] [--views K] [--truth DN,DT,KB]
//                        [--search thesis|ours|both|none] [--window W] [--stride S] [--landscape G] [--scan]
//                        [--gt-model | --gt-weights] [--dir DIR] [--rings R --segments S]
// --gt-model: estimate with the generating body model (its rigid weights, true clothness, the limb
// tubes) instead of the one our pipeline builds from the meshes; --gt-weights: the pipeline model
// with the generating skinning weights (which model error biases the estimate); --scan: E_fit
// along each parameter through the truth (±10 %…±50 %, k_bend ±0.05…±0.2).
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <string>
#include <vector>

#include "tbsp/cloth/cloth_parameter_estimation.h"
#include "tbsp/io/studio.h"
#include "tbsp/plugins/skirt_studio.h"

using namespace tbsp;

namespace {

double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

}  // namespace

int main(int argc, char** argv) {
  std::string clip_path = std::string(TBSP_SHARED_DATA_DIR) + "/capture/dopomoc__BVH/02_05.bvh";
  std::string search = "both", dir = (std::filesystem::temp_directory_path() / "tbsp_bench_cloth_estimate").string();
  bool gt_model = false, gt_weights = false, scan = false, print_samples = false, rescore = false;
  int start_samples = 0, max_evals = 0, phases = 1;
  std::string eval_points;  // "d_n,d_t,k_bend;..." evaluated and printed (diagnostics)
  int frames = 100, bvh_step = 3, size = 640, views = 8, landscape = 0, window = ClothEstimationOptions{}.window, rings = 20, segments = 48, stride = 1;
  ClothMaterial truth{1.0, 10.0, 0.6};
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto next = [&]() -> const char* {
      if (i + 1 >= argc) { std::fprintf(stderr, "%s needs a value\n", a.c_str()); std::exit(2); }
      return argv[++i];
    };
    if (a == "--clip") clip_path = next();
    else if (a == "--frames") frames = std::atoi(next());
    else if (a == "--bvh-step") bvh_step = std::atoi(next());
    else if (a == "--size") size = std::atoi(next());
    else if (a == "--views") views = std::atoi(next());
    else if (a == "--search") search = next();
    else if (a == "--landscape") landscape = std::atoi(next());
    else if (a == "--dir") dir = next();
    else if (a == "--rings") rings = std::atoi(next());
    else if (a == "--segments") segments = std::atoi(next());
    else if (a == "--gt-model") gt_model = true;
    else if (a == "--samples") print_samples = true;
    else if (a == "--phases") phases = std::atoi(next());
    else if (a == "--eval") eval_points = next();
    else if (a == "--start") start_samples = std::atoi(next());
    else if (a == "--max-evals") max_evals = std::atoi(next());
    else if (a == "--gt-weights") gt_weights = true;
    else if (a == "--scan") scan = true;
    else if (a == "--rescore") rescore = true;
    else if (a == "--window") window = std::atoi(next());
    else if (a == "--stride") stride = std::atoi(next());
    else if (a == "--truth") {
      if (std::sscanf(next(), "%lf,%lf,%lf", &truth.d_n, &truth.d_t, &truth.k_bend) != 3) { std::fprintf(stderr, "--truth DN,DT,KB\n"); return 2; }
    } else {
      std::fprintf(stderr, "unknown option %s\n", a.c_str());
      return 2;
    }
  }
  std::setvbuf(stdout, nullptr, _IOLBF, 0);
  if (!std::filesystem::exists(clip_path)) {
    std::printf("skipped: %s not found\n", clip_path.c_str());
    return 0;
  }
  const BvhMotion clip = read_bvh(clip_path);
  synth::SkirtStudioOptions so;
  so.mannequin.skirt_rings = rings;
  so.mannequin.skirt_segments = segments;
  so.sequence.frames = frames;
  so.sequence.bvh_step = bvh_step;
  so.sequence.material = truth;
  so.studio.cameras = views;
  so.studio.width = so.studio.height = size;
  auto t0 = std::chrono::steady_clock::now();
  const synth::SkirtStudio gt = synth::write_skirt_studio(dir, clip, so);
  const double t_gt = seconds_since(t0);
  t0 = std::chrono::steady_clock::now();
  const Studio studio = read_studio(gt.studio.studio.path);
  ClothObservations obs(studio.cameraList());
  StudioFrameStream stream(studio, {});
  StudioFrame fr;
  while (stream.next(fr)) obs.addFrame(fr.images, fr.silhouettes);
  const double t_obs = seconds_since(t0);
  std::printf("ground truth: %d frames of %s, %d views %dx%d, %ld vertices, truth (d_n %.2f, d_t %.2f, k_bend %.2f); model: %s; window %d\n",
              frames, clip_path.c_str(), views, size, size, long(gt.model.mesh.V.rows()), truth.d_n, truth.d_t, truth.k_bend,
              gt_model ? "the generating one" : gt_weights ? "pipeline with the generating weights" : "built by the pipeline", window);
  std::printf("simulate+render %.1f s; observations %.1f s (%zu boundary px, %zu correspondences, %.1f MB)\n", t_gt, t_obs, obs.numBoundaryPixels(),
              obs.numCorrespondences(), obs.memoryBytes() / 1e6);
  AnimatableModel model = gt.model;
  if (gt_model) model = synth::generating_model(gt.mannequin, gt.skeleton, ClothMaterial{}, gt.model.settings);
  if (gt_weights) model.weights = gt.mannequin.weights;  // diagnostic: the pipeline model with the generating skinning
  ClothParameterEstimation est(model, gt.poses, obs);
  ClothEstimationOptions eo;
  eo.frame_stride = stride;
  eo.window = window;
  eo.window_phases = phases;
  if (start_samples > 0) eo.start_samples = start_samples;
  if (max_evals > 0) eo.max_evaluations = max_evals;
  est.setReferenceSequence(gt.frames);
  est.setOptions(eo);
  std::printf("cloth vertices (δ ≥ 0.5): %d\n", est.clothVertices(0));
  t0 = std::chrono::steady_clock::now();
  const ClothFitEnergy et = est.evaluate(0, truth);
  std::printf("E_fit at the truth: %.3f (E_sil %.3f, E_sift %.4f; %ld rim, %ld features, %d frames) in %.2f s\n", et.e_fit, et.e_sil, et.e_sift,
              et.rim_samples, et.feature_samples, et.frames, seconds_since(t0));
  // Held-out score (--rescore): a point on the window grid shifted by half a window, which the
  // search never saw; from E with 2 phases (S0 + S1)/(F0 + F1) and E with 1 phase S0/F0.
  auto rescore_point = [&](const char* what, const ClothMaterial& rho) {
    if (window <= 1) return;
    ClothEstimationOptions ro = eo;
    ro.window_phases = 2;
    est.setOptions(ro);
    const ClothFitEnergy e2 = est.evaluate(0, rho);
    ro.window_phases = 1;
    est.setOptions(ro);
    const ClothFitEnergy e1 = est.evaluate(0, rho);
    est.setOptions(eo);
    const double held = (e2.e_fit * e2.frames - e1.e_fit * e1.frames) / double(e2.frames - e1.frames);
    std::printf("  rescore %s: E_fit on the search's grid %.3f, on the shifted grid (held out) %.3f, both grids %.3f\n", what, e1.e_fit, held,
                e2.e_fit);
    std::fflush(stdout);
  };
  if (rescore) rescore_point("truth", truth);
  if (!eval_points.empty()) {
    std::vector<ClothMaterial> rhos;
    std::size_t at = 0;
    while (at < eval_points.size()) {
      const std::size_t end = std::min(eval_points.find(';', at), eval_points.size());
      ClothMaterial m;
      if (std::sscanf(eval_points.substr(at, end - at).c_str(), "%lf,%lf,%lf", &m.d_n, &m.d_t, &m.k_bend) != 3) { std::fprintf(stderr, "--eval DN,DT,KB;...\n"); return 2; }
      rhos.push_back(m);
      at = end + 1;
    }
    const std::vector<ClothFitEnergy> es = est.evaluate(0, rhos);
    for (std::size_t i = 0; i < rhos.size(); ++i)
      std::printf("  eval %6.3f %6.2f %6.3f  E_fit %.3f\n", rhos[i].d_n, rhos[i].d_t, rhos[i].k_bend, es[i].e_fit);
  }
  if (scan) {  // 1-D scans through the truth
    const double f[7] = {0.5, 0.7, 0.9, 1.0, 1.1, 1.3, 1.5};
    const double kb[7] = {-0.2, -0.1, -0.05, 0, 0.05, 0.1, 0.2};
    std::vector<ClothMaterial> rhos;
    for (int ax = 0; ax < 3; ++ax)
      for (int i = 0; i < 7; ++i) {
        ClothMaterial m = truth;
        if (ax == 0) m.d_n *= f[i];
        if (ax == 1) m.d_t *= f[i];
        if (ax == 2) m.k_bend = std::clamp(m.k_bend + kb[i], 0.0, 1.0);
        rhos.push_back(m);
      }
    const auto es = est.evaluate(0, rhos);
    for (int ax = 0; ax < 3; ++ax) {
      std::printf("%s:", ax == 0 ? "d_n x{.5,.7,.9,1,1.1,1.3,1.5}" : ax == 1 ? "d_t x{...}" : "k_bend +{-.2,-.1,-.05,0,.05,.1,.2}");
      for (int i = 0; i < 7; ++i) std::printf(" %8.3f", es[std::size_t(ax * 7 + i)].e_fit);
      std::printf("\n  sil:");
      for (int i = 0; i < 7; ++i) std::printf(" %8.3f", es[std::size_t(ax * 7 + i)].e_sil);
      std::printf("\n  sift:");
      for (int i = 0; i < 7; ++i) std::printf(" %8.3f", es[std::size_t(ax * 7 + i)].e_sift);
      std::printf("\n");
    }
  }
  if (landscape > 1) {
    // slices through the truth: k_bend × d_n (Fig. 10.5), d_t × d_n
    std::vector<ClothMaterial> rhos;
    for (int i = 0; i < landscape; ++i)
      for (int j = 0; j < landscape; ++j) {
        ClothMaterial m = truth;
        m.k_bend = (j + 0.5) / landscape;
        m.d_n = 10.0 * (i + 0.5) / landscape;
        rhos.push_back(m);
      }
    for (int i = 0; i < landscape; ++i)
      for (int j = 0; j < landscape; ++j) {
        ClothMaterial m = truth;
        m.d_t = 50.0 * (j + 0.5) / landscape;
        m.d_n = 10.0 * (i + 0.5) / landscape;
        rhos.push_back(m);
      }
    t0 = std::chrono::steady_clock::now();
    const auto es = est.evaluate(0, rhos);
    std::printf("landscape %zu samples in %.1f s\n", rhos.size(), seconds_since(t0));
    for (int s = 0; s < 2; ++s) {
      std::printf(s == 0 ? "\nrows d_n (0..10), columns k_bend (0..1), d_t = truth\n" : "\nrows d_n (0..10), columns d_t (0..50), k_bend = truth\n");
      for (int i = 0; i < landscape; ++i) {
        for (int j = 0; j < landscape; ++j) std::printf(" %7.2f", es[std::size_t(s * landscape * landscape + i * landscape + j)].e_fit);
        std::printf("\n");
      }
    }
  }
  std::printf("\n| search | simulations | wall s | E_fit | d_n | d_t | k_bend | err d_n | err d_t | err k_bend |\n|---|---|---|---|---|---|---|---|---|---|\n");
  for (const char* s : {"thesis", "ours"}) {
    if (search != "both" && search != s) continue;
    eo.search = std::string(s) == "thesis" ? ClothSearch::Thesis : ClothSearch::Bobyqa;
    est.setOptions(eo);
    const ClothEstimationResult r = est.estimate();
    const ClothRegionEstimate& g = r.regions.front();
    std::printf("| %s | %d | %.1f | %.3f | %.3f | %.2f | %.3f | %+.1f %% | %+.1f %% | %+.3f |\n", s, g.simulations, g.seconds, g.energy.e_fit, g.rho.d_n,
                g.rho.d_t, g.rho.k_bend, 100 * (g.rho.d_n - truth.d_n) / truth.d_n, 100 * (g.rho.d_t - truth.d_t) / truth.d_t,
                g.rho.k_bend - truth.k_bend);
    if (rescore) rescore_point(s, g.rho);
    if (print_samples)
      for (const ClothSample& c : r.samples)
        std::printf("  sample %6.3f %6.2f %6.3f  E_fit %.3f\n", c.rho.d_n, c.rho.d_t, c.rho.k_bend, c.energy.e_fit);
    std::fflush(stdout);
  }
  return 0;
}
