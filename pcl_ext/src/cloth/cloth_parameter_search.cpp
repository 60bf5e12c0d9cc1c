// The searches of ClothParameterEstimation (thesis §10.7): the thesis' grid + greedy stochastic
// search, and ours (a parallel start design, then NLopt BOBYQA). ρ is searched in the unit cube
// (each axis scaled to the options' box).
#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <random>

#include <nlopt.h>
#ifdef _OPENMP
#include <omp.h>
#endif

#include "tbsp/cloth/cloth_parameter_estimation.h"
#include "tbsp/core/error.h"

namespace tbsp {

namespace {

using Unit = std::array<double, 3>;

ClothMaterial from_unit(const Unit& u, const ClothEstimationOptions& o) {
  ClothMaterial m;
  m.d_n = o.lower.d_n + u[0] * (o.upper.d_n - o.lower.d_n);
  m.d_t = o.lower.d_t + u[1] * (o.upper.d_t - o.lower.d_t);
  m.k_bend = o.lower.k_bend + u[2] * (o.upper.k_bend - o.lower.k_bend);
  return m;
}

// Radical inverse in base b with a digit permutation (Owen-free "scrambled" Halton: one random
// permutation of the digits per base, from the seed): well spread for a handful of points.
double radical_inverse(int i, int base, const std::vector<int>& perm) {
  double f = 1.0, r = 0.0;
  for (int n = i; n > 0; n /= base) {
    f /= base;
    r += f * perm[std::size_t(n % base)];
  }
  return r;
}

// Evaluates a batch of unit-cube samples in parallel, appends them to the log, reports progress.
class Evaluator {
public:
  Evaluator(const ClothParameterEstimation& est, int region, std::vector<ClothSample>& log, const ProgressCallback& progress, int budget)
      : est_(est), region_(region), log_(log), progress_(progress), budget_(std::max(budget, 1)) {}

  std::vector<double> operator()(const std::vector<Unit>& us) {
    std::vector<ClothMaterial> rhos;
    for (const Unit& u : us) rhos.push_back(from_unit(u, est_.options()));
    const std::vector<ClothFitEnergy> es = est_.evaluate(region_, rhos);
    std::vector<double> out;
    for (std::size_t i = 0; i < us.size(); ++i) {
      log_.push_back({region_, rhos[i], es[i]});
      out.push_back(es[i].e_fit);
      if (es[i].e_fit < best_energy_.e_fit || count_ + int(i) == 0) {
        best_energy_ = es[i];
        best_ = us[i];
      }
    }
    count_ += int(us.size());
    if (progress_ && !progress_(std::min(1.0, double(count_) / budget_), "cloth region " + std::to_string(region_) + ": " + std::to_string(count_) + " simulations"))
      throw Cancelled("[tbsp::ClothParameterEstimation] cancelled");
    return out;
  }
  double operator()(const Unit& u) { return (*this)(std::vector<Unit>{u}).front(); }

