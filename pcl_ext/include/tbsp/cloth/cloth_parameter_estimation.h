#pragma once
/// \file cloth_parameter_estimation.h
/// \brief Cloth material estimation from a studio recording (thesis §10.7): the material
/// ρ = (d_n, d_t, k_bend) of each cloth region of an AnimatableModel is the one whose forward
/// simulation, driven by the recorded skeleton motion, best explains the videos:
///
///   E_fit(ρ) = 1/N Σ_n ( α E_sil(ρ, n) + β E_sift(ρ, n) )                        (eq. 10.6)
///
/// - E_sil (eq. 10.7): mean over the region's silhouette rim vertices in all views (rendered with
///   the Rasterizer, rim_vertices) of the squared image distance to the nearest boundary pixel of
///   the measured silhouette;
/// - E_sift (eq. 10.8): every SIFT correspondence (frame n − 1 → n, ClothObservations) whose
///   frame n − 1 pixel lies on the region's simulated cloth is lifted to that surface point
///   (triangle + barycentrics), carried to frame n by the simulation and reprojected; mean of the
///   squared distances to the feature's measured position at n.
/// Simulation: ModelAnimator; by default in windows of 10 frames restarted from the reference
/// mesh sequence (see `window`: our change against chaos), or the whole sequence (the thesis).
/// Squared distances are capped at `max_pixel_error`² (our addition: one rim vertex next to a
/// far-away boundary or one mismatched feature otherwise dominates a frame).
///
/// Searches: the thesis' (K³ grid + n_sam greedy stochastic samples around the best, σ shrinking
/// linearly to 0, the mean of the last ten particles returned) and ours: a small space-filling
/// start design evaluated in parallel, then NLopt's BOBYQA (Powell's bound-constrained quadratic
/// model, derivative-free) from its best sample, restarted from its end with a 4× smaller trust
/// region (up to twice, while that improves) — 6.6× fewer simulations than the thesis' search, a
/// nearer k_bend, E_fit within a few % of it (docs/cloth.md). Samples and windows run in parallel (one simulation per
/// thread; each is deterministic, so the result does not depend on the thread count), and over
/// several processes with setWorkShare.
///
/// Library: tbsp::multiview (links OpenCV and NLopt; libtbsp stays free of both).
/// Cost: one simulation of the whole sequence plus one rendering of every view per evaluated
/// frame per sample. Errors: InvalidInput (pose count ≠ frame count, a region without cloth,
/// invalid options or model), Cancelled (progress callback returned false).

#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "tbsp/cloth/animatable_model.h"
#include "tbsp/cloth/cloth_observations.h"
#include "tbsp/core/progress.h"

namespace tbsp {

enum class ClothSearch {
  Thesis,  ///< K³ grid + greedy stochastic samples (§10.7)
  Bobyqa,  ///< start design + NLopt BOBYQA (ours, default)
};

struct ClothEstimationOptions {
  double alpha = 1.0;            ///< weight of E_sil, ≥ 0 (thesis 1)
  double beta = 10.0;            ///< weight of E_sift, ≥ 0 (thesis 10)
  double max_pixel_error = 20;   ///< residual cap, pixels, > 0
  double clothness_min = 0.5;    ///< a vertex belongs to a region's cloth when δ ≥ this, (0, 1]
  int frame_stride = 1;          ///< E is evaluated on every n-th frame (the simulation runs every frame), 1..1000; thesis 1
  /// Frames per simulation window, 0..10000. 0 = the thesis: one simulation of the whole sequence
  /// from the settled first pose. > 0 (default 10): the simulation restarts every `window` frames
  /// from the reference sequence's state (positions, velocities by finite differences; needs
  /// setReferenceSequence); a window's first frame is its restart state and is not scored.
  /// Cloth simulation is chaotic — changing d_t by 0.1 % moves a skirt by 1.3 cm on average after
  /// 50 frames — so whole-sequence E_fit is a noisy landscape whose minimum a search finds only by
  /// chance. Shorter windows are smoother but see less: 10 frames leave needles of ±5 % at k_bend
  /// steps of 0.005 and keep the soft side of the k_bend valley; 5 frames are smooth to ±0.3 % but
  /// lost that side on a 60-frame sequence (k_bend 0.07 for a true 0.6, against 0.49 with 10);
  /// same simulation cost (docs/dev/cloth_experiments.md).
  int window = 10;
  /// Restart phases, 1..max(window, 1) (default 1): the window grid is laid this many times,
  /// shifted by window·p/phases frames, and E_fit averages every scored frame of every phase, which
  /// averages the chaotic part of E_fit at phases × the simulation cost.
  int window_phases = 1;
  int settle_frames = 40;        ///< frames the cloth settles in the first pose, ≥ 0
  ClothMaterial lower{0.0, 0.0, 0.0};    ///< search box (thesis: d_n ∈ [0, 10], d_t ∈ [0, 50], k_bend ∈ [0, 1])
  ClothMaterial upper{10.0, 50.0, 1.0};
  ClothSearch search = ClothSearch::Bobyqa;
  int grid_k = 4;                ///< Thesis: K, grid samples per axis, 1..10
  int greedy_samples = 192;      ///< Thesis: n_sam, ≥ 0
  /// Thesis: greedy samples drawn — and simulated in parallel — per batch, 1..1000. A sample
  /// competes with the current particle after its batch, so the result depends on this (and on
  /// nothing else: not on the thread or process count). 1 = the thesis' strictly sequential
  /// greedy search; 2 = the figures of docs/cloth.md. A batch's windows run in parallel anyway.
  int greedy_batch = 2;
  int start_samples = 8;         ///< Bobyqa: start design size (a scrambled 3-D Halton set + the box centre), 1..1000
  int max_evaluations = 40;      ///< Bobyqa: simulations in all (start design included), ≥ start_samples
  double tolerance = 0.01;       ///< Bobyqa: a round stops when a step changes ρ by less than this share of the box (restarts: min(this, region/4)), > 0
  std::uint64_t seed = 1;        ///< random choices (Halton scrambling, greedy samples)

