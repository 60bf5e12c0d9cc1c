// Ground-truth template-fitting scenarios built from a real mesh (bunny.off, libigl data):
// a known bend + twist + ×2 scale, Gaussian noise (0.2 % of the bbox diagonal), 10 % uniform
// outliers and a hole removing >= 25 % of the surface; 20 markers on the data.
// Thresholds are the measured performance of this implementation with a margin (see the note
// of issue 3 for how they compare with the targets).
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>

#include "tbsp/plugins/synthetic_scan.h"
#include "test_util.h"
#include "tbsp/core/error.h"
#include "tbsp/fitting/template_fitter.h"
#include "tbsp/io/mesh_io.h"
#include "tbsp/io/range_scan_conf.h"
#include "tbsp/mesh/mesh_validation.h"
#include "tbsp/mesh/point_mesh_distance.h"
#include "tbsp/mesh/point_search.h"
#include "tbsp/mesh/remeshing.h"

using namespace tbsp;

namespace {
const char* kBunny = "meshes/libigl__libigl-tutorial-data/bunny.off";

struct GtOutcome {
  FitReport report;
  synth::ScenarioErrors err;
  double clean_p99 = 0, hole_surface_mean = 0;
  int flipped_vs_truth = 0;
  Eigen::MatrixX3d V;  // the fit's vertices
};

GtOutcome run(const synth::Scenario& s, const FitParameters& p = {}) {
  GtOutcome o;
  TriMesh fit;
  std::vector<VertexStatus> st;
  o.report = fit_template(s.templ, s.P, s.N, s.markers, {}, p, fit, st);
  o.err = synth::evaluate(s, fit);
  o.V = fit.V;
  const MeshDistance fd(fit.V, fit.F);
  std::vector<double> d;
  for (std::size_t i = 0; i < s.inlier.size(); ++i)
    if (s.inlier[i]) d.push_back((fd.closest(s.clean.row(Eigen::Index(i)).transpose()) - s.clean.row(Eigen::Index(i)).transpose()).norm());
  std::nth_element(d.begin(), d.begin() + long(0.99 * double(d.size() - 1)), d.end());
  o.clean_p99 = d[std::size_t(0.99 * double(d.size() - 1))] / s.diag;
  const MeshDistance gt(s.target, s.templ.F);
  const Eigen::VectorXd ds = gt.distances(fit.V);
  double sum = 0;
  int n = 0;
  for (Eigen::Index v = 0; v < ds.rows(); ++v)
    if (s.hole_vertex[std::size_t(v)]) { sum += ds(v); ++n; }
  o.hole_surface_mean = sum / n / s.diag;
  TriMesh truth;
  truth.V = s.target;
  truth.F = s.templ.F;
  o.flipped_vs_truth = count_flipped_faces(fit.V, fit.F, face_normals(truth.V, truth.F));
  std::printf("  scale %.3f, %d iterations, %.2f s | clean samples: Hausdorff %.3f%%, p99 %.3f%% | noisy inliers: "
              "Hausdorff %.3f%% | hole: surface %.3f%%, correspondence %.3f%% | flipped faces %d\n",
              o.report.scale, o.report.iterations, o.report.t_total, 100 * o.err.hausdorff_clean_rel, 100 * o.clean_p99,
              100 * o.err.hausdorff_noisy_rel, 100 * o.hole_surface_mean, 100 * o.err.hole_mean_rel, o.flipped_vs_truth);
  return o;
}
// the scenario with its marker budget (30)
synth::Scenario bunny_30_markers(unsigned seed = 1) {
  synth::ScenarioOptions opt;
  opt.markers = 30;
  opt.seed = seed;
  return synth::make_scenario(read_mesh(test::shared(kBunny)), opt);
}

// the parameters of the 30-marker tests: propagation weight 1 (thesis: ½)
FitParameters weight_one() {
  FitParameters p;
  p.propagation_weight = 1.0;
  return p;
}

// The articulated bunny of the fitting-v2 issue: head and ears turned by `deg`, σ 0.2 % noise,
// no outliers, 25 % hole, 16 farthest-point markers, scaled by `scale`.
synth::ScenarioOptions articulated_bunny(double deg, double scale) {
  synth::ScenarioOptions opt;
  opt.points = 30000;
  opt.markers = 16;
  opt.bend_deg = opt.twist_deg = 0;
  opt.scale = scale;
  opt.outliers = 0;
  opt.joints = synth::bunny_head_and_ears(deg);
  return opt;
}

// The template roughly in place, as a PCL user without markers has it: the scan is the bunny
// bent by 10°, scaled ×1.05, offset by ~3.7 % of the diagonal and then turned by 8° about a
// tilted axis through its centre (σ 0.2 % noise, 10 % outliers, 25 % hole as above).
synth::Scenario bunny_roughly_placed(unsigned seed) {
  synth::ScenarioOptions opt;
  opt.bend_deg = 10;
  opt.twist_deg = 0;
  opt.scale = 1.05;
  opt.translation = Eigen::Vector3d(0.03, -0.02, 0.01);
  opt.markers = 30;
  opt.seed = seed;
  synth::Scenario s = synth::make_scenario(read_mesh(test::shared(kBunny)), opt);
  synth::turn_scenario(s, 8);
  return s;
}
}  // namespace

TEST(TemplateFittingGroundTruth, BendTwistScaleNoiseOutliersHole) {
  TBSP_REQUIRE_FILE(test::shared(kBunny));
  const synth::Scenario s = bunny_30_markers();
  ASSERT_GE(s.hole_area_fraction, 0.25);
  ASSERT_LE(s.markers.size(), 30u);
  const GtOutcome o = run(s, weight_one());
  EXPECT_NEAR(o.report.scale, 2.0, 0.1);                 // §5.2 recovers the ×2
  EXPECT_LE(o.err.hole_mean_rel, 0.0100);                // issue target; measured 0.895 %
  EXPECT_LE(o.hole_surface_mean, 0.0100);                // measured 0.35 %: semantic hole filling
  EXPECT_LE(o.err.hausdorff_clean_rel, 0.0100);          // issue target 0.3 %: NOT met, measured 0.864 %
  EXPECT_LE(o.clean_p99, 0.0040);                        // measured ~0.35 %
  EXPECT_EQ(o.flipped_vs_truth, 0);
}

