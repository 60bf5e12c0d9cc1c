// fit_template: the stages of a template fit in order (template_fitter.h has the pipeline; each
// stage is in a file of its own, see fit_state.h).
#include "tbsp/fitting/template_fitter.h"

#include <algorithm>
#include <cstdio>
#include <limits>
#include <optional>

#include "fit_state.h"
#include "tbsp/core/error.h"
#include "tbsp/core/timer.h"
#include "tbsp/mesh/mesh_validation.h"
#include "tbsp/mesh/point_search.h"
#include "tbsp/solve/blas_threads.h"

namespace tbsp {
namespace {

// What the passes and hypotheses of one fit without markers share: they fit the same template
// to the same cloud, so the prepared cloud and the similarity alignment are computed once (by
// the first pass) and reused; results are identical to computing them each time.
struct SharedWork {
  std::optional<fit_impl::PreparedCloud> cloud;
  std::optional<SimilarityIcpResult> alignment;
};

FitReport fit_once(const TriMesh& templ, const Eigen::MatrixX3d& P_in, const Eigen::MatrixX3d& N_in,
                   const std::vector<FitMarker>& markers, const RegionOfInterest& roi, const FitParameters& params,
                   TriMesh& result, std::vector<VertexStatus>& status, const ProgressCallback& progress,
                   bool orient_normals, int coarse_prepass, SharedWork* shared = nullptr);
FitReport markerless_fit(const TriMesh& templ, const Eigen::MatrixX3d& P_in, const Eigen::MatrixX3d& N_in, const RegionOfInterest& roi,
                         const FitParameters& params, TriMesh& result, std::vector<VertexStatus>& status, const ProgressCallback& progress,
                         bool orient_normals, int coarse_prepass, SharedWork& shared);

// The part [lo, hi] of `progress` (empty when `progress` is).
ProgressCallback sub_progress(const ProgressCallback& progress, double lo, double hi) {
  if (!progress) return {};
  return [&progress, lo, hi](double f, const std::string& stage) { return progress(lo + (hi - lo) * f, stage); };
}

}  // namespace

FitReport fit_template(const TriMesh& templ, const Eigen::MatrixX3d& P_in, const Eigen::MatrixX3d& N_in,
                       const std::vector<FitMarker>& markers, const RegionOfInterest& roi, const FitParameters& params_in,
                       TriMesh& result, std::vector<VertexStatus>& status, const ProgressCallback& progress,
                       bool orient_normals) {
  const bool markerless = markers.empty() && params_in.auto_markers != 0 && !params_in.remeshing;
  // coarse_nodes −1: the coarse stage when the fit aligns the template itself
  FitParameters params = params_in;
  if (params.coarse_nodes == -1) params.coarse_nodes = markerless && params.align_without_markers ? 400 : 0;
  if (!markerless) return fit_once(templ, P_in, N_in, markers, roi, params, result, status, progress, orient_normals, 0);
  const auto t_all = Clock::now();
  // Without markers nothing but nearest points tells the coarse stage where a turned part went,
  // and it can settle in the wrong place; hypotheses whose coarser graphs turn parts as wholes
  // first settle elsewhere, and the data decide (measured: docs/dev/fitting_experiments.md).
  std::vector<int> prepass{0};  // 0: the coarse_nodes graph alone
  if (params.coarse_nodes > 0)
    for (int c : params.coarse_prepass_nodes)
      if (c < params.coarse_nodes && std::find(prepass.begin(), prepass.end(), c) == prepass.end()) prepass.push_back(c);
  const double nh = double(prepass.size());
  SharedWork shared;  // the same for every pass and hypothesis
  FitReport rep = markerless_fit(templ, P_in, N_in, roi, params, result, status, sub_progress(progress, 0.0, 1.0 / nh), orient_normals, 0,
                                 shared);
  if (params.coarse_nodes > 0) {
    std::vector<double> scores{rep.tail_mean};
    std::size_t kept = 0;
    for (std::size_t h = 1; h < prepass.size(); ++h) {
      TriMesh r2;
      std::vector<VertexStatus> s2;
      FitReport rep2 = markerless_fit(templ, P_in, N_in, roi, params, r2, s2, sub_progress(progress, double(h) / nh, double(h + 1) / nh),
                                      orient_normals, prepass[h], shared);
      scores.push_back(rep2.tail_mean);
      if (rep2.tail_mean < rep.tail_mean) {  // ties keep the earlier hypothesis
        rep = std::move(rep2);
        result = std::move(r2);
        status = std::move(s2);
        kept = h;
      }
    }
    rep.coarse_hypotheses = int(prepass.size());
    rep.coarse_kept = int(kept);
    rep.coarse_scores = scores;
    if (prepass.size() > 1) {
      std::string msg = std::to_string(prepass.size()) + " coarse-stage hypotheses, mean of the farthest 1 % of the cloud:";
      char buf[96];
      for (std::size_t h = 0; h < prepass.size(); ++h) {
        if (h == 0) std::snprintf(buf, sizeof buf, " %.4g with the %d-node graph alone", scores[h], params.coarse_nodes);
        else std::snprintf(buf, sizeof buf, ", %.4g with a %d-node graph first", scores[h], prepass[h]);
        msg += buf;
      }
      rep.message += msg + "; hypothesis " + std::to_string(kept + 1) + " kept. ";
    }
  }
  rep.t_total = seconds_since(t_all);
  return rep;
}

namespace {

// Without markers: the aligned fit, then its matched vertices as markers of a second fit.
FitReport markerless_fit(const TriMesh& templ, const Eigen::MatrixX3d& P_in, const Eigen::MatrixX3d& N_in, const RegionOfInterest& roi,
                         const FitParameters& params, TriMesh& result, std::vector<VertexStatus>& status, const ProgressCallback& progress,
                         bool orient_normals, int coarse_prepass, SharedWork& shared) {
  const auto t_all = Clock::now();
  FitParameters first = params;
  first.detail_rounds = 0;  // (2 rounds here: clean Hausdorff 0.50-0.91 % for 0.61-0.93 % over the
                            // roughly placed bunny seeds 1-5, the same scale bias, twice the time)
  TriMesh r1;
  std::vector<VertexStatus> s1;
  const FitReport rep1 = fit_once(templ, P_in, N_in, {}, roi, first, r1, s1, sub_progress(progress, 0.0, 0.4), orient_normals, coarse_prepass, &shared);
  std::vector<int> matched;
  for (std::size_t v = 0; v < s1.size(); ++v)
    if (s1[v] == VertexStatus::Matched) matched.push_back(int(v));
  const std::vector<int> picked = farthest_point_sample(templ.V, matched, params.auto_markers);
  if (picked.size() < 3) {  // too little data matched to steer a second pass: the aligned fit it is
    result = r1;
    status = s1;
    return rep1;
  }
  std::vector<FitMarker> auto_markers;
  for (int v : picked) {
    FitMarker m;
    m.template_vertex = v;
    m.position = r1.V.row(v).transpose();
    auto_markers.push_back(m);
  }
  FitReport rep = fit_once(templ, P_in, N_in, auto_markers, roi, params, result, status, sub_progress(progress, 0.4, 1.0), orient_normals,
                           coarse_prepass, &shared);
  rep.aligned_without_markers = true;
  rep.alignment = rep1.alignment;
  rep.alignment_rotation_deg = rep1.alignment_rotation_deg;
  rep.alignment_scale = rep1.alignment_scale;
  rep.alignment_rms = rep1.alignment_rms;
  rep.alignment_iterations = rep1.alignment_iterations;
  rep.auto_markers = int(auto_markers.size());
  rep.t_alignment = rep1.t_total;  // the whole first pass
  rep.message = rep1.message + "second pass with " + std::to_string(auto_markers.size()) +
                " markers taken from the aligned fit. " + rep.message;
  rep.t_total = seconds_since(t_all);
  return rep;
}

FitReport fit_once(const TriMesh& templ, const Eigen::MatrixX3d& P_in, const Eigen::MatrixX3d& N_in,
                       const std::vector<FitMarker>& markers, const RegionOfInterest& roi, const FitParameters& params,
                       TriMesh& result, std::vector<VertexStatus>& status, const ProgressCallback& progress,
                       bool orient_normals, int coarse_prepass, SharedWork* shared) {
  const auto t_all = Clock::now();
  // one BLAS thread: no contention with our OpenMP loops (blas_threads.h)
  const ScopedBlasThreads blas_threads(1);
  const std::string who = fit_impl::kWho;
  std::string why;
  if (!params.isValid(&why)) throw InvalidInput(who + "invalid parameters: " + why);
  MeshRequirements req;
  req.allow_nonmanifold = !params.remeshing;
  require_valid_mesh(templ, req, "tbsp::TemplateFitting::setInputTemplate");
  if (P_in.rows() == 0) throw InvalidInput(who + "the input cloud is empty; give a cloud with points");
  if (N_in.rows() != 0 && N_in.rows() != P_in.rows())
    throw InvalidInput(who + "the normals have " + std::to_string(N_in.rows()) + " rows for " + std::to_string(P_in.rows()) +
                       " points");
  report_progress(progress, 0.0, "prepare");
  std::optional<fit_impl::PreparedCloud> own;
  std::optional<fit_impl::PreparedCloud>& cloud = shared ? shared->cloud : own;
  if (!cloud) cloud = fit_impl::prepare_cloud(P_in, N_in, roi, params.normal_neighbours);
  FitReport rep;
  fit_impl::FitState s(templ, markers, progress, rep, status, *cloud);
  s.coarse_prepass = coarse_prepass;
  s.alignment_cache = shared ? &shared->alignment : nullptr;
  fit_impl::use_cloud(s, params, orient_normals);
  fit_impl::prepare_markers(s, P_in, roi);
  TriMesh aligned;
  if (markers.empty() && params.align_without_markers) {  // a template roughly in place: similarity alignment first
    report_progress(progress, 0.03, "alignment");
    fit_impl::align_without_markers(s, aligned);
    s.useTemplate(aligned);
  }
  fit_impl::initial_pose(s);             // stage 1 (+ global scale)
  fit_impl::orient_cloud_normals(s);
  fit_impl::coarse_stage(s);
  fit_impl::iterate_fit(s);              // stage 2
  fit_impl::propagate_displacements(s);  // stage 3
  fit_impl::detail_rounds(s);
  const int known_crossings = fit_impl::repair_surface(s);
  fit_impl::compute_metrics(s, known_crossings);
  result.V = s.V;
  result.F = s.F;
  result.N.resize(0, 3);
  result.C.resize(0, 3);
  rep.t_total = seconds_since(t_all);
  report_progress(progress, 1.0, "done");
  return rep;
}

}  // namespace

}  // namespace tbsp