  bool isValid(std::string* why = nullptr) const;
};

/// The terms of E_fit for one sample.
struct ClothFitEnergy {
  double e_fit = 0;       ///< eq. 10.6
  double e_sil = 0;       ///< mean over frames of E_sil (pixels²)
  double e_sift = 0;      ///< mean over frames of E_sift (pixels²)
  long rim_samples = 0;   ///< rim vertices counted, all frames and views
  long feature_samples = 0;
  int frames = 0;         ///< frames evaluated
};

struct ClothSample {
  int region = 0;
  ClothMaterial rho;
  ClothFitEnergy energy;
};

struct ClothRegionEstimate {
  int region = 0;
  ClothMaterial rho;          ///< the estimate
  ClothFitEnergy energy;      ///< E_fit at the estimate
  int simulations = 0;        ///< samples simulated for this region
  double seconds = 0;
};

struct ClothEstimationResult {
  std::vector<ClothRegionEstimate> regions;
  std::vector<ClothSample> samples;  ///< every sample, in evaluation order
  int simulations = 0;
  double seconds = 0;
};

/// Sharing the simulations among cooperating processes (MPI ranks: `tbsp cloth estimate` under
/// mpirun). Every process runs the same estimation; the simulations of each evaluation — one per
/// (sample, window) — are dealt round-robin: process `rank` runs those whose index ≡ rank
/// (mod size), on its own threads, and `sum` combines the processes' results, so every process
/// goes on with all of them: bit for bit what one process computes, whatever the process and
/// thread counts. An error in any simulation is thrown on every process, with the same type and
/// message; so is a cancel (the progress callback returning false on any process).
struct ClothWorkShare {
  int rank = 0;  ///< this process, 0..size − 1
  int size = 1;  ///< cooperating processes, ≥ 1
  /// Collective, needed when size > 1: every process calls it at the same point with a vector of
  /// the same length; on return each holds the elementwise sum over all processes
  /// (MPI_Allreduce with MPI_SUM). Entries a process did not compute are 0 on it, so the sums are
  /// exact.
  std::function<void(std::vector<double>&)> sum;
};

class ClothParameterEstimation {
public:
  using Options = ClothEstimationOptions;

  /// `model`: the animatable model (its materials are the starting values of the regions not
  /// being estimated); `poses`: global joint transforms, one per observed frame (the recorded
  /// skeleton motion); `observations`: the studio recording. The objects must outlive this one.
  /// \throws InvalidInput on an invalid model, a pose count ≠ the frame count (< 2 frames), or a
  /// region of the model without cloth.
  ClothParameterEstimation(const AnimatableModel& model, const std::vector<SkeletonPose>& poses, const ClothObservations& observations);

  /// \brief The mesh sequence the model was built from (one mesh per observed frame, the
  /// model's vertex order; the performance capture's output): the states the windows restart
  /// from. Must outlive this object. \throws InvalidInput on a count or size mismatch, NaN.
  void setReferenceSequence(const std::vector<Eigen::MatrixX3d>& frames);
  void setOptions(const ClothEstimationOptions& o);
  const ClothEstimationOptions& options() const { return options_; }
  void setProgressCallback(ProgressCallback cb) { progress_ = std::move(cb); }
  /// \brief Shares the simulations with other processes (ClothWorkShare; default: one process).
  /// \throws InvalidInput when rank is not in 0..size − 1, size < 1, or size > 1 without `sum`.
  void setWorkShare(ClothWorkShare share);

  int numRegions() const { return static_cast<int>(model_.materials.size()); }
  /// Vertices of region r's cloth (δ ≥ clothness_min).
  int clothVertices(int region) const;

  /// E_fit of one material for region `region` (the other regions keep `model`'s): one simulation.
  ClothFitEnergy evaluate(int region, const ClothMaterial& rho) const;
  /// Several samples: their simulations (one per sample and window) run in parallel, one per
  /// thread (and shared over the processes of setWorkShare). Output in input order.
  std::vector<ClothFitEnergy> evaluate(int region, const std::vector<ClothMaterial>& rhos) const;

  /// Estimates every region in turn (each with the earlier regions at their estimates).
  ClothEstimationResult estimate();

private:
  ClothRegionEstimate estimateRegion(int region, std::vector<ClothSample>& samples);
  void checkRegion(int region) const;
  bool inRegion(Eigen::Index vertex, int region) const;  // δ ≥ clothness_min and the region's label

  AnimatableModel model_;  // a copy: materials change as regions are estimated
  const std::vector<SkeletonPose>& poses_;
  const std::vector<Eigen::MatrixX3d>* reference_ = nullptr;
  const ClothObservations& obs_;
  ClothEstimationOptions options_;
  ProgressCallback progress_;
  ClothWorkShare share_;
};

}  // namespace tbsp
