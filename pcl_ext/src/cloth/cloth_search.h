// Internal: the two material searches of ClothParameterEstimation (thesis §10.7) on the unit cube,
// independent of the cloth energy so that they can be tested on analytic functions.
#pragma once

#include <array>
#include <cstdint>
#include <functional>
#include <map>
#include <vector>

namespace tbsp::detail {

/// A point of the unit cube [0, 1]³ (each axis of ρ scaled to the search box).
using UnitPoint = std::array<double, 3>;

/// Evaluates a batch of points (in parallel where it can) and returns E per point, in order.
using BatchEnergy = std::function<std::vector<double>(const std::vector<UnitPoint>&)>;

/// Memoizes a deterministic BatchEnergy: a point evaluated before is answered from the memo (a
/// BOBYQA restart evaluates its start point again); counts the evaluations actually made and keeps
/// the best point (the first of equal energies).
class MemoEnergy {
public:
  explicit MemoEnergy(BatchEnergy f) : f_(std::move(f)) {}
  std::vector<double> operator()(const std::vector<UnitPoint>& points);
  double operator()(const UnitPoint& p) { return (*this)(std::vector<UnitPoint>{p}).front(); }
  int evaluations() const { return count_; }
  const UnitPoint& best() const { return best_; }
  double bestEnergy() const { return best_energy_; }

private:
  BatchEnergy f_;
  std::map<UnitPoint, double> seen_;
  int count_ = 0;
  UnitPoint best_{0.5, 0.5, 0.5};
  double best_energy_ = 0;
};

/// The thesis' search: a K³ grid at the cell centres, then `greedy_samples` samples from
/// N(current, q(n)·σ₁) with q falling linearly from 1 to 0 and σ₁ = 1/K, clamped to the cube, each
/// replacing the current particle when lower; drawn in batches of `batch` around the particle as
/// it was before the batch (so the result depends on `batch`; the random numbers do not).
/// Returns the mean of the last ten particles (not evaluated; the grid's best when
/// greedy_samples = 0).
UnitPoint thesis_search(MemoEnergy& energy, int grid_k, int greedy_samples, std::uint64_t seed, int batch);

/// Ours: the cube's centre + (start_samples − 1) points of a scrambled 3-D Halton set (digit
/// permutations from `seed`) in one batch, then NLopt BOBYQA from the best point with a trust
/// region of 0.25 until steps fall below `tolerance`, then up to two restarts from the best with a
/// 4× smaller region while they improve; at most `max_evaluations` evaluations in all. Returns the
/// best point evaluated. Rethrows what the energy throws.
UnitPoint bobyqa_search(MemoEnergy& energy, int start_samples, int max_evaluations, double tolerance, std::uint64_t seed);

}  // namespace tbsp::detail
