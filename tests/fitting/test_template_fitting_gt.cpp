// Acceptance: ground-truth fitting scenarios built from a real mesh (issue: template fitting).
#include <gtest/gtest.h>

#include <cstdio>

#include "support/gt_scenario.h"
#include "test_util.h"
#include "tbsp/fitting/template_fitter.h"
#include "tbsp/io/mesh_io.h"

using namespace tbsp;

namespace {
TriMesh bunny() { return read_mesh(test::shared("meshes/libigl__libigl-tutorial-data/bunny.off")); }
}  // namespace

TEST(TemplateFittingGroundTruth, BendTwistScaleNoiseOutliersHole) {
  TBSP_REQUIRE_FILE(test::shared("meshes/libigl__libigl-tutorial-data/bunny.off"));
  test::ScenarioOptions o;
  const test::Scenario s = test::make_scenario(bunny(), o);
  ASSERT_GE(s.hole_area_fraction, 0.25);
  ASSERT_LE(s.markers.size(), 30u);
  TriMesh fit;
  std::vector<VertexStatus> st;
  const FitReport r = fit_template(s.templ, s.P, s.N, s.markers, {}, {}, fit, st);
  const test::ScenarioErrors e = test::evaluate(s, fit);
  std::printf("[bunny GT] scale %.3f, %d iterations, %.2f s; Hausdorff (clean samples) %.3f%%, (noisy inliers) %.3f%%, "
              "hole mean %.3f%%, all mean %.3f%%, report Hausdorff (all points) %.2f%%\n",
              r.scale, r.iterations, r.t_total, 100 * e.hausdorff_clean_rel, 100 * e.hausdorff_noisy_rel,
              100 * e.hole_mean_rel, 100 * e.all_mean_rel, 100 * r.hausdorff_rel);
  EXPECT_NEAR(r.scale, 2.0, 0.3);
  EXPECT_LE(e.hausdorff_clean_rel, 0.003);
  EXPECT_LE(e.hole_mean_rel, 0.01);
}