// Detail rounds (FitParameters::detail_rounds): Laplacian updating after the §5.3 fit with the
// unsupported vertices held and the data-supported ones moved by the kernel mean of the data ->
// fit residuals. The ear tips that the template's detail held back reach the data; the hole
// (held) does not move.
TEST(TemplateFittingGroundTruth, DetailRoundsSharpenProtrusionsAndKeepTheHole) {
  TBSP_REQUIRE_FILE(test::shared(kBunny));
  const synth::Scenario s = bunny_30_markers();
  FitParameters base = weight_one();
  base.detail_rounds = 0;  // (the automatic default runs 4 on this template)
  FitParameters detail = base;
  detail.detail_rounds = 4;
  const GtOutcome a = run(s, base);
  const GtOutcome b = run(s, detail);
  EXPECT_GT(b.report.detail_iterations_run, 0);
  EXPECT_GT(b.report.detail_points_tracked, 0);
  EXPECT_EQ(b.report.detail_surface_constraints, 0);  // off by default
  EXPECT_GT(b.report.t_detail, 0);
  // issue target 0.3 %: measured 0.266 % (0.864 % without detail rounds); over seeds 1-24
  // 0.23-0.38 %, 17 of 24 within 0.3 % (docs/dev/fitting_experiments.md)
  EXPECT_LE(b.err.hausdorff_clean_rel, 0.0030);
  EXPECT_LE(b.err.hausdorff_clean_rel, 0.5 * a.err.hausdorff_clean_rel);   // measured ratio 0.31
  EXPECT_LE(b.clean_p99, 0.45 * a.clean_p99);                             // measured 0.124 vs 0.357 %
  EXPECT_LE(b.err.hole_mean_rel, 0.0100);                                 // issue target; measured 0.887 %
  EXPECT_NEAR(b.err.hole_mean_rel, a.err.hole_mean_rel, 0.0002);          // the hole is held
  EXPECT_EQ(b.flipped_vs_truth, 0);
}

// The accuracy setting of docs/fitting.md (4 detail rounds) on two more seeds of the scenario:
// the gain is not specific to seed 1.
TEST(TemplateFittingGroundTruth, DetailRoundsOnOtherSeeds) {
  TBSP_REQUIRE_FILE(test::shared(kBunny));
  FitParameters p = weight_one();
  p.detail_rounds = 4;
  for (unsigned seed : {2u, 4u}) {
    const GtOutcome o = run(bunny_30_markers(seed), p);
    EXPECT_NEAR(o.report.scale, 2.0, 0.1) << "seed " << seed;
    EXPECT_LE(o.err.hausdorff_clean_rel, 0.0035) << "seed " << seed;  // measured 0.265 / 0.326 % (defaults 0.92 / 0.75 %)
    EXPECT_LE(o.clean_p99, 0.0016) << "seed " << seed;                // measured 0.12-0.13 %
    EXPECT_LE(o.err.hole_mean_rel, 0.0100) << "seed " << seed;        // issue target; measured 0.82 / 0.91 %
    EXPECT_EQ(o.flipped_vs_truth, 0) << "seed " << seed;
  }
}

// FitParameters::detail_residual_matching against the previous detail targets (the §5.3 kernel
// mean along the normal + per-face data constraints of weight 4): the kernel mean of points on a
// curved surface lies inside it, the mean residual does not, so the residual targets are
// unbiased and average over a kernel twice as wide. Signed normal error of the data-supported
// vertices against the ground truth: mean and RMS.
TEST(TemplateFittingGroundTruth, ResidualMatchingIsUnbiasedAndLessNoisy) {
  TBSP_REQUIRE_FILE(test::shared(kBunny));
  const synth::Scenario s = bunny_30_markers();
  FitParameters residual = weight_one();
  residual.detail_rounds = 4;
  FitParameters kernel = residual;
  kernel.detail_residual_matching = false;
  kernel.detail_surface_weight = 4;
  auto normal_error = [&](const FitParameters& p, double& mean, double& rms, int& n, GtOutcome& o) {
    TriMesh fit;
    std::vector<VertexStatus> st;
    o.report = fit_template(s.templ, s.P, s.N, s.markers, {}, p, fit, st);
    o.err = synth::evaluate(s, fit);
    const Eigen::MatrixX3d TN = vertex_normals(s.target, s.templ.F);
    double sum = 0, sum2 = 0;
    n = 0;
    for (Eigen::Index v = 0; v < s.target.rows(); ++v) {
      if (s.hole_vertex[std::size_t(v)] || st[std::size_t(v)] != VertexStatus::Matched) continue;
      const double e = (fit.V.row(v) - s.target.row(v)).dot(TN.row(v)) / s.diag;
      sum += e;
      sum2 += e * e;
      ++n;
    }
    mean = sum / n;
    rms = std::sqrt(sum2 / n);
  };
  double mr, rr, mk, rk;
  int nr, nk;
  GtOutcome o_r, o_k;
  normal_error(residual, mr, rr, nr, o_r);
  normal_error(kernel, mk, rk, nk, o_k);
  // standard errors of the means (the errors of neighbouring vertices are correlated, so these
  // understate the spread; used only to say which mean is distinguishable from 0)
  const double se_r = rr / std::sqrt(double(nr)), se_k = rk / std::sqrt(double(nk));
  std::printf("  signed normal error of the supported vertices: residual matching mean %.4f%% rms %.4f%% (Hausdorff %.3f%%), "
              "kernel targets mean %.4f%% rms %.4f%% (%.3f%%); means in standard errors: %.1f / %.1f\n",
              100 * mr, 100 * rr, 100 * o_r.err.hausdorff_clean_rel, 100 * mk, 100 * rk, 100 * o_k.err.hausdorff_clean_rel,
              mr / se_r, mk / se_k);
  // the kernel targets' mean lies inside the convex surface (-0.0047 %, -2.9 standard errors);
  // the residual mean is within 2 standard errors of 0: measured 0.0016 % (1.4; 0.0013 % before
  // the frozen iterations reused their neighbour lists, which changes the summation order)
  EXPECT_LT(std::abs(mr), 2 * se_r);
  EXPECT_LT(std::abs(mr), 0.5 * std::abs(mk));
  EXPECT_LT(rr, 0.85 * rk);                     // measured 0.055 vs 0.080 %
  EXPECT_LT(o_r.err.hausdorff_clean_rel, o_k.err.hausdorff_clean_rel);  // measured 0.266 vs 0.327 %
}

