// ClothParameterEstimation's searches (thesis §10.7) on its energy: ρ is searched in the unit cube
// (each axis scaled to the options' box) by the searches of cloth_search.h; every sample is logged.
#include <algorithm>
#include <chrono>
#include <cmath>

#include "tbsp/cloth/cloth_parameter_estimation.h"
#include "tbsp/core/error.h"
#include "cloth_search.h"

namespace tbsp {

namespace {

using Unit = detail::UnitPoint;

ClothMaterial from_unit(const Unit& u, const ClothEstimationOptions& o) {
  ClothMaterial m;
  m.d_n = o.lower.d_n + u[0] * (o.upper.d_n - o.lower.d_n);
  m.d_t = o.lower.d_t + u[1] * (o.upper.d_t - o.lower.d_t);
  m.k_bend = o.lower.k_bend + u[2] * (o.upper.k_bend - o.lower.k_bend);
  return m;
}

}  // namespace

ClothRegionEstimate ClothParameterEstimation::estimateRegion(int region, std::vector<ClothSample>& samples) {
  checkRegion(region);
  const auto t0 = std::chrono::steady_clock::now();
  const ClothEstimationOptions& o = options_;
  const int budget = o.search == ClothSearch::Thesis ? o.grid_k * o.grid_k * o.grid_k + o.greedy_samples + 1 : o.max_evaluations;
  int count = 0;
  ClothFitEnergy best;
  // The energy of a batch: simulated in parallel, logged, reported; cancellation throws.
  detail::MemoEnergy energy([&](const std::vector<Unit>& us) {
    std::vector<ClothMaterial> rhos;
    for (const Unit& u : us) rhos.push_back(from_unit(u, o));
    const std::vector<ClothFitEnergy> es = evaluate(region, rhos);
    std::vector<double> out;
    for (std::size_t i = 0; i < us.size(); ++i) {
      samples.push_back({region, rhos[i], es[i]});
      if (count + int(i) == 0 || es[i].e_fit < best.e_fit) best = es[i];
      out.push_back(es[i].e_fit);
    }
    count += int(us.size());
    bool stop = progress_ && !progress_(std::min(1.0, double(count) / std::max(budget, 1)),
                                        "cloth region " + std::to_string(region) + ": " + std::to_string(count) + " simulations");
    if (share_.size > 1) {  // a cancel on any process stops every process here
      std::vector<double> v{stop ? 1.0 : 0.0};
      share_.sum(v);
      stop = v[0] > 0;
    }
    if (stop) throw Cancelled("[tbsp::ClothParameterEstimation] cancelled");
    return out;
  });
  ClothRegionEstimate r;
  r.region = region;
  if (o.search == ClothSearch::Thesis) {
    const Unit u = detail::thesis_search(energy, o.grid_k, o.greedy_samples, o.seed, o.greedy_batch);
    r.rho = from_unit(u, o);
    r.energy = evaluate(region, r.rho);  // the mean particle was not simulated
    samples.push_back({region, r.rho, r.energy});
    r.simulations = energy.evaluations() + 1;
  } else {
    detail::bobyqa_search(energy, o.start_samples, o.max_evaluations, o.tolerance, o.seed);
    r.rho = from_unit(energy.best(), o);
    r.energy = best;
    r.simulations = energy.evaluations();
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
