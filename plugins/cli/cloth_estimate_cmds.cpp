// `tbsp cloth estimate`: the cloth materials of an animatable model from a studio recording
// (thesis §10.7; ClothParameterEstimation), with the report, the estimated model and the energy
// landscape (Fig. 10.5) as a PNG.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <exception>
#include <filesystem>
#include <functional>
#include <iostream>
#include <limits>
#include <memory>
#include <sstream>

#include <nlohmann/json.hpp>
#include <opencv2/imgproc.hpp>

#include "cloth_cmds.h"
#ifdef TBSP_WITH_MPI
#include "cloth_mpi.h"
#include "pipeline_mpi.h"
#endif
#include "progress_bar.h"
#include "studio_frames.h"
#include "tbsp/cloth/cloth_parameter_estimation.h"
#include "tbsp/core/error.h"
#include "tbsp/core/error_kind.h"
#include "tbsp/io/atomic_file.h"
#include "tbsp/io/mesh_io.h"
#include "tbsp/io/studio.h"
#include "tbsp/plugins/cloth_model_json.h"

namespace fs = std::filesystem;

namespace tbsp::cli {

namespace {

struct EstimateArgs {
  std::string model, studio, bvh, reference, out, search = "ours", truth;
  double scale = 0.01;
  int first = 0, step = 3, landscape = 0;
  ClothEstimationOptions o;
  bool quiet = false;
};

void add_estimate(CLI::App& cloth, EstimateArgs& a, CLI::App*& sub) {
  sub = cloth.add_subcommand("estimate",
                             "cloth materials (d_n, d_t, k_bend) of a model from a studio recording (thesis §10.7); under mpirun the simulations "
                             "are shared over the ranks (the same result, bit for bit)");
  sub->add_option("--model", a.model, "model JSON from `tbsp cloth build`")->required();
  sub->add_option("--studio", a.studio, "studio.yaml of the recording (images + silhouettes of every frame)")->required();
  sub->add_option("--bvh", a.bvh, "the recorded skeleton motion (the model's joint names)")->required();
  sub->add_option("--reference", a.reference,
                  "folder of the mesh sequence the model was built from, one mesh per studio frame: the simulation restarts from it every --window "
                  "frames (without it: --window 0, one simulation of the whole sequence as in the thesis)");
  sub->add_option("--out", a.out, "output folder: estimated_model.json, estimate_report.json [, landscape.png]")->required();
  sub->add_option("--first", a.first, "BVH frame of the studio's first frame (default 0)")->check(CLI::NonNegativeNumber);
  sub->add_option("--step", a.step, "BVH frames per studio frame (default 3: a 120 Hz clip for a 40 Hz recording)")->check(CLI::PositiveNumber);
  sub->add_option("--scale", a.scale, "BVH units -> metres (default 0.01)")->check(CLI::PositiveNumber);
  sub->add_option("--search", a.search, "ours (start design + BOBYQA, default) or thesis (K³ grid + greedy samples)")
      ->check(CLI::IsMember({"ours", "thesis"}));
  sub->add_option("--max-evaluations", a.o.max_evaluations, "ours: simulations per region (default 40)")->check(CLI::Range(1, 100000));
  sub->add_option("--start-samples", a.o.start_samples, "ours: start design size (default 8)")->check(CLI::Range(1, 1000));
  sub->add_option("--grid", a.o.grid_k, "thesis: K grid samples per axis (default 4)")->check(CLI::Range(1, 10));
  sub->add_option("--greedy", a.o.greedy_samples, "thesis: greedy samples (default 192)")->check(CLI::NonNegativeNumber);
  sub->add_option("--greedy-batch", a.o.greedy_batch,
                  "thesis: greedy samples per batch (default 2; the result depends on it, not on threads or ranks; 1 = strictly sequential)")
      ->check(CLI::Range(1, 1000));
  sub->add_option("--window", a.o.window, "frames per simulation window restarted from --reference (default 10; 0 = whole sequence)")
      ->check(CLI::Range(0, 10000));
  sub->add_option("--window-phases", a.o.window_phases,
                  "restart phases: the window grid laid this many times, shifted, E_fit averaged over all (default 1; costs this many times the simulation)")
      ->check(CLI::Range(1, 10000));
  sub->add_option("--stride", a.o.frame_stride, "evaluate E_fit on every n-th frame (default 1)")->check(CLI::Range(1, 1000));
  sub->add_option("--settle", a.o.settle_frames, "frames the cloth settles in the first pose (window 0; default 40)")->check(CLI::NonNegativeNumber);
  sub->add_option("--seed", a.o.seed, "random seed of the searches (default 1)");
  sub->add_option("--landscape", a.landscape, "also write landscape.png: E_fit on a G×G grid of k_bend × d_n at the estimated d_t (default 0 = none)")
      ->check(CLI::Range(0, 64));
  sub->add_option("--truth", a.truth, "d_n,d_t,k_bend to mark in the landscape and report (ground-truth runs)");
  sub->add_flag("-q,--quiet", a.quiet, "no progress bar");
}

ClothMaterial parse_truth(const std::string& s) {
  ClothMaterial m;
  char c1 = 0, c2 = 0;
  std::istringstream is(s);
  if (!(is >> m.d_n >> c1 >> m.d_t >> c2 >> m.k_bend) || c1 != ',' || c2 != ',' || !(m.d_n >= 0) || !(m.d_t >= 0) || !(m.k_bend >= 0 && m.k_bend <= 1))
    throw InvalidInput("--truth '" + s + "': expected d_n,d_t,k_bend with d_n, d_t ≥ 0 and k_bend in [0, 1]");
  return m;
}

nlohmann::json material_json(const ClothMaterial& m) { return {{"d_n", m.d_n}, {"d_t", m.d_t}, {"k_bend", m.k_bend}}; }

nlohmann::json energy_json(const ClothFitEnergy& e) {
  return {{"e_fit", e.e_fit}, {"e_sil", e.e_sil}, {"e_sift", e.e_sift}, {"rim_samples", e.rim_samples}, {"feature_samples", e.feature_samples}, {"frames", e.frames}};
}

// Green (low) -> yellow -> red (high), as Fig. 10.5.
cv::Vec3b energy_colour(double t) {
  t = std::clamp(t, 0.0, 1.0);
  const double r = t < 0.5 ? 2 * t : 1.0, g = t < 0.5 ? 1.0 : 2 * (1 - t);
  return cv::Vec3b(40, std::uint8_t(40 + 200 * g), std::uint8_t(40 + 200 * r));
}

// E_fit on a G×G grid: x = k_bend, y = d_n (low at the bottom), the estimate (×) and the truth (○).
void write_landscape(const std::string& path, const std::vector<double>& e, int G, const ClothEstimationOptions& o, const ClothMaterial& est,
                     const ClothMaterial* truth, double d_t) {
  const int cell = std::max(8, 480 / G), ml = 70, mt = 40, mb = 60, mr = 20;
  cv::Mat img(mt + G * cell + mb, ml + G * cell + mr, CV_8UC3, cv::Scalar(255, 255, 255));
  const double lo = *std::min_element(e.begin(), e.end()), hi = *std::max_element(e.begin(), e.end());
  for (int i = 0; i < G; ++i)      // d_n
    for (int j = 0; j < G; ++j) {  // k_bend
      const double t = hi > lo ? (e[std::size_t(i * G + j)] - lo) / (hi - lo) : 0.0;
      cv::rectangle(img, cv::Rect(ml + j * cell, mt + (G - 1 - i) * cell, cell, cell), cv::Scalar(energy_colour(t)), cv::FILLED);
    }
  auto px = [&](const ClothMaterial& m) {
    const double x = (m.k_bend - o.lower.k_bend) / std::max(1e-12, o.upper.k_bend - o.lower.k_bend);
    const double y = (m.d_n - o.lower.d_n) / std::max(1e-12, o.upper.d_n - o.lower.d_n);
    return cv::Point(int(ml + x * G * cell), int(mt + (1 - y) * G * cell));
  };
  const cv::Point pe = px(est);
  cv::line(img, pe + cv::Point(-8, -8), pe + cv::Point(8, 8), cv::Scalar(0, 0, 0), 2);
  cv::line(img, pe + cv::Point(-8, 8), pe + cv::Point(8, -8), cv::Scalar(0, 0, 0), 2);
  if (truth) cv::circle(img, px(*truth), 9, cv::Scalar(255, 255, 255), 2);
  const auto font = cv::FONT_HERSHEY_SIMPLEX;
  char buf[160];
  std::snprintf(buf, sizeof buf, "E_fit over k_bend x d_n (d_t = %.2f): green low, red high [%.1f, %.1f]", d_t, lo, hi);
  cv::putText(img, buf, cv::Point(8, 24), font, 0.45, cv::Scalar(0, 0, 0), 1, cv::LINE_AA);
  std::snprintf(buf, sizeof buf, "k_bend %.2f .. %.2f", o.lower.k_bend, o.upper.k_bend);
  cv::putText(img, buf, cv::Point(ml, mt + G * cell + 22), font, 0.45, cv::Scalar(0, 0, 0), 1, cv::LINE_AA);
  std::snprintf(buf, sizeof buf, truth ? "x estimate, o truth" : "x estimate");
  cv::putText(img, buf, cv::Point(ml, mt + G * cell + 44), font, 0.45, cv::Scalar(0, 0, 0), 1, cv::LINE_AA);
  std::snprintf(buf, sizeof buf, "d_n %.0f", o.upper.d_n);
  cv::putText(img, buf, cv::Point(4, mt + 12), font, 0.4, cv::Scalar(0, 0, 0), 1, cv::LINE_AA);
  std::snprintf(buf, sizeof buf, "d_n %.0f", o.lower.d_n);
  cv::putText(img, buf, cv::Point(4, mt + G * cell), font, 0.4, cv::Scalar(0, 0, 0), 1, cv::LINE_AA);
  write_png(path, img);
}

// What every rank reads and computes on its own before the estimation.
struct EstimateInputs {
  AnimatableModel model;
  std::vector<SkeletonPose> poses;
  std::vector<Eigen::MatrixX3d> reference;
  std::unique_ptr<ClothMaterial> truth;
  std::unique_ptr<ClothObservations> obs;
  int frames = 0;
};

void read_inputs(EstimateArgs& a, EstimateInputs& in, const ProgressCallback& cb, bool speak, int rank, int nproc) {
  in.model = load_animatable_model(a.model);
  const AnimatableModel& model = in.model;
  const Studio studio = read_studio(a.studio);
  const BvhMotion clip = read_bvh(a.bvh);
  const int frames = in.frames = studio.numFrames();
  const int last = a.first + (frames - 1) * a.step;
  if (last >= clip.numFrames())
    throw InvalidInput("'" + a.bvh + "': " + std::to_string(clip.numFrames()) + " frames; the studio's " + std::to_string(frames) + " frames from BVH frame " +
                       std::to_string(a.first) + " every " + std::to_string(a.step) + " need " + std::to_string(last + 1) + " (check --first/--step)");
  if (!a.truth.empty()) in.truth = std::make_unique<ClothMaterial>(parse_truth(a.truth));
  for (int i = 0; i < frames; ++i) in.poses.push_back(pose_by_name(model.skeleton, clip, a.first + i * a.step, a.scale, a.bvh));
  if (!a.reference.empty()) {
    const std::vector<std::string> files = mesh_files_in(a.reference);
    if (int(files.size()) != frames)
      throw InvalidInput("'" + a.reference + "': " + std::to_string(files.size()) + " meshes for the studio's " + std::to_string(frames) +
                         " frames (one mesh per frame, sorted by name)");
    for (const std::string& f : files) {
      const TriMesh m = read_mesh(f);
      if (m.V.rows() != model.mesh.V.rows())
        throw InvalidInput("'" + f + "': " + std::to_string(m.V.rows()) + " vertices, the model " + std::to_string(model.mesh.V.rows()) +
                           " (the reference must be the sequence the model was built from)");
      in.reference.push_back(m.V);
    }
  } else if (a.o.window > 0) {
    a.o.window = 0;
    if (speak) std::cout << "cloth estimate: no --reference: one simulation of the whole sequence per sample (--window 0)\n";
  }
  a.o.search = a.search == "thesis" ? ClothSearch::Thesis : ClothSearch::Bobyqa;
  std::string why;
  if (!a.o.isValid(&why)) throw InvalidInput(why);  // fail before reading the studio

  // this rank's part of the frames (all of them on one process): [f0, f1), with the features of
  // frame f0 − 1 for the correspondences into f0
  in.obs = std::make_unique<ClothObservations>(studio.cameraList());
  ClothObservations& obs = *in.obs;
  const int f0 = int(long(frames) * rank / nproc), f1 = int(long(frames) * (rank + 1) / nproc);
  if (f1 <= f0) return;
  StudioFrameStream::Options so;
  so.first = studio.first_frame + std::max(f0 - 1, 0);
  so.last = studio.first_frame + f1 - 1;
  StudioFrameStream stream(studio, so);
  StudioFrame fr;
  while (stream.next(fr)) {
    for (std::size_t c = 0; c < fr.images.size(); ++c)
      if (fr.images[c].empty())
        throw InvalidInput("'" + a.studio + "': camera '" + studio.cameras[c].camera.name() + "' has no images: the estimation needs the video of every camera");
    if (fr.frame < studio.first_frame + f0) {
      obs.primeFrame(fr.images, fr.silhouettes);
      continue;
    }
    obs.addFrame(fr.images, fr.silhouettes);
    report_progress(cb, 0.1 * obs.numFrames() / (f1 - f0), "features and silhouettes");
  }
}

// This process as one of several (mpirun): its rank, the work share and the agreement on errors
// of the steps each rank runs alone (ClothRanks, cloth_mpi.h).
struct Ranks {
  ClothWorkShare share;  // its rank and size are this process's
  std::function<void(const std::exception_ptr&)> agree;
  std::function<std::vector<std::string>(const std::string&)> allgather;
};

// The estimation on one process (ranks: null) or as one rank of several (every rank computes its
// share of the simulations; rank 0 shows the progress and writes the outputs).
int run_estimate(EstimateArgs a, const Ranks* ranks) {
  const bool lead = !ranks || ranks->share.rank == 0;
  ProgressBar bar(!a.quiet && lead);
  const auto cb = bar.callback();
  const auto t_obs = std::chrono::steady_clock::now();
  EstimateInputs in;
  if (ranks) {  // every rank reads on its own: a rank that fails alone must stop the others too
    std::exception_ptr err;
    try {
      read_inputs(a, in, cb, !a.quiet && lead, ranks->share.rank, ranks->share.size);
    } catch (...) {
      err = std::current_exception();
    }
    ranks->agree(err);
    // the ranks' parts of the observations, appended in frame order: what one pass gives
    std::unique_ptr<ClothObservations> all = std::make_unique<ClothObservations>(in.obs->cameras(), in.obs->options());
    for (const std::string& part : ranks->allgather(in.obs->serialize())) all->append(part);
    in.obs = std::move(all);
  } else {
    read_inputs(a, in, cb, !a.quiet, 0, 1);
  }
  const AnimatableModel& model = in.model;
  const std::vector<SkeletonPose>& poses = in.poses;
  const std::vector<Eigen::MatrixX3d>& reference = in.reference;
  const ClothObservations& obs = *in.obs;
  const std::unique_ptr<ClothMaterial>& truth = in.truth;
  const int frames = in.frames;
  const double obs_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t_obs).count();
  ClothParameterEstimation est(model, poses, obs);
  if (!reference.empty()) est.setReferenceSequence(reference);
  est.setOptions(a.o);
  if (ranks) est.setWorkShare(ranks->share);
  est.setProgressCallback([&](double x, const std::string& s) { return !cb || cb(0.1 + (a.landscape ? 0.6 : 0.9) * x, s); });
  const ClothEstimationResult r = est.estimate();
  AnimatableModel out = model;
  for (const ClothRegionEstimate& g : r.regions) out.materials[std::size_t(g.region)] = g.rho;
  std::vector<double> land;
  if (a.landscape > 1) {
    const int G = a.landscape;
    std::vector<ClothMaterial> rhos;
    for (int i = 0; i < G; ++i)
      for (int j = 0; j < G; ++j) {
        ClothMaterial m = r.regions.front().rho;
        m.d_n = a.o.lower.d_n + (i + 0.5) / G * (a.o.upper.d_n - a.o.lower.d_n);
        m.k_bend = a.o.lower.k_bend + (j + 0.5) / G * (a.o.upper.k_bend - a.o.lower.k_bend);
        rhos.push_back(m);
      }
    ClothParameterEstimation scan(out, poses, obs);  // the other regions at their estimates
    if (!reference.empty()) scan.setReferenceSequence(reference);
    scan.setOptions(a.o);
    if (ranks) scan.setWorkShare(ranks->share);
    for (std::size_t b = 0; b < rhos.size(); b += 16) {
      const std::vector<ClothMaterial> part(rhos.begin() + long(b), rhos.begin() + long(std::min(rhos.size(), b + 16)));
      for (const ClothFitEnergy& e : scan.evaluate(0, part)) land.push_back(e.e_fit);
      report_progress(cb, 0.7 + 0.3 * double(land.size()) / double(rhos.size()), "landscape");
    }
  }
  bar.finish();
  if (!lead) return 0;  // rank 0 writes