// FitParameters::support_points: matches backed by fewer than ~3 effective points count less
// (inverse-variance weighting). One or two noisy points at the rim of the hole then no longer
// set the rim vertices and, through the displacement propagation, the hole next to them.
TEST(TemplateFittingGroundTruth, SparseSupportWeightingImprovesTheHoleFilling) {
  TBSP_REQUIRE_FILE(test::shared(kBunny));
  FitParameters off = weight_one();
  off.support_points = 0;
  for (unsigned seed : {1u, 4u}) {
    const synth::Scenario s = bunny_30_markers(seed);
    const GtOutcome a = run(s, off);
    const GtOutcome b = run(s, weight_one());  // default: 3
    // measured 0.977 -> 0.895 % (seed 1), 1.064 -> 0.917 % (seed 4)
    EXPECT_LE(b.err.hole_mean_rel, a.err.hole_mean_rel - 0.0005) << "seed " << seed;
    EXPECT_LE(b.err.hausdorff_clean_rel, a.err.hausdorff_clean_rel + 0.0005) << "seed " << seed;  // 0.864 / 0.731 -> 0.864 / 0.752 %
  }
}

TEST(TemplateFittingGroundTruth, TwentyMarkersThesisWeights) {
  TBSP_REQUIRE_FILE(test::shared(kBunny));
  const synth::Scenario s = synth::make_scenario(read_mesh(test::shared(kBunny)), {});
  const GtOutcome o = run(s);
  EXPECT_NEAR(o.report.scale, 2.0, 0.1);
  EXPECT_LE(o.err.hausdorff_clean_rel, 0.0100);          // measured 0.845 %
  EXPECT_LE(o.hole_surface_mean, 0.0100);                // measured 0.50 %
  EXPECT_LE(o.err.hole_mean_rel, 0.0150);                // measured 1.08 %
  EXPECT_EQ(o.flipped_vs_truth, 0);
}

TEST(TemplateFittingGroundTruth, WithoutGlobalScaleTheFitFails) {
  // control for §5.2: data ×2 out of scale is not reached by the iterations alone
  TBSP_REQUIRE_FILE(test::shared(kBunny));
  const synth::Scenario s = synth::make_scenario(read_mesh(test::shared(kBunny)), {});
  FitParameters no_scale;
  no_scale.estimate_scale = false;
  no_scale.pull_rounds = 0;  // the iterations alone (the pull rounds bring this fit to 1.8 %,
  no_scale.detail_rounds = 0;  // the detail rounds to 1.4 %)
  const GtOutcome o = run(s, no_scale);
  EXPECT_GT(o.err.hausdorff_clean_rel, 0.03);  // measured 7.1 % (0.83 % with the scale)
}

TEST(TemplateFittingGroundTruth, BadlyRegisteredFragmentsGiveOneSurface) {
  TBSP_REQUIRE_FILE(test::shared(kBunny));
  synth::ScenarioOptions opt;
  opt.fragment_offset = 0.01;  // one half of the cloud shifted by 1 % of the bbox diagonal
  opt.hole = 0.05;
  const synth::Scenario s = synth::make_scenario(read_mesh(test::shared(kBunny)), opt);
  const GtOutcome o = run(s);
  // a single sheet between the fragments: no fold-overs, every clean sample within ~offset
  EXPECT_EQ(o.flipped_vs_truth, 0);
  EXPECT_LE(o.err.hausdorff_clean_rel, 0.02);
  EXPECT_LE(o.err.all_mean_rel, 0.012);
}

TEST(TemplateFittingGroundTruth, OverRelaxationReachesTheSameFitInFewerIterations) {
  // the frozen iterations converge to one fixed point; ω only changes how fast
  TBSP_REQUIRE_FILE(test::shared(kBunny));
  const synth::Scenario s = synth::make_scenario(read_mesh(test::shared(kBunny)), {});
  FitParameters plain, relaxed;
  plain.relaxation = 1.0;
  plain.max_iterations = relaxed.max_iterations = 40;
  TriMesh a, b;
  std::vector<VertexStatus> st;
  const FitReport ra = fit_template(s.templ, s.P, s.N, s.markers, {}, plain, a, st);
  const FitReport rb = fit_template(s.templ, s.P, s.N, s.markers, {}, relaxed, b, st);
  const double mean_diff = (a.V - b.V).rowwise().norm().mean() / s.diag;
  std::printf("  relaxation 1: %d iterations, 1.5: %d iterations; mean vertex difference %.4f%%\n", ra.iterations,
              rb.iterations, 100 * mean_diff);
  EXPECT_EQ(ra.status, FitReport::Status::Success);
  EXPECT_EQ(rb.status, FitReport::Status::Success);
  EXPECT_LT(rb.iterations, ra.iterations);
  EXPECT_LT(mean_diff, 0.001);  // 0.1 % of the diagonal
}

TEST(TemplateFittingGroundTruth, BinnedMatchingAtLargeRadiiGivesTheExactFit) {
  // the first coarse-to-fine iterations match against the binned cloud; the fit must be the one
  // of exact matching to well within its own error
  TBSP_REQUIRE_FILE(test::shared(kBunny));
  const synth::Scenario s = synth::make_scenario(read_mesh(test::shared(kBunny)), {});
  FitParameters exact, binned;
  exact.binned_matching = false;
  TriMesh a, b;
  std::vector<VertexStatus> st;
  const FitReport ra = fit_template(s.templ, s.P, s.N, s.markers, {}, exact, a, st);
  const FitReport rb = fit_template(s.templ, s.P, s.N, s.markers, {}, binned, b, st);
  const synth::ScenarioErrors ea = synth::evaluate(s, a), eb = synth::evaluate(s, b);
  const double mean_diff = (a.V - b.V).rowwise().norm().mean() / s.diag;
  std::printf("  exact: clean Hausdorff %.3f%%, hole %.3f%%; binned: %.3f%%, %.3f%%; mean vertex difference %.4f%%\n",
              100 * ea.hausdorff_clean_rel, 100 * ea.hole_mean_rel, 100 * eb.hausdorff_clean_rel, 100 * eb.hole_mean_rel,
              100 * mean_diff);
  ASSERT_FALSE(rb.history.empty());
  EXPECT_TRUE(rb.history.front().binned);   // r = 3 % of the diagonal: bins of 1 %
  EXPECT_FALSE(rb.history.back().binned);   // the final radius matches every point
  for (const auto& h : ra.history) EXPECT_FALSE(h.binned);
  EXPECT_LT(mean_diff, 0.001);  // 0.1 % of the diagonal
  EXPECT_LT(std::abs(eb.hausdorff_clean_rel - ea.hausdorff_clean_rel), 0.001);
  EXPECT_LT(std::abs(eb.hole_mean_rel - ea.hole_mean_rel), 0.001);
}

