// The thesis' grid + greedy stochastic search and ours (a start design, then NLopt BOBYQA with
// restarts) on the unit cube (cloth_search.h).
#include "cloth_search.h"

#include <algorithm>
#include <cmath>
#include <exception>
#include <random>

#include <nlopt.h>

namespace tbsp::detail {

std::vector<double> MemoEnergy::operator()(const std::vector<UnitPoint>& points) {
  std::vector<UnitPoint> todo;
  for (const UnitPoint& p : points)
    if (!seen_.count(p) && std::find(todo.begin(), todo.end(), p) == todo.end()) todo.push_back(p);
  if (!todo.empty()) {
    const std::vector<double> e = f_(todo);
    for (std::size_t i = 0; i < todo.size(); ++i) {
      seen_[todo[i]] = e[i];
      if (count_ + int(i) == 0 || e[i] < best_energy_) {
        best_energy_ = e[i];
        best_ = todo[i];
      }
    }
    count_ += int(todo.size());
  }
  std::vector<double> out;
  out.reserve(points.size());
  for (const UnitPoint& p : points) out.push_back(seen_.at(p));
  return out;
}

UnitPoint thesis_search(MemoEnergy& energy, int K, int n, std::uint64_t seed, int batch) {
  std::vector<UnitPoint> grid;
  for (int i = 0; i < K; ++i)
    for (int j = 0; j < K; ++j)
      for (int k = 0; k < K; ++k) grid.push_back({(i + 0.5) / K, (j + 0.5) / K, (k + 0.5) / K});
  energy(grid);
  UnitPoint cur = energy.best();
  double cur_e = energy.bestEnergy();
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> N01(0.0, 1.0);
  const double sigma1 = 1.0 / K;
  const int B = std::max(batch, 1);
  std::vector<UnitPoint> particles;  // ρ_n for every iteration n
  for (int it = 0; it < n;) {
    const int b = std::min(B, n - it);
    std::vector<UnitPoint> draws;
    for (int s = 0; s < b; ++s) {
      const double q = n > 1 ? 1.0 - double(it + s) / double(n - 1) : 1.0;
      UnitPoint u;
      for (std::size_t d = 0; d < 3; ++d) u[d] = std::clamp(cur[d] + q * sigma1 * N01(rng), 0.0, 1.0);
      draws.push_back(u);
    }
    const std::vector<double> e = energy(draws);
    for (int s = 0; s < b; ++s) {  // the best of a batch competes with the current particle
      if (e[std::size_t(s)] < cur_e) {
        cur_e = e[std::size_t(s)];
        cur = draws[std::size_t(s)];
      }
      particles.push_back(cur);
    }
    it += b;
  }
  if (particles.empty()) return cur;
  UnitPoint mean{0, 0, 0};
  const std::size_t last = std::min<std::size_t>(10, particles.size());
  for (std::size_t i = particles.size() - last; i < particles.size(); ++i)
    for (std::size_t d = 0; d < 3; ++d) mean[d] += particles[i][d] / double(last);
  return mean;
}

namespace {

// Radical inverse in base b with a digit permutation (a "scrambled" Halton set: one random
// permutation of the digits per base, from the seed): well spread for a handful of points.
double radical_inverse(int i, int base, const std::vector<int>& perm) {
  double f = 1.0, r = 0.0;
  for (int n = i; n > 0; n /= base) {
    f /= base;
    r += f * perm[std::size_t(n % base)];
  }
  return r;
}

struct NloptData {
  MemoEnergy* energy;
  std::exception_ptr error;
};

double nlopt_objective(unsigned, const double* x, double*, void* data) {
  auto* d = static_cast<NloptData*>(data);
  try {
    return (*d->energy)(UnitPoint{x[0], x[1], x[2]});
  } catch (...) {
    d->error = std::current_exception();
    return HUGE_VAL;
  }
}

}  // namespace

UnitPoint bobyqa_search(MemoEnergy& energy, int start_samples, int max_evaluations, double tolerance, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::vector<UnitPoint> design{{0.5, 0.5, 0.5}};
  std::array<std::vector<int>, 3> perm;
  const int bases[3] = {2, 3, 5};
  for (std::size_t d = 0; d < 3; ++d) {
    perm[d].resize(std::size_t(bases[d]));
    for (int i = 0; i < bases[d]; ++i) perm[d][std::size_t(i)] = i;
    std::shuffle(perm[d].begin() + 1, perm[d].end(), rng);  // keep 0 -> 0
  }
  for (int i = 1; int(design.size()) < start_samples; ++i)
    design.push_back({radical_inverse(i, 2, perm[0]), radical_inverse(i, 3, perm[1]), radical_inverse(i, 5, perm[2])});
  energy(design);
  // BOBYQA from the best point, restarted there with a trust region a quarter of the last one
  // while the previous round improved and the budget lasts: a round stops when its model says the
  // minimum is found (steps below the tolerance), but on a landscape with small-scale noise a
  // smaller trust region still finds lower values nearby.
  const double lo[3] = {0, 0, 0}, hi[3] = {1, 1, 1};
  double radius = 0.25;
  for (int round = 0; round < 3 && energy.evaluations() < max_evaluations; ++round, radius *= 0.25) {
    const double before = energy.bestEnergy();
    nlopt_opt opt = nlopt_create(NLOPT_LN_BOBYQA, 3);
    const double step[3] = {radius, radius, radius};
    NloptData data{&energy, nullptr};
    nlopt_set_lower_bounds(opt, lo);
    nlopt_set_upper_bounds(opt, hi);
    nlopt_set_min_objective(opt, nlopt_objective, &data);
    // NLopt counts memoized answers too: the budget in new evaluations is at least this
    nlopt_set_maxeval(opt, max_evaluations - energy.evaluations());
    nlopt_set_xtol_abs1(opt, std::min(tolerance, 0.25 * radius));
    nlopt_set_initial_step(opt, step);
    UnitPoint x = energy.best();
    double f = 0;
    nlopt_optimize(opt, x.data(), &f);
    nlopt_destroy(opt);
    if (data.error) std::rethrow_exception(data.error);
    if (round > 0 && !(energy.bestEnergy() < before)) break;
  }
  return energy.best();
}

}  // namespace tbsp::detail