  make_out_dir(a.out);
  save_animatable_model((fs::path(a.out) / "estimated_model.json").string(), out);
  nlohmann::json rep;
  rep["model"] = a.model;
  rep["studio"] = a.studio;
  rep["bvh"] = a.bvh;
  rep["frames"] = frames;
  rep["views"] = obs.numViews();
  rep["search"] = a.search;
  rep["window"] = a.o.window;
  rep["window_phases"] = a.o.window_phases;
  rep["observations"] = {{"boundary_pixels", obs.numBoundaryPixels()}, {"correspondences", obs.numCorrespondences()}, {"megabytes", obs.memoryBytes() / 1e6}};
  rep["processes"] = ranks ? ranks->share.size : 1;
  rep["observation_seconds"] = obs_seconds;  // reading the inputs and observing every frame (with ranks: their exchange too)
  rep["simulations"] = r.simulations;
  rep["seconds"] = r.seconds;
  nlohmann::json regions = nlohmann::json::array();
  for (const ClothRegionEstimate& g : r.regions) {
    nlohmann::json j{{"region", g.region}, {"material", material_json(g.rho)}, {"energy", energy_json(g.energy)}, {"simulations", g.simulations},
                     {"seconds", g.seconds}};
    if (truth)
      j["error"] = {{"d_n_percent", truth->d_n > 0 ? 100 * (g.rho.d_n - truth->d_n) / truth->d_n : std::numeric_limits<double>::quiet_NaN()},
                    {"d_t_percent", truth->d_t > 0 ? 100 * (g.rho.d_t - truth->d_t) / truth->d_t : std::numeric_limits<double>::quiet_NaN()},
                    {"k_bend", g.rho.k_bend - truth->k_bend}};
    regions.push_back(j);
  }
  rep["regions"] = regions;
  if (truth) rep["truth"] = material_json(*truth);
  nlohmann::json samples = nlohmann::json::array();
  for (const ClothSample& s : r.samples) samples.push_back({{"region", s.region}, {"material", material_json(s.rho)}, {"e_fit", s.energy.e_fit}});
  rep["samples"] = samples;
  if (!land.empty()) {
    rep["landscape"] = {{"size", a.landscape}, {"axes", "rows d_n (low to high), columns k_bend (low to high)"}, {"e_fit", land}};
    write_landscape((fs::path(a.out) / "landscape.png").string(), land, a.landscape, a.o, r.regions.front().rho, truth.get(), r.regions.front().rho.d_t);
  }
  write_text_file_atomic((fs::path(a.out) / "estimate_report.json").string(), rep.dump(1) + "\n");
  if (!a.quiet)
    for (const ClothRegionEstimate& g : r.regions)
      std::printf("cloth estimate: region %d: d_n %.3f, d_t %.3f, k_bend %.3f (E_fit %.3f) after %d simulations in %.1f s -> %s\n", g.region, g.rho.d_n,
                  g.rho.d_t, g.rho.k_bend, g.energy.e_fit, g.simulations, g.seconds, a.out.c_str());
  return 0;
}

int cmd_estimate(const EstimateArgs& a) {
#ifdef TBSP_WITH_MPI
  if (launched_by_mpirun()) {
    ClothRanks mpi;
    if (mpi.size() > 1) {
      mpi.shareCores();
      Ranks ranks;
      ranks.share = mpi.share();
      ranks.agree = [&mpi](const std::exception_ptr& e) { mpi.agree(e); };
      ranks.allgather = [&mpi](const std::string& mine) { return mpi.allgather(mine); };
      if (mpi.rank() == 0) return run_estimate(a, &ranks);  // its error is printed by main()
      // every rank has the same error (ClothRanks::agree and the work share): rank 0 prints it
      try {
        return run_estimate(a, &ranks);
      } catch (...) {
        return exit_code_of(std::current_exception());
      }
    }
  }
#endif
  return run_estimate(a, nullptr);
}

}  // namespace

void add_cloth_estimate_commands(CLI::App& cloth, CommandTable& table) {
  register_command<EstimateArgs>(cloth, table, add_estimate, [](const EstimateArgs& a) { return cmd_estimate(a); });
}

}  // namespace tbsp::cli
