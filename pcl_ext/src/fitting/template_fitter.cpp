// fit_template: the stages of a template fit in order (template_fitter.h has the pipeline; each
// stage is in a file of its own, see fit_state.h).
#include "tbsp/fitting/template_fitter.h"

#include <algorithm>
#include <atomic>
#include <cstdio>
#include <exception>
#include <limits>
#include <memory>
#include <mutex>
#include <optional>
#include <stdexcept>
#include <string>
#include <system_error>
#include <thread>

#ifdef _OPENMP
#include <omp.h>
#endif

#include "fit_state.h"
#include "tbsp/core/error.h"
#include "tbsp/core/logging.h"
#include "tbsp/core/timer.h"
#include "tbsp/mesh/mesh_validation.h"
#include "tbsp/mesh/point_search.h"
#include "tbsp/solve/blas_threads.h"

namespace tbsp {
namespace {

// What the passes and hypotheses of one fit without markers, or the two compared fits of one
// with markers, share: they fit the same template to the same cloud, so the prepared cloud and
// the similarity alignment are computed once and reused; results are identical to computing
// them each time.
struct SharedWork {
  std::optional<fit_impl::PreparedCloud> cloud;
  std::optional<SimilarityIcpResult> alignment;
};

// One fit in parts: the constructor runs it up to the coarse stage (alignment, initial pose and
// scale), fitStages() on to the detail rounds (coarse stage, iterations, propagation), finish()
// does the rest (detail rounds, repair, metrics). After the constructor a second fit can branch
// off (the fork constructor: the fits with and without the coarse stage share what comes before
// it); after fitStages() pointsBeyondMatchDistance() tells how much of the cloud the fit so far
// leaves unexplained, so a fit with markers can compare its fits without and with the coarse
// stage before it spends the detail rounds on one of them.
// Holds references to the template, markers and (shared) cloud: they must outlive it.
class FitRun {
public:
  FitRun(const TriMesh& templ, const Eigen::MatrixX3d& P_in, const Eigen::MatrixX3d& N_in, const std::vector<FitMarker>& markers,
         const RegionOfInterest& roi, const FitParameters& params, ProgressCallback progress, bool orient_normals, int coarse_prepass,
         SharedWork* shared = nullptr, bool markers_from_fit = false);
  /// A second fit from `from`'s state after its constructor (before fitStages), with
  /// `coarse_nodes` instead of from's (the only parameter the stages before it do not read).
  /// It reads from's cloud when that is not shared: `from` must then outlive it.
  FitRun(const FitRun& from, int coarse_nodes, ProgressCallback progress);
  FitRun(const FitRun&) = delete;
  FitRun& operator=(const FitRun&) = delete;
  /// The coarse stage, iterations and propagation (once; pull and finish run them if this did not).
  void fitStages();
  /// The detail and pull rounds (once; finish runs them if this did not).
  void pull();
  /// ROI points farther than max_match_distance from the current shape; with `surface_only`
  /// only those that are not isolated (fit_impl::is_surface_point).
  Eigen::Index pointsBeyondMatchDistance(bool surface_only = false) const;
  /// FitReport::tail_mean of the current shape (the mean of the largest 1 % of the ROI point
  /// distances), as finish() would report it for this shape.
  double tailMean() const;
  FitReport finish(TriMesh& result, std::vector<VertexStatus>& status);
  /// Nodes of the coarse stage's graph (0: none ran; at most the template's vertices).
  int coarseNodes() const { return rep_.coarse_nodes; }

private:
  Clock::time_point t_all_;
  ScopedBlasThreads blas_threads_;
  ProgressCallback progress_;
  std::optional<fit_impl::PreparedCloud> own_;
  FitReport rep_;
  std::vector<VertexStatus> status_;
  TriMesh aligned_;
  std::unique_ptr<fit_impl::FitState> s_;
  bool staged_ = false, pulled_ = false;
};

FitReport fit_once(const TriMesh& templ, const Eigen::MatrixX3d& P_in, const Eigen::MatrixX3d& N_in,
                   const std::vector<FitMarker>& markers, const RegionOfInterest& roi, const FitParameters& params,
                   TriMesh& result, std::vector<VertexStatus>& status, const ProgressCallback& progress,
                   bool orient_normals, int coarse_prepass, SharedWork* shared = nullptr, bool markers_from_fit = false);
// A hypothesis of a fit without markers whose second pass has run its stages but not its
// detail rounds: those run only for the hypothesis that is kept (markerless_fit, fit_template).
struct DeferredPass {
  ProgressCallback progress;       // the hypothesis's own (the run's sub-progress refers to it)
  std::vector<FitMarker> markers;  // the second pass's markers (the run refers to them)
  FitReport first;                 // the first pass's report
  std::unique_ptr<FitRun> run;     // null: no second pass (too few matched vertices)
};
FitReport markerless_fit(const TriMesh& templ, const Eigen::MatrixX3d& P_in, const Eigen::MatrixX3d& N_in, const RegionOfInterest& roi,
                         const FitParameters& params, TriMesh& result, std::vector<VertexStatus>& status, const ProgressCallback& progress,
                         bool orient_normals, int coarse_prepass, SharedWork& shared, DeferredPass* defer = nullptr);
FitReport second_pass_report(FitReport rep, const FitReport& first, std::size_t n_markers);

// What every fit checks first: the parameters, the template, the cloud's and normals' sizes.
void check_fit_inputs(const TriMesh& templ, const Eigen::MatrixX3d& P_in, const Eigen::MatrixX3d& N_in, const FitParameters& params) {
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
}

// A fit in which no template vertex matched the cloud returns the template as the markers or
// the alignment posed it: not a fit. Thrown (InvalidInput) with what the user can check.
void require_a_match(const FitReport& rep, const TriMesh& templ, const Eigen::MatrixX3d& P, bool had_markers) {
  if (rep.matched > 0 || rep.used.max_iterations == 0) return;
  Eigen::Vector3d lo = Eigen::Vector3d::Constant(std::numeric_limits<double>::infinity()), hi = -lo;
  for (Eigen::Index i = 0; i < P.rows(); ++i)
    if (P.row(i).allFinite()) {
      lo = lo.cwiseMin(P.row(i).transpose());
      hi = hi.cwiseMax(P.row(i).transpose());
    }
  const Eigen::Vector3d tlo = templ.V.colwise().minCoeff().transpose(), thi = templ.V.colwise().maxCoeff().transpose();
  char buf[512];
  std::snprintf(buf, sizeof buf,
                "no template vertex matched the cloud (none came within r_max = %.4g of a cloud point whose normal is within "
                "theta_max = %.4g deg of its own), so the result would be the template as %s posed it, not a fit. The template's "
                "bounding box has its centre at (%.4g, %.4g, %.4g) and a diagonal of %.4g, the cloud's at (%.4g, %.4g, %.4g) and %.4g: ",
                rep.used.max_match_distance, rep.used.max_normal_angle_deg, had_markers ? "the markers" : "the alignment",
                0.5 * (tlo + thi).x(), 0.5 * (tlo + thi).y(), 0.5 * (tlo + thi).z(), (thi - tlo).norm(), 0.5 * (lo + hi).x(),
                0.5 * (lo + hi).y(), 0.5 * (lo + hi).z(), (hi - lo).norm());
  throw InvalidInput(std::string(fit_impl::kWho) + buf +
                     (had_markers ? "check that the markers' positions lie on the cloud and that both use the same units"
                                  : "without markers the template must already lie roughly on the scan (within ~10 deg and ~5 % of its "
                                    "size) in the same units; move it there or give markers") +
                     ", or raise max_match_distance / max_normal_angle_deg");
}

// A crumpled result (a fit to a handful of points, markers pulling against the data) is said
// so in the report: more than 1 % of the edges (and at least 10) bent back by more than 120°
// beyond those the template has itself.
void warn_if_crumpled(FitReport& rep, const TriMesh& templ) {
  const double n_edges = 1.5 * double(rep.faces);
  if (rep.folded_edges < 10 || rep.folded_edges <= 0.01 * n_edges) return;
  const int own = fit_impl::folded_edges(templ.F, templ.V, nullptr);
  const int extra = rep.folded_edges - own;
  if (extra < 10 || extra <= 0.01 * n_edges) return;
  char buf[360];
  std::snprintf(buf, sizeof buf,
                "warning: %d edges of the result (%.1f %%; the template has %d) fold back by more than 120 deg: the fit crumpled; "
                "check it (too few cloud points for the template, markers off the scan, a template far from the scan's shape). ",
                rep.folded_edges, 100.0 * rep.folded_edges / n_edges, own);
  rep.message += buf;
  logger()->warn("[TemplateFitting] {}", buf);
}

// The warning for FitReport::unexplained: the largest region, where it is, what to do.
void warn_if_unexplained(FitReport& rep) {
  if (rep.unexplained.empty()) return;
  const FitReport::UnexplainedRegion& r = rep.unexplained.front();
  const double d = rep.bbox_diagonal > 0 ? rep.bbox_diagonal : 1;
  char buf[480];
  std::snprintf(buf, sizeof buf,
                "warning: %zu region%s of the cloud %s not explained by the result (the largest: %lld points around (%.4g, %.4g, %.4g), "
                "up to %.2f %% of the diagonal away): a part of the template may have stayed behind (give a marker on it), or "
                "the points are not the object (exclude them with the region of interest). ",
                rep.unexplained.size(), rep.unexplained.size() > 1 ? "s" : "", rep.unexplained.size() > 1 ? "are" : "is",
                static_cast<long long>(r.points), r.centre.x(), r.centre.y(), r.centre.z(), 100 * r.max_distance / d);
  std::string msg = buf;
  if (rep.used.coarse_nodes <= 0 && !rep.coarse_compared)
    msg += "This fit ran without the coarse stage, which turns such parts back (FitParameters::coarse_nodes = 400, "
           "`tbsp fit --coarse-nodes 400`). ";
  rep.message += msg;
  logger()->warn("[TemplateFitting] {}", msg);
}

// The part [lo, hi] of `progress` (empty when `progress` is).
ProgressCallback sub_progress(const ProgressCallback& progress, double lo, double hi) {
  if (!progress) return {};
  return [&progress, lo, hi](double f, const std::string& stage) { return progress(lo + (hi - lo) * f, stage); };
}

// The OpenMP threads a fit may use (1 without OpenMP).
int omp_thread_budget() {
#ifdef _OPENMP
  return std::max(1, omp_get_max_threads());
#else
  return 1;
#endif
}

// With markers and coarse_nodes −1: the fit runs twice, without the coarse stage and with it
// (400 nodes). Both share the initial pose and scale (computed once, on every thread), then run
// side by side on two threads when OpenMP allows more than one (each fit's OpenMP loops on its
// share, and on all of them once the other fit is done; a fit's result does not depend on the
// thread count, so neither does the choice). Both run their pull rounds (with detail rounds: the
// choice is made before them and only the kept fit runs them); kept: the fit from which fewer
// ROI points lie farther than r_max, the fit without the coarse stage unless the other has more
// than 10 points and 1 % fewer (the same points for both, outliers included, so the difference
// is the data one fit explains and the other does not; the margin keeps near-equal fits from
// flipping on rounding, and where the data cannot tell, the template's own shape in holes is
// kept rather than the graph's).
FitReport fit_with_and_without_coarse_stage(const TriMesh& templ, const Eigen::MatrixX3d& P_in, const Eigen::MatrixX3d& N_in,
                                            const std::vector<FitMarker>& markers, const RegionOfInterest& roi, const FitParameters& params,
                                            TriMesh& result, std::vector<VertexStatus>& status, const ProgressCallback& progress,
                                            bool orient_normals) {
  const auto t_all = Clock::now();
  check_fit_inputs(templ, P_in, N_in, params);
  const ScopedBlasThreads blas_threads(1);  // before the workers: their own scopes then keep 1
  SharedWork shared;
  shared.cloud = fit_impl::prepare_cloud(P_in, N_in, roi, params.normal_neighbours);
  const int coarse_nodes = 400;  // the measured setting (docs/fitting.md)
  const bool after_pull = params.detail_rounds == 0;
  std::unique_ptr<FitRun> runs[2];
  Eigen::Index far[2] = {0, 0}, far_surface = 0;
  std::vector<std::exception_ptr> errors(2);
  double fraction[2] = {0, 0}, shown = 0;
  std::mutex m;
  // stop: both fits (the caller asked to, or one failed); skip: the coarse stage's fit is not needed
  std::atomic<bool> stop{false}, skip{false}, caller_stop{false};
  // done: one fit has run its part; the other's next stage takes the whole thread budget
  std::atomic<bool> done{false};
  bool finished[2] = {false, false};  // fit h ran its part (each written by its own thread only)
  const int budget = omp_thread_budget();
  const int omp_each = std::max(1, budget / 2);
  // one bar: the mean of the two fits' fractions, never backwards
  auto progress_of = [&](int h) -> ProgressCallback {
    return [&, h](double f, const std::string& stage) {
#ifdef _OPENMP
      // (called by the fit's own thread between its parallel loops; the thread count does not
      // change a fit's result)
      if (budget >= 2 && done.load() && !omp_in_parallel()) omp_set_num_threads(budget);
#endif
      if (stop.load() || (h == 1 && skip.load())) return false;
      if (!progress) return true;
      std::lock_guard<std::mutex> lock(m);
      fraction[h] = f;
      shown = std::max(shown, 0.5 * (fraction[0] + fraction[1]));
      if (progress(shown, stage)) return true;
      stop = caller_stop = true;
      return false;
    };
  };
  auto work = [&](int h) {
#ifdef _OPENMP
    if (budget >= 2) omp_set_num_threads(omp_each);  // this thread's OpenMP regions only
#endif
    try {
      if (stop.load()) return;
      runs[h]->fitStages();
      if (after_pull) runs[h]->pull();
      far[h] = runs[h]->pointsBeyondMatchDistance();
      // the coarse stage's fit can only be kept with more than 10 points fewer (below), and
      // isolated points do not make it worth running: stray outliers lie far from any fit (a
      // bunny with 10 % of them: ~2,800 points beyond r_max from both fits)
      if (h == 0) far_surface = runs[0]->pointsBeyondMatchDistance(true);  // (a k-d tree query per far point)
      if (h == 0 && far_surface <= 10) skip = true;
      finished[h] = true;
      done = true;
    } catch (...) {
      errors[std::size_t(h)] = std::current_exception();
      if (!(h == 1 && skip.load())) stop = true;
    }
  };
  // what comes before the coarse stage (the initial pose and scale) is the same for both fits:
  // run once, on every thread, and the coarse stage's fit branches off from it
  runs[0] = std::make_unique<FitRun>(templ, P_in, N_in, markers, roi, params, progress_of(0), orient_normals, 0, &shared);
  runs[1] = std::make_unique<FitRun>(*runs[0], coarse_nodes, progress_of(1));
  fraction[1] = fraction[0];
  bool side_by_side = false;
  {
#ifdef _OPENMP
    const int own = omp_get_max_threads();
#endif
    std::thread other;
    if (budget >= 2) {
      try {
        other = std::thread(work, 1);
        side_by_side = true;
      } catch (const std::system_error&) {  // no thread to be had: one after the other
      }
    }
    work(0);
    if (side_by_side) other.join();
    else if (!skip.load()) work(1);
#ifdef _OPENMP
    omp_set_num_threads(own);
#endif
  }
  const bool skipped = skip.load() && !finished[1];  // (it may have finished first)
  if (skipped) far[0] = far_surface;
  if (skipped && !caller_stop.load()) errors[1] = nullptr;  // stopped here, not by the caller
  if (const std::exception_ptr e = first_real_error(errors)) std::rethrow_exception(e);
  // counts within 10 points or 1 % of each other are a tie (scans with many outliers have many
  // points far from both fits, and their count moves with any small change of either)
  const int kept = !skipped && far[1] + std::max<Eigen::Index>(10, far[0] / 100) < far[0] ? 1 : 0;
  fraction[1 - kept] = 1.0;  // the bar follows the kept fit's remaining steps
  FitReport rep = runs[kept]->finish(result, status);
  char buf[400];
  if (skipped)
    std::snprintf(buf, sizeof buf,
                  "%lld of the ROI points that are not isolated lie beyond r_max from the fit without the coarse stage%s: the fit "
                  "with it was %s. ",
                  static_cast<long long>(far[0]), after_pull ? " after the pull rounds" : " before the detail rounds",
                  side_by_side ? "stopped" : "not run");
  else
    std::snprintf(buf, sizeof buf,
                  "fitted without and with the coarse stage (%d nodes)%s: %lld / %lld of the ROI points lie beyond r_max from the "
                  "two fits%s; %s kept. ",
                  runs[1]->coarseNodes(), side_by_side ? " side by side" : "", static_cast<long long>(far[0]), static_cast<long long>(far[1]),
                  after_pull ? " after the pull rounds" : " before the detail rounds", kept ? "the coarse stage's fit" : "the fit without it");
  logger()->info("[TemplateFitting] {}", buf);
  rep.coarse_compared = !skipped;
  if (skipped) rep.coarse_far_points = {far[0]};
  else rep.coarse_far_points = {far[0], far[1]};
  rep.message = buf + rep.message;
  rep.t_total = seconds_since(t_all);
  report_progress(progress, 1.0, "done");
  return rep;
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
  // detail_rounds −1: 4 rounds where they are cheap (a template of at most 20k vertices); a fit
  // without markers runs them on its kept hypothesis only (below)
  params.detail_rounds = params.resolvedDetailRounds(templ.V.rows());
  if (!markerless) {
    // with markers and coarse_nodes −1: the fit without and the fit with the coarse stage, side
    // by side, and the one that explains more of the scan kept (below)
    const bool compare = params_in.coarse_nodes == -1 && params.coarse_nodes == 0 && !params.remeshing;
    TriMesh fitted;
    std::vector<VertexStatus> st;
    FitReport rep;
    if (!compare) {
      FitRun run(templ, P_in, N_in, markers, roi, params, progress, orient_normals, 0);
      rep = run.finish(fitted, st);
    } else {
      rep = fit_with_and_without_coarse_stage(templ, P_in, N_in, markers, roi, params, fitted, st, progress, orient_normals);
    }
    require_a_match(rep, templ, P_in, !markers.empty());
    warn_if_crumpled(rep, templ);
    warn_if_unexplained(rep);
    result = std::move(fitted);
    status = std::move(st);
    return rep;
  }
  const auto t_all = Clock::now();
  // Without markers nothing but nearest points tells the coarse stage where a turned part went,
  // and it can settle in the wrong place; hypotheses whose coarser graphs turn parts as wholes
  // first settle elsewhere, and the data decide (measured: docs/dev/fitting_experiments.md).
  std::vector<int> prepass{0};  // 0: the coarse_nodes graph alone
  if (params.coarse_nodes > 0)
    for (int c : params.coarse_prepass_nodes)
      if (c < params.coarse_nodes && std::find(prepass.begin(), prepass.end(), c) == prepass.end()) prepass.push_back(c);
  const std::size_t nh = prepass.size();
  SharedWork shared;  // the same for every pass and hypothesis
  if (nh == 1) {
    TriMesh fitted;
    std::vector<VertexStatus> st;
    FitReport rep = markerless_fit(templ, P_in, N_in, roi, params, fitted, st, progress, orient_normals, 0, shared);
    require_a_match(rep, templ, P_in, false);
    warn_if_crumpled(rep, templ);
    warn_if_unexplained(rep);
    result = std::move(fitted);
    status = std::move(st);
    if (params.coarse_nodes > 0) {
      rep.coarse_hypotheses = 1;
      rep.coarse_kept = 0;
      rep.coarse_scores = {rep.tail_mean};
    }
    rep.t_total = seconds_since(t_all);
    return rep;
  }
  // The hypotheses are independent fits of the same template to the same cloud: the cloud and
  // the alignment are prepared once, then they run side by side, each on its own thread (its
  // OpenMP loops on its share of the threads; a fit's result does not depend on the thread
  // count, so neither does the choice). Progress is the mean of the hypotheses' fractions.
  check_fit_inputs(templ, P_in, N_in, params);
  const ScopedBlasThreads blas_threads(1);  // before the workers: their own scopes then keep 1
  shared.cloud = fit_impl::prepare_cloud(P_in, N_in, roi, params.normal_neighbours);
  if (params.align_without_markers) {
    shared.alignment = fit_impl::similarity_alignment(*shared.cloud, templ.V);
    const std::string w = fit_impl::alignment_warning(*shared.alignment);
    if (!w.empty()) logger()->warn("[TemplateFitting] {}", w);
  }
  std::vector<FitReport> reps(nh);
  std::vector<TriMesh> results(nh);
  std::vector<std::vector<VertexStatus>> statuses(nh);
  std::vector<std::exception_ptr> errors(nh);
  std::vector<double> fraction(nh, 0.0);
  std::mutex m;
  std::atomic<bool> stop{false};
  std::atomic<std::size_t> next{0};
  auto progress_of = [&](std::size_t h) -> ProgressCallback {
    if (!progress) return [&stop](double, const std::string&) { return !stop.load(); };
    return [&, h](double f, const std::string& stage) {
      if (stop.load()) return false;
      std::lock_guard<std::mutex> lock(m);
      fraction[h] = f;
      double sum = 0;
      for (double x : fraction) sum += x;
      if (progress(sum / double(nh), stage)) return true;
      stop = true;
      return false;
    };
  };
  const int budget = omp_thread_budget();
  // one thread per hypothesis whenever more than one is allowed: three equal fits on two cores
  // take ~1.5 fits' time as three threads, two fits' time as two (bunny without markers, 2026-12-06:
  // 2.45-2.58 s against 3.02-3.05 s; one after the other 3.95-4.06 s)
  const int workers = budget >= 2 ? int(nh) : 1;
  const int omp_each = std::max(1, budget / workers);
  // with detail rounds, each hypothesis stops before them and is scored there; only the kept one
  // runs them (below): one hypothesis's rounds instead of nh
  const bool defer = params.detail_rounds > 0;
  std::vector<DeferredPass> deferred(defer ? nh : 0);
  auto work = [&]() {
#ifdef _OPENMP
    omp_set_num_threads(omp_each);  // this thread's OpenMP regions only
#endif
    for (std::size_t h = next++; h < nh; h = next++) {
      if (stop.load()) break;
      try {
        if (defer) {
          // (the deferred run refers to the callback: it lives in deferred[h], not in a temporary)
          deferred[h].progress = progress_of(h);
          reps[h] = markerless_fit(templ, P_in, N_in, roi, params, results[h], statuses[h], deferred[h].progress, orient_normals,
                                   prepass[h], shared, &deferred[h]);
        } else {
          reps[h] = markerless_fit(templ, P_in, N_in, roi, params, results[h], statuses[h], progress_of(h), orient_normals, prepass[h],
                                   shared);
        }
      } catch (...) {
        errors[h] = std::current_exception();
        stop = true;
      }
    }
  };
  std::size_t started = 1;
  {
#ifdef _OPENMP
    const int own = omp_get_max_threads();
#endif
    std::vector<std::thread> pool;
    for (int t = 1; t < workers; ++t) {
      try {
        pool.emplace_back(work);
      } catch (const std::system_error&) {  // no thread to be had: the threads started take the rest
        break;
      }
    }
    started += pool.size();
    work();
    for (auto& th : pool) th.join();
#ifdef _OPENMP
    omp_set_num_threads(own);
#endif
  }
  if (const std::exception_ptr e = first_real_error(errors)) std::rethrow_exception(e);
  std::vector<double> scores;
  std::size_t kept = 0;
  for (std::size_t h = 0; h < nh; ++h) {
    scores.push_back(reps[h].tail_mean);
    if (reps[h].tail_mean < reps[kept].tail_mean) kept = h;  // ties keep the earlier hypothesis
  }
  if (defer) {
    for (std::size_t h = 0; h < nh; ++h)
      if (h != kept) {
        deferred[h].run.reset();  // (its memory)
        std::lock_guard<std::mutex> lock(m);
        fraction[h] = 1.0;  // the bar follows the kept hypothesis's detail rounds
      }
    DeferredPass& d = deferred[kept];
    if (d.run) {  // (on all threads: the block above gave this thread its own count back)
      reps[kept] = second_pass_report(d.run->finish(results[kept], statuses[kept]), d.first, d.markers.size());
      d.run.reset();
    }
  }
  FitReport rep = std::move(reps[kept]);
  require_a_match(rep, templ, P_in, false);
  warn_if_crumpled(rep, templ);
  warn_if_unexplained(rep);
  result = std::move(results[kept]);
  status = std::move(statuses[kept]);
  rep.coarse_hypotheses = int(nh);
  rep.coarse_kept = int(kept);
  rep.coarse_scores = scores;
  std::string msg = std::to_string(nh) + " coarse-stage hypotheses" +
                    (started > 1 ? " (side by side on " + std::to_string(started) + " threads)" : std::string()) +
                    ", mean of the farthest 1 % of the cloud:";
  char buf[96];
  for (std::size_t h = 0; h < nh; ++h) {
    if (h == 0) std::snprintf(buf, sizeof buf, " %.4g with the %d-node graph alone", scores[h], params.coarse_nodes);
    else std::snprintf(buf, sizeof buf, ", %.4g with a %d-node graph first", scores[h], prepass[h]);
    msg += buf;
  }
  if (kept == 0) std::snprintf(buf, sizeof buf, "; kept: the %d-node graph alone. ", params.coarse_nodes);
  else std::snprintf(buf, sizeof buf, "; kept: a %d-node graph first. ", prepass[kept]);
  rep.message += msg + buf;
  rep.t_total = seconds_since(t_all);
  return rep;
}

namespace {

// Without markers: the aligned fit, then its matched vertices as markers of a second fit.
FitReport markerless_fit(const TriMesh& templ, const Eigen::MatrixX3d& P_in, const Eigen::MatrixX3d& N_in, const RegionOfInterest& roi,
                         const FitParameters& params, TriMesh& result, std::vector<VertexStatus>& status, const ProgressCallback& progress,
                         bool orient_normals, int coarse_prepass, SharedWork& shared, DeferredPass* defer) {
  const auto t_all = Clock::now();
  FitParameters first = params;
  first.pull_rounds = 0;    // the second pass pulls
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
  if (defer) {
    // the second pass up to its detail rounds; the returned report carries its score only
    defer->markers = std::move(auto_markers);
    defer->first = rep1;
    defer->run = std::make_unique<FitRun>(templ, P_in, N_in, defer->markers, roi, params, sub_progress(progress, 0.4, 1.0), orient_normals,
                                          coarse_prepass, &shared, true);
    defer->run->fitStages();
    FitReport score;
    score.tail_mean = defer->run->tailMean();
    return score;
  }
  FitReport rep = fit_once(templ, P_in, N_in, auto_markers, roi, params, result, status, sub_progress(progress, 0.4, 1.0), orient_normals,
                           coarse_prepass, &shared, true);
  FitReport out = second_pass_report(std::move(rep), rep1, auto_markers.size());
  out.t_total = seconds_since(t_all);
  return out;
}

// The second pass's report of a fit without markers, with the first pass's alignment.
FitReport second_pass_report(FitReport rep, const FitReport& rep1, std::size_t n_markers) {
  rep.aligned_without_markers = true;
  rep.alignment = rep1.alignment;
  rep.alignment_rotation_deg = rep1.alignment_rotation_deg;
  rep.alignment_scale = rep1.alignment_scale;
  rep.alignment_rms = rep1.alignment_rms;
  rep.alignment_iterations = rep1.alignment_iterations;
  rep.auto_markers = int(n_markers);
  rep.t_alignment = rep1.t_total;  // the whole first pass
  rep.message = rep1.message + "second pass with " + std::to_string(n_markers) + " markers taken from the aligned fit. " + rep.message;
  return rep;
}

FitRun::FitRun(const TriMesh& templ, const Eigen::MatrixX3d& P_in, const Eigen::MatrixX3d& N_in, const std::vector<FitMarker>& markers,
               const RegionOfInterest& roi, const FitParameters& params, ProgressCallback progress, bool orient_normals,
               int coarse_prepass, SharedWork* shared, bool markers_from_fit)
    : t_all_(Clock::now()), blas_threads_(1), progress_(std::move(progress)) {
  // (one BLAS thread: no contention with our OpenMP loops, blas_threads.h)
  check_fit_inputs(templ, P_in, N_in, params);
  report_progress(progress_, 0.0, "prepare");
  std::optional<fit_impl::PreparedCloud>& cloud = shared ? shared->cloud : own_;
  if (!cloud) cloud = fit_impl::prepare_cloud(P_in, N_in, roi, params.normal_neighbours);
  s_ = std::make_unique<fit_impl::FitState>(templ, markers, progress_, rep_, status_, *cloud);
  fit_impl::FitState& s = *s_;
  s.coarse_prepass = coarse_prepass;
  s.markers_from_fit = markers_from_fit;
  s.alignment_cache = shared ? &shared->alignment : nullptr;
  fit_impl::use_cloud(s, params, orient_normals);
  fit_impl::prepare_markers(s, P_in, roi);
  if (markers.empty() && params.align_without_markers) {  // a template roughly in place: similarity alignment first
    report_progress(progress_, 0.03, "alignment");
    fit_impl::align_without_markers(s, aligned_);
    s.useTemplate(aligned_);
  }
  fit_impl::initial_pose(s);  // stage 1 (+ global scale)
  fit_impl::orient_cloud_normals(s);
}

FitRun::FitRun(const FitRun& from, int coarse_nodes, ProgressCallback progress)
    : t_all_(from.t_all_), blas_threads_(1), progress_(std::move(progress)), rep_(from.rep_), status_(from.status_),
      aligned_(from.aligned_) {
  if (from.staged_) throw std::logic_error("FitRun: a fit branches off before its stages");
  s_ = std::make_unique<fit_impl::FitState>(*from.s_, progress_, rep_, status_);
  if (&from.s_->templ() == &from.aligned_) s_->useTemplate(aligned_);
  rep_.used.coarse_nodes = coarse_nodes;
}

void FitRun::fitStages() {
  if (staged_) return;
  fit_impl::FitState& s = *s_;
  fit_impl::coarse_stage(s);
  fit_impl::iterate_fit(s);              // stage 2
  fit_impl::propagate_displacements(s);  // stage 3
  staged_ = true;
}

void FitRun::pull() {
  if (pulled_) return;
  fitStages();
  fit_impl::detail_rounds(*s_);
  fit_impl::pull_rounds(*s_);
  pulled_ = true;
}

Eigen::Index FitRun::pointsBeyondMatchDistance(bool surface_only) const {
  const fit_impl::RoiDistances& r = fit_impl::roi_distances(*s_);
  Eigen::Index n = 0;
  for (Eigen::Index i = 0; i < r.d.size(); ++i)
    n += r.d(i) > s_->u.max_match_distance && (!surface_only || fit_impl::is_surface_point(s_->cloud, r.Q.row(i).transpose()));
  return n;
}

double FitRun::tailMean() const {
  const Eigen::VectorXd& d = fit_impl::roi_distances(*s_).d;
  return fit_impl::tail_mean(std::vector<double>(d.data(), d.data() + d.size()));
}

FitReport FitRun::finish(TriMesh& result, std::vector<VertexStatus>& status) {
  fit_impl::FitState& s = *s_;
  pull();
  const int known_crossings = fit_impl::repair_surface(s);
  fit_impl::compute_metrics(s, known_crossings);
  result.V = s.V;
  result.F = s.F;
  result.N.resize(0, 3);
  result.C.resize(0, 3);
  rep_.t_total = seconds_since(t_all_);
  report_progress(progress_, 1.0, "done");
  status = status_;
  return rep_;
}

FitReport fit_once(const TriMesh& templ, const Eigen::MatrixX3d& P_in, const Eigen::MatrixX3d& N_in,
                   const std::vector<FitMarker>& markers, const RegionOfInterest& roi, const FitParameters& params,
                   TriMesh& result, std::vector<VertexStatus>& status, const ProgressCallback& progress,
                   bool orient_normals, int coarse_prepass, SharedWork* shared, bool markers_from_fit) {
  FitRun run(templ, P_in, N_in, markers, roi, params, progress, orient_normals, coarse_prepass, shared, markers_from_fit);
  return run.finish(result, status);
}

}  // namespace

}  // namespace tbsp