// Without markers (issue: fitting v2): the template is first aligned by trimmed ICP with scale,
// fitted by the matches alone, and 30 of its matched vertices then steer a second fit as
// markers (FitParameters::auto_markers); the coarse stage runs by default here (coarse_nodes
// −1: 400 without markers), with its three hypotheses. Measured over seeds 1-5 of the roughly
// placed bunny (2026-12-05, three hypotheses; two gave the same ranges):
//   alignment 9.0-9.2° (8° turn + the 10° bend), scale 1.059-1.060 (truth 1.05: a similarity
//   cannot follow the bend); the fit's scale 1.047-1.051;
//   without markers: clean Hausdorff 0.32-0.54 %, p99 0.175-0.197 %, hole 0.57-0.67 %, 0 flips
//   (with the coarse stage off: 0.61-0.93 %, 0.28-0.38 %, 0.99-1.17 %);
//   with the 30 scenario markers:  0.38-0.50 %,        0.19-0.22 %,      0.56-0.71 %.
// The bounds below are the measured spread with a margin, so that a regression shows.
TEST(TemplateFittingGroundTruth, WithoutMarkersARoughlyPlacedTemplateIsAlignedAndFitted) {
  TBSP_REQUIRE_FILE(test::shared(kBunny));
  for (unsigned seed : {1u, 2u}) {
    synth::Scenario s = bunny_roughly_placed(seed);
    s.markers.clear();
    const GtOutcome o = run(s, weight_one());
    std::printf("  seed %u alignment: %.2f deg, scale %.4f, %d iterations, rms %.3g, first pass %.3f s; fit: scale %.4f, clean %.3f%%, "
                "p99 %.3f%%, hole %.3f%%, coarse nodes %d (hypotheses %d), %.2f s\n",
                seed, o.report.alignment_rotation_deg, o.report.alignment_scale, o.report.alignment_iterations, o.report.alignment_rms,
                o.report.t_alignment, o.report.scale, 100 * o.err.hausdorff_clean_rel, 100 * o.clean_p99, 100 * o.err.hole_mean_rel,
                o.report.coarse_nodes, o.report.coarse_hypotheses, o.report.t_total);
    EXPECT_TRUE(o.report.aligned_without_markers) << "seed " << seed;
    EXPECT_EQ(o.report.auto_markers, 30) << "seed " << seed;
    EXPECT_NEAR(o.report.alignment_rotation_deg, 9.0, 1.5) << "seed " << seed;
    EXPECT_NEAR(o.report.alignment_scale, 1.05, 0.015) << "seed " << seed;
    EXPECT_NEAR(o.report.scale, 1.05, 0.012) << "seed " << seed;
    EXPECT_EQ(o.report.coarse_nodes, 400) << "seed " << seed;  // automatic without markers
    EXPECT_EQ(o.report.coarse_hypotheses, 3) << "seed " << seed;
    EXPECT_LE(o.err.hausdorff_clean_rel, 0.0070) << "seed " << seed;
    EXPECT_LE(o.clean_p99, 0.0026) << "seed " << seed;
    EXPECT_LE(o.err.hole_mean_rel, 0.0085) << "seed " << seed;
    EXPECT_EQ(o.flipped_vs_truth, 0) << "seed " << seed;
  }
}

// ScenarioOptions::hole_axis: the hole lies across the chosen principal axis (a different set
// of vertices, the same removed area); an axis outside 0-2 is refused.
TEST(SyntheticScenario, HoleAxisChoosesWhereTheHoleIs) {
  TBSP_REQUIRE_FILE(test::shared(kBunny));
  const TriMesh t = read_mesh(test::shared(kBunny));
  synth::ScenarioOptions o;
  o.points = 2000;
  const synth::Scenario a = synth::make_scenario(t, o);
  o.hole_axis = 2;
  const synth::Scenario b = synth::make_scenario(t, o);
  EXPECT_NEAR(a.hole_area_fraction, 0.25, 0.01);
  EXPECT_NEAR(b.hole_area_fraction, 0.25, 0.01);
  std::size_t both = 0, in_a = 0;
  for (std::size_t v = 0; v < a.hole_vertex.size(); ++v) {
    in_a += a.hole_vertex[v] != 0;
    both += a.hole_vertex[v] && b.hole_vertex[v];
  }
  EXPECT_GT(in_a, 100u);
  EXPECT_LT(both, in_a / 2);  // another part of the surface
  o.hole_axis = 3;
  EXPECT_THROW(synth::make_scenario(t, o), InvalidInput);
}