  int count() const { return count_; }
  const Unit& best() const { return best_; }
  double bestEnergy() const { return best_energy_.e_fit; }
  const ClothFitEnergy& bestTerms() const { return best_energy_; }

private:
  const ClothParameterEstimation& est_;
  int region_;
  std::vector<ClothSample>& log_;
  const ProgressCallback& progress_;
  int budget_, count_ = 0;
  Unit best_{0.5, 0.5, 0.5};
  ClothFitEnergy best_energy_;
};

int batch_size() {
#ifdef _OPENMP
  return std::max(1, omp_get_max_threads());
#else
  return 1;
#endif
}

// Thesis: K³ grid, then n_sam greedy samples from N(best, q(n)·σ₁), q falling linearly from 1 to 0,
// σ₁ = the grid spacing; the mean of the last ten particles. In batches of (threads) samples drawn
// from the same distribution, the best of a batch competing with the current particle (the same
// number of simulations as one-at-a-time; the batch size does not change the draws).
Unit thesis_search(Evaluator& eval, const ClothEstimationOptions& o) {
  const int K = o.grid_k;
  std::vector<Unit> grid;
  for (int i = 0; i < K; ++i)
    for (int j = 0; j < K; ++j)
      for (int k = 0; k < K; ++k) grid.push_back({(i + 0.5) / K, (j + 0.5) / K, (k + 0.5) / K});
  eval(grid);
  Unit cur = eval.best();
  double cur_e = eval.bestEnergy();
  std::mt19937_64 rng(o.seed);
  std::normal_distribution<double> N01(0.0, 1.0);
  const double sigma1 = 1.0 / K;
  const int n = o.greedy_samples, B = batch_size();
  std::vector<Unit> particles;  // ρ_n for every iteration n
  for (int it = 0; it < n;) {
    const int b = std::min(B, n - it);
    std::vector<Unit> draws;
    for (int s = 0; s < b; ++s) {
      const double q = n > 1 ? 1.0 - double(it + s) / double(n - 1) : 1.0;
      Unit u;
      for (int d = 0; d < 3; ++d) u[std::size_t(d)] = std::clamp(cur[std::size_t(d)] + q * sigma1 * N01(rng), 0.0, 1.0);
      draws.push_back(u);
    }
    const std::vector<double> e = eval(draws);
    for (int s = 0; s < b; ++s) {
      if (e[std::size_t(s)] < cur_e) {
        cur_e = e[std::size_t(s)];
        cur = draws[std::size_t(s)];
      }
      particles.push_back(cur);
    }
    it += b;
  }
  if (particles.empty()) return cur;
  Unit mean{0, 0, 0};
  const std::size_t last = std::min<std::size_t>(10, particles.size());
  for (std::size_t i = particles.size() - last; i < particles.size(); ++i)
    for (int d = 0; d < 3; ++d) mean[std::size_t(d)] += particles[i][std::size_t(d)] / double(last);
  return mean;
}

struct NloptData {
  Evaluator* eval;
  std::exception_ptr error;
};

double nlopt_objective(unsigned, const double* x, double*, void* data) {
  auto* d = static_cast<NloptData*>(data);
  try {
    return (*d->eval)(Unit{x[0], x[1], x[2]});
  } catch (...) {
    d->error = std::current_exception();
    return HUGE_VAL;
  }
}

// Ours: the box centre + (start_samples − 1) scrambled Halton points in parallel, then BOBYQA from
// the best with a trust region of a quarter of the box, until max_evaluations or the tolerance.
Unit bobyqa_search(Evaluator& eval, const ClothEstimationOptions& o) {
  std::mt19937_64 rng(o.seed);
  std::vector<Unit> design{{0.5, 0.5, 0.5}};
  std::array<std::vector<int>, 3> perm;
  const int bases[3] = {2, 3, 5};
  for (int d = 0; d < 3; ++d) {
    perm[std::size_t(d)].resize(std::size_t(bases[d]));
    for (int i = 0; i < bases[d]; ++i) perm[std::size_t(d)][std::size_t(i)] = i;
    std::shuffle(perm[std::size_t(d)].begin() + 1, perm[std::size_t(d)].end(), rng);  // keep 0 -> 0
  }
  for (int i = 1; int(design.size()) < o.start_samples; ++i)
    design.push_back({radical_inverse(i, 2, perm[0]), radical_inverse(i, 3, perm[1]), radical_inverse(i, 5, perm[2])});
  eval(design);
  const int left = o.max_evaluations - eval.count();
  if (left < 1) return eval.best();
  nlopt_opt opt = nlopt_create(NLOPT_LN_BOBYQA, 3);
  const double lo[3] = {0, 0, 0}, hi[3] = {1, 1, 1}, step[3] = {0.25, 0.25, 0.25};
  NloptData data{&eval, nullptr};
  nlopt_set_lower_bounds(opt, lo);
  nlopt_set_upper_bounds(opt, hi);
  nlopt_set_min_objective(opt, nlopt_objective, &data);
  nlopt_set_maxeval(opt, left);
  nlopt_set_xtol_abs1(opt, o.tolerance);
  nlopt_set_initial_step(opt, step);
  Unit x = eval.best();
  double f = 0;
  nlopt_optimize(opt, x.data(), &f);
  nlopt_destroy(opt);
  if (data.error) std::rethrow_exception(data.error);
  return eval.best();
}

}  // namespace

ClothRegionEstimate ClothParameterEstimation::estimateRegion(int region, std::vector<ClothSample>& samples) {
  checkRegion(region);
  const auto t0 = std::chrono::steady_clock::now();
  const ClothEstimationOptions& o = options_;
  const int budget = o.search == ClothSearch::Thesis ? o.grid_k * o.grid_k * o.grid_k + o.greedy_samples + 1 : o.max_evaluations;
  Evaluator eval(*this, region, samples, progress_, budget);
  ClothRegionEstimate r;
  r.region = region;
  if (o.search == ClothSearch::Thesis) {
    const Unit u = thesis_search(eval, o);
    r.rho = from_unit(u, o);
    r.energy = evaluate(region, r.rho);  // the mean particle was not simulated
    samples.push_back({region, r.rho, r.energy});
    r.simulations = eval.count() + 1;
  } else {
    bobyqa_search(eval, o);
    r.rho = from_unit(eval.best(), o);
    r.energy = eval.bestTerms();
    r.simulations = eval.count();
  }
  r.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  model_.materials[std::size_t(region)] = r.rho;
  return r;
}

ClothEstimationResult ClothParameterEstimation::estimate() {
  const auto t0 = std::chrono::steady_clock::now();
  ClothEstimationResult res;
  for (int r = 0; r < numRegions(); ++r) {
    res.regions.push_back(estimateRegion(r, res.samples));
    res.simulations += res.regions.back().simulations;
  }
  res.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return res;
}

}  // namespace tbsp
