// With markers and the default coarse_nodes (−1) a fit runs without and with the coarse stage and
// keeps the one that leaves fewer scan points beyond r_max (template_fitter.cpp,
// fit_with_and_without_coarse_stage). These tests check the parts of that choice the ground-truth
// tests do not: the coarse stage's fit stopped when it cannot win (or when only stray outliers are
// left unexplained), the same fit on one thread and
// on two, a cancel from the caller, and the SMPL human turned by 45° (no region of the scan is
// left unexplained, yet its hands stay behind without the coarse stage).
#include <gtest/gtest.h>

#include <omp.h>

#include <algorithm>
#include <cstdio>
#include <string>
#include <vector>

#include "tbsp/core/error.h"
#include "tbsp/fitting/template_fitter.h"
#include "tbsp/io/mesh_io.h"
#include "tbsp/plugins/synthetic_scan.h"
#include "test_util.h"

using namespace tbsp;

namespace {
const char* kCmpBunny = "meshes/libigl__libigl-tutorial-data/bunny.off";
const char* kCmpHuman = "meshes/odedstein__meshes/objects/human/human_man.obj";
const char* kCmpArmadillo = "meshes/libigl__libigl-tutorial-data/armadillo.obj";

// The articulated recipe (as bench_fit --articulated DEG --markers 16): parts turned by
// `deg`, ×1.1, σ 0.2 %, no outliers, 25 % hole, 16 farthest-point markers.
synth::Scenario cmp_articulated(const char* mesh, std::vector<synth::Joint> joints, unsigned seed, int points = 30000) {
  synth::ScenarioOptions opt;
  opt.points = points;
  opt.markers = 16;
  opt.bend_deg = opt.twist_deg = 0;
  opt.scale = 1.1;
  opt.outliers = 0;
  opt.seed = seed;
  opt.joints = std::move(joints);
  return synth::make_scenario(read_mesh(test::shared(mesh)), opt);
}

FitReport cmp_fit(const synth::Scenario& s, const FitParameters& p, TriMesh& out, const ProgressCallback& progress = {}) {
  std::vector<VertexStatus> st;
  return fit_template(s.templ, s.P, s.N, s.markers, {}, p, out, st, progress);
}
}  // namespace

// The bunny's head turned by 15°: the fit without the coarse stage leaves 1 point beyond r_max,
// so the coarse stage's fit (which could only be kept with more than 10 fewer) is stopped; the
// result is the fit without it, bit for bit, whether the two ran side by side or (one OpenMP
// thread) the second was not started.
TEST(CoarseCompare, TheCoarseFitIsStoppedWhenTheFirstLeavesNothingToExplain) {
  TBSP_REQUIRE_FILE(test::shared(kCmpBunny));
  const synth::Scenario s = cmp_articulated(kCmpBunny, synth::bunny_head_and_ears(15), 1);
  TriMesh a, b, c;
  const FitReport ra = cmp_fit(s, FitParameters{}, a);
  EXPECT_FALSE(ra.coarse_compared) << ra.message;
  ASSERT_EQ(ra.coarse_far_points.size(), 1u);
  EXPECT_LE(ra.coarse_far_points[0], 10);
  EXPECT_EQ(ra.coarse_nodes, 0);
  FitParameters off;
  off.coarse_nodes = 0;
  const FitReport rb = cmp_fit(s, off, b);
  EXPECT_TRUE(rb.coarse_far_points.empty());
  EXPECT_TRUE(a.V == b.V) << "largest difference " << (a.V - b.V).cwiseAbs().maxCoeff();
  const int threads = omp_get_max_threads();
  omp_set_num_threads(1);
  const FitReport rc = cmp_fit(s, FitParameters{}, c);
  omp_set_num_threads(threads);
  EXPECT_NE(rc.message.find("not run"), std::string::npos) << rc.message;
  EXPECT_TRUE(c.V == b.V) << "largest difference " << (c.V - b.V).cwiseAbs().maxCoeff();
}

// Stray outliers lie far from any fit: the bunny ground truth (bend + twist, ×2, 20 markers, 10 %
// uniform outliers) leaves ~2,800 of its points beyond r_max from the fit without the coarse stage
// and from the fit with it alike. Isolated points do not start the coarse stage's fit: the fit
// without it leaves 5 points that are not isolated (measured, seed 1), so the other is stopped —
// the same fit bit for bit as coarse_nodes = 0 (0.6 → 0.25 s on two cores).
TEST(CoarseCompare, StrayOutliersDoNotStartTheCoarseFit) {
  TBSP_REQUIRE_FILE(test::shared(kCmpBunny));
  const synth::Scenario s = synth::make_scenario(read_mesh(test::shared(kCmpBunny)), {});
  TriMesh a, b;
  const FitReport ra = cmp_fit(s, FitParameters{}, a);
  EXPECT_FALSE(ra.coarse_compared) << ra.message;
  ASSERT_EQ(ra.coarse_far_points.size(), 1u);
  EXPECT_LE(ra.coarse_far_points[0], 10);
  EXPECT_NE(ra.message.find("not isolated"), std::string::npos) << ra.message;
  const double beyond = (1.0 - ra.coverage_points) * double(s.P.rows());  // every point is in the ROI here
  std::printf("  points beyond r_max: %.0f, of them not isolated: %lld\n", beyond, static_cast<long long>(ra.coarse_far_points[0]));
  EXPECT_GT(beyond, 1000);  // measured ~2,800: the outliers
  FitParameters off;
  off.coarse_nodes = 0;
  cmp_fit(s, off, b);
  EXPECT_TRUE(a.V == b.V) << "largest difference " << (a.V - b.V).cwiseAbs().maxCoeff();
}