// Markers optional (fitting v2 issue): the articulated bunny (head and ears turned by 15°, 30°
// and 45°) roughly placed (×1.05, 3.7 % of d off, turned by 8°), coarse stage on, fitted without
// markers and with its 16 farthest-point markers. Without markers the fit runs three coarse-stage
// hypotheses (the 400-node graph alone; a 100- or a 200-node graph first) and keeps the one
// closest to the cloud (FitReport::tail_mean). Measured over seeds 1-10 (bench_fit --markerless
// --coarse 400): without markers clean Hausdorff 0.34-0.50 / 0.50-0.78 / 0.67-1.18 % (one
// hypothesis: 0.34-0.56 / 0.58-0.91 / 1.04-1.84 %), with them 0.34-0.48 / 0.48-0.90 / 0.52-0.91 %.
TEST(TemplateFittingGroundTruth, WithoutMarkersTheCoarseStageFollowsATurnedHead) {
  TBSP_REQUIRE_FILE(test::shared(kBunny));
  FitParameters p;
  p.coarse_nodes = 400;
  for (double deg : {15.0, 30.0, 45.0}) {
    synth::ScenarioOptions opt = articulated_bunny(deg, 1.05);
    opt.translation = Eigen::Vector3d(0.03, -0.02, 0.01);
    synth::Scenario s = synth::make_scenario(read_mesh(test::shared(kBunny)), opt);
    synth::turn_scenario(s, 8);
    const GtOutcome with = run(s, p);
    s.markers.clear();
    const GtOutcome without = run(s, p);
    std::printf("  %g deg: with markers %.3f%%, without %.3f%% (tail means", deg, 100 * with.err.hausdorff_clean_rel,
                100 * without.err.hausdorff_clean_rel);
    for (double t : without.report.coarse_scores) std::printf(" %.4g", t);
    std::printf("; kept %d, coarser graph first: %d)\n", without.report.coarse_kept, without.report.coarse_prepass_nodes);
    EXPECT_TRUE(without.report.aligned_without_markers) << deg;
    EXPECT_GT(without.report.coarse_steps, 0) << deg;
    EXPECT_EQ(without.report.coarse_hypotheses, 3) << deg;
    ASSERT_EQ(without.report.coarse_scores.size(), 3u) << deg;
    for (double t : without.report.coarse_scores) EXPECT_LE(without.report.tail_mean, t) << deg;  // the closest hypothesis is kept
    EXPECT_EQ(with.report.coarse_hypotheses, 0) << deg;                          // markers pose the parts: one fit
    EXPECT_LE(without.err.hausdorff_clean_rel, deg < 20 ? 0.0065 : 0.0100) << deg;
    EXPECT_LE(without.err.hausdorff_clean_rel, with.err.hausdorff_clean_rel + 0.0025) << deg;
    EXPECT_EQ(without.flipped_vs_truth, 0) << deg;
  }
}

// The articulated ground truth of the fitting-v2 issue (synth::articulate): analytic checks of
// one joint (rigid on each side, a monotone blend across the falloff) and of a chain (the
// child's joint turns with its parent).
TEST(SyntheticArticulation, JointsTurnTheirPartRigidlyAndBlendSmoothly) {
  Eigen::MatrixX3d V(41, 3);
  for (int i = 0; i < 41; ++i) V.row(i) << 0.3 * std::sin(i), -1.0 + 0.05 * i, 0.2 * std::cos(i);
  synth::Joint j;
  j.centre = Eigen::Vector3d::Zero();
  j.side = Eigen::Vector3d::UnitY();
  j.axis = Eigen::Vector3d::UnitZ();
  j.falloff = 0.1;
  j.angle_deg = 30;
  const Eigen::MatrixX3d A = synth::articulate(V, {j});
  const Eigen::Matrix3d R = Eigen::AngleAxisd(M_PI / 6, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  double last_angle = -1;
  for (int i = 0; i < 41; ++i) {
    const Eigen::Vector3d p = V.row(i).transpose(), q = A.row(i).transpose();
    EXPECT_NEAR(q.norm(), p.norm(), 1e-12) << i;  // a rotation about the centre, whatever the blend
    if (p.y() <= -0.1) {
      EXPECT_LT((q - p).norm(), 1e-15) << i;
    }
    if (p.y() >= 0.1) {
      EXPECT_LT((q - R * p).norm(), 1e-12) << i;
    }
    const double angle = std::atan2(p.x() * q.y() - p.y() * q.x(), p.x() * q.x() + p.y() * q.y());
    EXPECT_GE(angle, last_angle - 1e-12) << i;  // monotone along the chain of points
    last_angle = angle;
  }
  synth::Joint child = j;
  child.centre = Eigen::Vector3d(0, 0.5, 0);
  const Eigen::MatrixX3d B = synth::articulate(V, {j, child});
  const Eigen::Vector3d c2 = R * child.centre;  // the child's joint after its parent turned
  const Eigen::Matrix3d R60 = Eigen::AngleAxisd(M_PI / 3, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  for (int i = 0; i < 41; ++i) {
    if (V(i, 1) >= 0.6) {
      EXPECT_LT((B.row(i).transpose() - (c2 + R60 * (V.row(i).transpose() - child.centre))).norm(), 1e-12) << i;
    }
  }
}

// The articulated ground truth must be a surface a scanner could see: a joint whose blend is
// too narrow folds the inner side of the bend through itself, and the samples on the folded
// sheet lie inside the body, where no fit without self-intersections can reach them.
TEST(SyntheticArticulation, BunnyHeadAndEarsDoNotFoldThroughThemselves) {
  const TriMesh t = read_mesh(test::shared(kBunny));
  ASSERT_EQ(count_self_intersections(t.V, t.F), 0);
  for (double deg : {15.0, 30.0, 45.0}) {
    const Eigen::MatrixX3d A = synth::articulate(t.V, synth::bunny_head_and_ears(deg));
    EXPECT_EQ(count_self_intersections(A, t.F), 0) << deg << " deg";
    EXPECT_GT((A - t.V).rowwise().norm().maxCoeff(), 0.01) << deg;  // the head did turn (bunny: 0.2 m diagonal)
  }
}

// The same for the Armadillo's and the SMPL human's limbs (joints with seeds: one limb each).
TEST(SyntheticArticulation, ArmadilloAndHumanLimbsTurnWithoutFolding) {
  struct Case { const char* path; std::vector<synth::Joint> (*joints)(double); };
  for (const Case& c : {Case{"meshes/libigl__libigl-tutorial-data/armadillo.obj", &synth::armadillo_limbs},
                        Case{"meshes/odedstein__meshes/objects/human/human_man.obj", &synth::human_limbs}}) {
    TBSP_REQUIRE_FILE(test::shared(c.path));
    const TriMesh t = read_mesh(test::shared(c.path));
    const int before = count_self_intersections(t.V, t.F);
    const double diag = bbox_diagonal(t.V);
    for (double deg : {15.0, 30.0, 45.0}) {
      const std::vector<synth::Joint> J = c.joints(deg);
      const Eigen::MatrixX3d A = synth::articulate(t.V, t.F, J);
      EXPECT_LE(count_self_intersections(A, t.F), before) << c.path << " " << deg << " deg";
      // every joint turns its own limb only: the moved vertices of one joint alone are few
      for (const synth::Joint& j : J) {
        const Eigen::VectorXd d = (synth::articulate(t.V, t.F, {j}) - t.V).rowwise().norm();
        const Eigen::Index moved = (d.array() > 1e-9).count();
        std::printf("  %s %g deg: joint at (%.2f %.2f %.2f) moves %ld of %ld vertices, up to %.1f %% of the diagonal; crossing face pairs %d\n", c.path, deg,
                    j.centre.x(), j.centre.y(), j.centre.z(), long(moved), long(t.V.rows()), 100 * d.maxCoeff() / diag,
                    count_self_intersections(synth::articulate(t.V, t.F, {j}), t.F));
        EXPECT_GT(d.maxCoeff(), 0.02 * diag * deg / 15) << c.path;
        EXPECT_LT(moved, t.V.rows() / 4) << c.path;
      }
    }
  }
}

// Fitting v2's coarse stage on the articulated bunny (head nodded and ears tilted by 30° and 45°,
// ×1.1, σ = 0.2 % noise, 25 % hole over the bent neck, 16 farthest-point markers). Measured over
// seeds 1-10 (docs/fitting.md): with the coarse stage + 4 detail rounds clean Hausdorff 0.31-0.57 %
// (30°) and 0.34-0.61 % (45°), hole surface 0.59-0.77 / 0.83-0.97 %; without the coarse stage the
// 45° case reaches 2.2 % on some seeds (the §5.3 matching moves vertices along their normals
// only). The hole cannot get below 0.57 / 0.79 %: a deformation graph driven by the true
// positions outside the hole gets there (bench_fit --hole-oracle).
TEST(TemplateFittingGroundTruth, CoarseStageFollowsTurnedHeadAndEars) {
  TBSP_REQUIRE_FILE(test::shared(kBunny));
  FitParameters p;
  p.coarse_nodes = 400;
  p.detail_rounds = 4;
  for (double deg : {30.0, 45.0}) {
    const synth::Scenario s = synth::make_scenario(read_mesh(test::shared(kBunny)), articulated_bunny(deg, 1.1));
    const GtOutcome o = run(s, p);
    EXPECT_EQ(o.report.coarse_nodes, 400);
    EXPECT_GT(o.report.coarse_steps, 0);
    EXPECT_LE(o.err.hausdorff_clean_rel, deg < 40 ? 0.0065 : 0.0075) << deg;
    EXPECT_LE(o.hole_surface_mean, deg < 40 ? 0.009 : 0.011) << deg;
    EXPECT_EQ(o.flipped_vs_truth, 0) << deg;
  }
}

// With markers the defaults (coarse_nodes −1) fit without and with the coarse stage and keep the
// fit that leaves fewer scan points beyond r_max. The articulated bunny at 45°, seed 4, with 4
// detail rounds: the ears stay behind without the coarse stage when the rounds' residual matching
// takes points within r_max only (measured: clean 2.16 %); with the points of the unexplained
// regions pulling at any distance (detail_pull_unexplained, the default) the rounds alone bring
// the ear back (0.366 %); the defaults compare the two fits before the rounds and keep the coarse
// stage's (0.441 %, 0.380 % before the coarse stage's second half; the target at 45°: 0.5 %).
TEST(TemplateFittingGroundTruth, DefaultsKeepTheCoarseStagesFitWhenEarsStayBehind) {
  TBSP_REQUIRE_FILE(test::shared(kBunny));
  synth::ScenarioOptions opt = articulated_bunny(45, 1.1);
  opt.seed = 4;
  const synth::Scenario s = synth::make_scenario(read_mesh(test::shared(kBunny)), opt);
  FitParameters off;
  off.coarse_nodes = 0;
  off.detail_rounds = 4;
  off.detail_pull_unexplained = false;
  const GtOutcome without = run(s, off);
  EXPECT_FALSE(without.report.coarse_compared);
  EXPECT_GT(without.err.hausdorff_clean_rel, 0.015);
  EXPECT_EQ(without.report.detail_rounds_pulling, 0);
  // the detail rounds alone bring the ear back when its points pull at any distance
  FitParameters pull = off;
  pull.detail_pull_unexplained = true;
  const GtOutcome pulled = run(s, pull);
  EXPECT_FALSE(pulled.report.coarse_compared);
  EXPECT_GE(pulled.report.detail_rounds_pulling, 1);
  EXPECT_LE(pulled.err.hausdorff_clean_rel, 0.0055);
  EXPECT_EQ(pulled.flipped_vs_truth, 0);
  EXPECT_TRUE(pulled.report.unexplained.empty()) << pulled.report.message;
  FitParameters defaults;
  defaults.detail_rounds = 4;
  const GtOutcome o = run(s, defaults);
  EXPECT_TRUE(o.report.coarse_compared) << o.report.message;
  EXPECT_EQ(o.report.coarse_nodes, 400);
  ASSERT_EQ(o.report.coarse_far_points.size(), 2u);
  EXPECT_LT(o.report.coarse_far_points[1] + 10, o.report.coarse_far_points[0]);
  EXPECT_NE(o.report.message.find("before the detail rounds"), std::string::npos);
  EXPECT_GT(o.report.detail_iterations_run, 0);  // the kept fit ran its detail rounds
  EXPECT_LE(o.err.hausdorff_clean_rel, 0.0055);
  EXPECT_LE(o.hole_surface_mean, 0.011);
  EXPECT_EQ(o.flipped_vs_truth, 0);
  EXPECT_TRUE(o.report.unexplained.empty()) << o.report.message;
  // the compared fit (on its own thread, one OpenMP thread) is the same, bit for bit, as one
  // asked for with the coarse stage (on all threads)
  FitParameters coarse = defaults;
  coarse.coarse_nodes = 400;
  const GtOutcome c = run(s, coarse);
  EXPECT_FALSE(c.report.coarse_compared);
  EXPECT_EQ(c.report.scale, o.report.scale);
  EXPECT_TRUE(c.V == o.V) << "largest difference " << (c.V - o.V).cwiseAbs().maxCoeff();
  // without detail rounds (pull rounds instead) both fits run their pull rounds and the choice
  // is made after them, on the scan points beyond r_max from each
  FitParameters no_detail;
  no_detail.detail_rounds = 0;
  const GtOutcome p = run(s, no_detail);
  EXPECT_TRUE(p.report.coarse_compared) << p.report.message;
  EXPECT_EQ(p.report.coarse_nodes, 400);
  ASSERT_EQ(p.report.coarse_far_points.size(), 2u);
  EXPECT_LT(p.report.coarse_far_points[1] + 10, p.report.coarse_far_points[0]);
  EXPECT_NE(p.report.message.find("after the pull rounds"), std::string::npos) << p.report.message;
  EXPECT_LE(p.err.hausdorff_clean_rel, 0.009);  // measured 0.643 %; the first fit alone 1.77 %
  EXPECT_TRUE(p.report.unexplained.empty()) << p.report.message;
  FitParameters coarse_pull = no_detail;
  coarse_pull.coarse_nodes = 400;
  const GtOutcome cp = run(s, coarse_pull);
  EXPECT_TRUE(cp.V == p.V) << "largest difference " << (cp.V - p.V).cwiseAbs().maxCoeff();
}

// The detail rounds' pull (detail_pull_unexplained) follows any unexplained region, clutter
// too: a table of points 3 % of d under the articulated bunny (15°, where nothing stays behind)
// is a region, but its points face the bunny's underside the other way (the rounds' normal test,
// detail_normal_angle_deg), so the fit must not move towards it.
TEST(TemplateFittingGroundTruth, DetailRoundsDoNotPullTheFitTowardsATableUnderTheScan) {
  TBSP_REQUIRE_FILE(test::shared(kBunny));
  synth::Scenario s = synth::make_scenario(read_mesh(test::shared(kBunny)), articulated_bunny(15, 1.1));
  const Eigen::RowVector3d lo = s.target.colwise().minCoeff(), hi = s.target.colwise().maxCoeff();
  const double y = lo(1) - 0.03 * s.diag, h = 0.005 * s.diag;
  std::vector<Eigen::RowVector3d> table;
  for (double x = lo(0) - 0.1 * s.diag; x <= hi(0) + 0.1 * s.diag; x += h)
    for (double z = lo(2) - 0.1 * s.diag; z <= hi(2) + 0.1 * s.diag; z += h) table.emplace_back(x, y, z);
  const Eigen::Index n0 = s.P.rows(), nt = Eigen::Index(table.size());
  s.P.conservativeResize(n0 + nt, 3);
  s.N.conservativeResize(n0 + nt, 3);
  s.clean.conservativeResize(n0 + nt, 3);
  for (Eigen::Index k = 0; k < nt; ++k) {
    s.P.row(n0 + k) = table[std::size_t(k)];
    s.N.row(n0 + k) = Eigen::RowVector3d(0, 1, 0);
    s.clean.row(n0 + k).setConstant(std::numeric_limits<double>::quiet_NaN());
    s.inlier.push_back(0);
  }
  FitParameters p;
  p.detail_rounds = 4;
  p.detail_pull_unexplained = false;
  const GtOutcome off = run(s, p);
  p.detail_pull_unexplained = true;
  const GtOutcome on = run(s, p);
  EXPECT_FALSE(on.report.unexplained.empty());  // the table is reported
  EXPECT_GE(on.report.detail_rounds_pulling, 1);
  const MeshDistance truth(s.target, s.templ.F);
  const double worst_off = truth.distances(off.V).maxCoeff() / s.diag, worst_on = truth.distances(on.V).maxCoeff() / s.diag;
  EXPECT_LE(worst_on, worst_off + 0.0005) << worst_off;
  EXPECT_LE(on.err.hausdorff_clean_rel, off.err.hausdorff_clean_rel + 0.0005);
  EXPECT_LE(on.err.hausdorff_clean_rel, 0.004);
  EXPECT_EQ(on.flipped_vs_truth, 0);
}

// Real scans (fitting v2 issue): the bunny template with its head and ears tilted by 15° and 30°,
// fitted to the real range scans bun000 + bun045 + bun090 (bun.conf) with 16 farthest-point
// markers on the scanned side (each to the scan point nearest the untilted vertex). The fit must
// be as close to the scans as the Stanford reconstruction is: p99 scan -> fit within the scans'
// own p99 distance to bun_zipper.ply + 0.05 % of the diagonal. Measured (bench_fit --only "real
// scans"): reference 0.227 %; coarse stage + 4 detail rounds 0.184 % (15°), 0.199 % (30°); the
// default fit 0.261 % / 1.72 % (an ear stays behind at 30°).
TEST(TemplateFittingRealScans, CoarseStageFitsThreeScansWithATiltedTemplate) {
  const std::string dir = test::shared("meshes/dengnantianjie__3dcoursework/bunny/");
  TBSP_REQUIRE_FILE(dir + "data/bun.conf");
  const Eigen::MatrixX3d P = read_registered_range_scans(dir + "data/bun.conf", {"bun000.ply", "bun045.ply", "bun090.ply"});
  const TriMesh zipper = read_mesh(dir + "reconstruction/bun_zipper.ply");
  const double diag = (P.colwise().maxCoeff() - P.colwise().minCoeff()).norm();
  auto p99 = [](Eigen::VectorXd d) {
    std::sort(d.data(), d.data() + d.size());
    return d(Eigen::Index(0.99 * double(d.size() - 1)));
  };
  const double reference = p99(point_mesh_distances(zipper.V, zipper.F, P)) / diag;
  EXPECT_LT(reference, 0.003);  // the scans are registered (bun.conf read right)
  const TriMesh t = read_mesh(test::shared(kBunny));
  const PointSearch tree(P);
  std::vector<int> cand;
  for (Eigen::Index v = 0; v < t.V.rows(); ++v) {
    double d2;
    tree.nearest(t.V.row(v).transpose(), &d2);
    if (d2 < 1e-6) cand.push_back(int(v));  // within 1 mm of a scan
  }
  std::vector<FitMarker> markers;
  for (int v : farthest_point_sample(t.V, cand, 16)) markers.push_back({v, tree.nearest(t.V.row(v).transpose())});
  FitParameters p;
  p.coarse_nodes = 400;
  p.detail_rounds = 4;
  for (double deg : {15.0, 30.0}) {
    TriMesh tilted = t;
    tilted.V = synth::articulate(t.V, synth::bunny_head_and_ears(deg));
    TriMesh fit;
    std::vector<VertexStatus> st;
    const FitReport r = fit_template(tilted, P, Eigen::MatrixX3d(), markers, {}, p, fit, st);
    const double got = p99(point_mesh_distances(fit.V, fit.F, P)) / diag;
    std::printf("  %g deg: scan -> fit p99 %.3f%% (reference %.3f%%), %.2f s\n", deg, 100 * got, 100 * reference, r.t_total);
    EXPECT_LE(got, reference + 5e-4) << deg << " deg";
    EXPECT_TRUE(r.unexplained.empty()) << deg << " deg: " << r.message;  // every part of the scans is explained
  }
  // Without the coarse stage the fit leaves an ear behind at 30° (p99 1.7 %, bench_fit --only
  // "real scans"): the report names that region. Its points lie on the true bunny (bun_zipper)
  // and away from the fit, on the head and ears (the upper third of the scans; measured: 1,663
  // points centred 0.154 m high in scans 0.033-0.187 m high, up to 3.9 % of the diagonal away), and
  // the message says so.
  TriMesh tilted = t;
  tilted.V = synth::articulate(t.V, synth::bunny_head_and_ears(30));
  TriMesh fit;
  std::vector<VertexStatus> st;
  FitParameters off;
  off.coarse_nodes = 0;
  off.pull_rounds = 0;    // the region as the fit leaves it (the pull rounds: below; the
  off.detail_rounds = 0;  // detail rounds, the default on this template, draw it in too)
  const FitReport r = fit_template(tilted, P, Eigen::MatrixX3d(), markers, {}, off, fit, st);
  EXPECT_FALSE(r.coarse_compared);  // (asked for: no coarse stage)
  ASSERT_FALSE(r.unexplained.empty()) << r.message;
  const FitReport::UnexplainedRegion& ear = r.unexplained.front();
  std::printf("  30 deg, no coarse stage: %zu region(s), the largest %lld points around (%.4f %.4f %.4f), up to %.2f%%\n", r.unexplained.size(),
              static_cast<long long>(ear.points), ear.centre.x(), ear.centre.y(), ear.centre.z(), 100 * ear.max_distance / diag);
  EXPECT_GE(ear.points, 500);
  EXPECT_GT(ear.max_distance, 0.02 * diag);
  const Eigen::MatrixX3d c = ear.centre.transpose();
  EXPECT_LT(point_mesh_distances(zipper.V, zipper.F, c)(0), 0.01 * diag);  // the data are right there...
  EXPECT_GT(point_mesh_distances(fit.V, fit.F, c)(0), 0.01 * diag);        // ...and the fit is not
  const double top = P.col(1).maxCoeff(), bottom = P.col(1).minCoeff();
  EXPECT_GT(ear.centre.y(), top - (top - bottom) / 3);
  EXPECT_NE(r.message.find("not explained by the result"), std::string::npos);
  EXPECT_NE(r.message.find("--coarse-nodes 400"), std::string::npos);  // the way out, named
  for (std::size_t k = 1; k < r.unexplained.size(); ++k) EXPECT_LE(r.unexplained[k].points, r.unexplained[k - 1].points);
  const double stuck = p99(point_mesh_distances(fit.V, fit.F, P)) / diag;
  // The pull rounds (default 2) draw the ear in: only vertices near the region move
  {
    FitParameters pull = off;
    pull.pull_rounds = 2;
    TriMesh fp;
    std::vector<VertexStatus> sp;
    const FitReport rp = fit_template(tilted, P, Eigen::MatrixX3d(), markers, {}, pull, fp, sp);
    const double pulled = p99(point_mesh_distances(fp.V, fp.F, P)) / diag;
    const Eigen::Index left = rp.unexplained.empty() ? 0 : rp.unexplained.front().points;
    std::printf("  30 deg, no coarse stage, 2 pull rounds: p99 %.3f%% (%.3f%% without), largest region %lld points, %.2f s pulling\n",
                100 * pulled, 100 * stuck, static_cast<long long>(left), rp.t_pull);
    EXPECT_EQ(rp.pull_rounds_run, 2);
    EXPECT_LT(pulled, 0.5 * stuck);
    EXPECT_LT(left, ear.points / 2);
    // vertices far from the region are held where the fit put them
    double far_moved = 0;
    for (Eigen::Index v = 0; v < fit.V.rows(); ++v)
      if ((fit.V.row(v).transpose() - ear.centre).norm() > 0.5 * diag) far_moved = std::max(far_moved, (fp.V.row(v) - fit.V.row(v)).norm());
    std::printf("  largest move of a vertex half a diagonal from the region: %.2e of the diagonal\n", far_moved / diag);
    EXPECT_LT(far_moved, 1e-3 * diag);
  }
  // The defaults (coarse_nodes −1) fit with the coarse stage too and keep that fit, which leaves
  // fewer points beyond r_max before the detail rounds: the ear is brought back (measured: p99
  // 0.198 %, no region left; 0.250 % without the detail rounds)
  TriMesh fit2;
  std::vector<double> progress;
  const FitReport d = fit_template(tilted, P, Eigen::MatrixX3d(), markers, {}, FitParameters(), fit2, st,
                                   [&](double f, const std::string&) { progress.push_back(f); return true; });
  ASSERT_FALSE(progress.empty());
  EXPECT_TRUE(std::is_sorted(progress.begin(), progress.end()));  // one bar over both fits
  EXPECT_EQ(progress.back(), 1.0);
  EXPECT_TRUE(d.coarse_compared) << d.message;
  EXPECT_EQ(d.coarse_nodes, 400);  // the coarse stage's fit was kept
  ASSERT_EQ(d.coarse_far_points.size(), 2u);
  EXPECT_GT(d.coarse_far_points[0], ear.points / 4);  // the fit without it: the ear drawn in part of the way
  EXPECT_LT(d.coarse_far_points[1] + 10, d.coarse_far_points[0]);
  EXPECT_TRUE(d.unexplained.empty()) << d.message;
  const double got = p99(point_mesh_distances(fit2.V, fit2.F, P)) / diag;
  std::printf("  30 deg, defaults: p99 %.3f%%, %lld / %lld points beyond r_max without / with the coarse stage\n", 100 * got,
              static_cast<long long>(d.coarse_far_points[0]), static_cast<long long>(d.coarse_far_points[1]));
  EXPECT_LE(got, reference + 5e-4);
}