// The SMPL human with arms, head and a knee turned by 45°: no region of the scan is unexplained
// (a hand's points are too few), but 313 points lie beyond r_max from the fit without the coarse
// stage and 82 from the fit with it, which is kept: clean Hausdorff 1.55 → 0.64 % (measured). The
// same fit on one thread as on two and as a fit with the coarse stage alone, and a cancel from
// the caller is a Cancelled, not a fit.
TEST(CoarseCompare, TheTurnedHumansHandsComeBackWithTheCoarseStage) {
  TBSP_REQUIRE_FILE(test::shared(kCmpHuman));
  const synth::Scenario s = cmp_articulated(kCmpHuman, synth::human_limbs(45), 1);
  TriMesh a, b, off_fit;
  std::vector<double> progress;
  const FitReport ra = cmp_fit(s, FitParameters{}, a, [&](double f, const std::string&) {
    progress.push_back(f);
    return true;
  });
  ASSERT_TRUE(ra.coarse_compared) << ra.message;
  ASSERT_EQ(ra.coarse_far_points.size(), 2u);
  EXPECT_LT(ra.coarse_far_points[1] + 10, ra.coarse_far_points[0]);
  EXPECT_EQ(ra.coarse_nodes, 400);
  EXPECT_TRUE(ra.unexplained.empty()) << ra.message;
  ASSERT_FALSE(progress.empty());
  EXPECT_TRUE(std::is_sorted(progress.begin(), progress.end()));  // one bar over both fits
  EXPECT_EQ(progress.back(), 1.0);
  const synth::ScenarioErrors e = synth::evaluate(s, a);
  FitParameters off;
  off.coarse_nodes = 0;
  cmp_fit(s, off, off_fit);
  const synth::ScenarioErrors e_off = synth::evaluate(s, off_fit);
  std::printf("  human 45 deg: clean Hausdorff %.3f%% (without the coarse stage %.3f%%), %lld / %lld points beyond r_max\n",
              100 * e.hausdorff_clean_rel, 100 * e_off.hausdorff_clean_rel, static_cast<long long>(ra.coarse_far_points[0]),
              static_cast<long long>(ra.coarse_far_points[1]));
  EXPECT_LE(e.hausdorff_clean_rel, 0.009);       // measured 0.547 % (0.639 % before the coarse stage's second half)
  EXPECT_GE(e_off.hausdorff_clean_rel, 0.012);   // measured 1.548 %
  const int threads = omp_get_max_threads();
  omp_set_num_threads(1);
  cmp_fit(s, FitParameters{}, b);
  omp_set_num_threads(threads);
  EXPECT_TRUE(a.V == b.V) << "largest difference " << (a.V - b.V).cwiseAbs().maxCoeff();
  // the coarse stage's fit branches off the other after the initial pose: the same fit as one
  // that runs the coarse stage alone
  FitParameters coarse;
  coarse.coarse_nodes = 400;
  TriMesh alone;
  cmp_fit(s, coarse, alone);
  EXPECT_TRUE(a.V == alone.V) << "largest difference " << (a.V - alone.V).cwiseAbs().maxCoeff();
  int calls = 0;
  TriMesh cancelled;
  EXPECT_THROW(cmp_fit(s, FitParameters{}, cancelled, [&](double, const std::string&) { return ++calls < 8; }), Cancelled);
}

// The Armadillo's forearms and knee turned by 45° (100k points, as bench_fit's row): few of the
// 16 markers sit on a forearm, so the marker rotation field poses it distorted; the coarse
// stage's second half, on a graph built on the template itself, is rigid against the template's
// shape instead of that pose (fit_coarse.cpp). Seeds 1–3: clean Hausdorff 0.30–0.52 % with it,
// 0.80–1.28 % when the whole coarse stage measured rigidity against the field's pose.
TEST(CoarseCompare, TheArmadillosTurnedForearmsFollowTheTemplatesOwnShape) {
  TBSP_REQUIRE_FILE(test::shared(kCmpArmadillo));
  for (unsigned seed = 1; seed <= 3; ++seed) {
    const synth::Scenario s = cmp_articulated(kCmpArmadillo, synth::armadillo_limbs(45), seed, 100000);
    TriMesh out;
    const FitReport r = cmp_fit(s, FitParameters{}, out);
    const synth::ScenarioErrors e = synth::evaluate(s, out);
    std::printf("  Armadillo 45 deg, seed %u: clean Hausdorff %.3f%%, coarse stage %d steps\n", seed, 100 * e.hausdorff_clean_rel,
                r.coarse_steps);
    EXPECT_EQ(r.coarse_nodes, 400) << "seed " << seed << ": " << r.message;  // the coarse stage's fit kept
    EXPECT_LE(e.hausdorff_clean_rel, 0.007) << "seed " << seed;
  }
}
