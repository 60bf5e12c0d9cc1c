// MarkerAnimation (thesis §6.2, §9.1) against ground truth: the synthetic studio's performer,
// its marker trajectories (markers.trc: one marker per farthest-point-sampled vertex) and its
// ground-truth mesh per frame.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>

#include "test_util.h"
#include "tbsp/core/error.h"
#include "tbsp/io/mesh_io.h"
#include "tbsp/io/mocap_io.h"
#include "tbsp/io/studio.h"
#include "tbsp/multiview/marker_animation.h"
#include "tbsp/plugins/synth_studio.h"

using namespace tbsp;

namespace {

struct AnimSetup {
  Studio studio;
  TriMesh rest;
  MarkerTrajectories markers;
  std::vector<MarkerMapEntry> map;
  double diag = 0;
};

// Markers are named "V<vertex>" by synth-studio: the map follows from the names.
AnimSetup make_anim_setup(const std::string& name, int frames, int markers) {
  const auto dir = test::temp_dir(name);
  synth::StudioOptions so;
  so.frames = frames;
  so.markers = markers;
  so.width = so.height = 64;  // the images are not used
  synth::write_synthetic_studio(dir.string(), so);
  AnimSetup s;
  s.studio = read_studio((dir / "studio.yaml").string());
  s.rest = read_mesh((dir / "template.ply").string());
  s.markers = read_trc((dir / "markers.trc").string());
  for (const auto& n : s.markers.names) s.map.push_back({n, std::stoi(n.substr(1)), true});
  s.diag = (s.rest.V.colwise().maxCoeff() - s.rest.V.colwise().minCoeff()).norm();
  return s;
}

}  // namespace

TEST(MarkerAnimation, FollowsTheGroundTruthPerformer) {
  const AnimSetup s = make_anim_setup("marker_anim", 25, 40);
  MarkerAnimation anim;
  MarkerAnimationOptions o;
  o.tets = 3000;
  anim.setOptions(o);
  anim.setTemplate(s.rest);
  anim.setMarkerMap(s.map);
  anim.setMarkers(s.markers.names, s.markers.data);
  TriMesh m;
  double worst = 0, med_res = 0;
  int frames = 0;
  while (anim.next(m)) {
    const TriMesh gt = read_mesh(s.studio.groundTruthPath(frames));
    ASSERT_EQ(m.V.rows(), gt.V.rows());
    const double err = (m.V - gt.V).rowwise().norm().mean() / s.diag;
    worst = std::max(worst, err);
    med_res = std::max(med_res, anim.report().frames.back().median_residual / s.diag);
    ++frames;
  }
  const auto& r = anim.report();
  std::printf("  %d frames, %ld tet vertices, %ld tets; alignment scale %.4f rms %.2e; worst mean vertex error %.3f %% of the diagonal, "
              "worst median marker residual %.3f %%; %.2f ms deform + %.2f ms transfer per frame (last frame)\n",
              frames, long(r.tet_vertices), long(r.tets), r.scale, r.alignment_rms, 100 * worst, 100 * med_res, 1000 * r.frames.back().seconds_deform,
              1000 * r.frames.back().seconds_transfer);
  EXPECT_EQ(frames, 25);
  EXPECT_NEAR(r.scale, 1.0, 0.05);  // the rest pose and frame 0 differ by the scripted pose only
  EXPECT_LT(med_res, 0.005);  // measured 0.08 %
  EXPECT_LT(worst, 0.02);     // measured 1.13 % (40 markers on a performer of 7 separate parts)
}

TEST(MarkerAnimation, GapsAreDroppedForTheirFramesNotZeroed) {
  AnimSetup s = make_anim_setup("marker_gaps", 12, 30);
  // Marker 3 is missing in frames 4..7, marker 5 in frame 9.
  for (int f = 4; f <= 7; ++f) s.markers.data.block<1, 3>(f, 9).setConstant(NAN);
  s.markers.data.block<1, 3>(9, 15).setConstant(NAN);
  MarkerAnimation anim;
  MarkerAnimationOptions o;
  o.tets = 2000;
  anim.setOptions(o);
  anim.setTemplate(s.rest);
  anim.setMarkerMap(s.map);
  anim.setMarkers(s.markers.names, s.markers.data);
  TriMesh m;
  int frames = 0;
  while (anim.next(m)) {
    const TriMesh gt = read_mesh(s.studio.groundTruthPath(frames));
    const double err = (m.V - gt.V).rowwise().norm().mean() / s.diag;
    EXPECT_LT(err, 0.02) << "frame " << frames;
    EXPECT_TRUE(m.V.allFinite());
    ++frames;
  }
  const auto& r = anim.report();
  EXPECT_EQ(frames, 12);
  ASSERT_EQ(r.frames.size(), 12u);
  EXPECT_EQ(r.frames[5].missing, std::vector<std::string>(1, s.markers.names[3]));
  EXPECT_EQ(r.frames[5].markers_used, 29);
  EXPECT_EQ(r.frames[9].missing, std::vector<std::string>(1, s.markers.names[5]));
  EXPECT_TRUE(r.frames[4].rebuilt);
  EXPECT_FALSE(r.frames[5].rebuilt);
  EXPECT_FALSE(r.frames[8].rebuilt);  // back to the full set: its deformer is kept
  EXPECT_EQ(r.deformers_built, 3);
}

TEST(MarkerAnimation, BadInputGivesClearErrors) {
  TriMesh rest = synth::make_humanoid(0).mesh;
  Eigen::MatrixXd data = Eigen::MatrixXd::Zero(2, 9);
  for (int k = 0; k < 3; ++k) data.block<2, 3>(0, 3 * k) = rest.V.row(k * 50).replicate(2, 1);
  const std::vector<std::string> names{"A", "B", "C"};
  auto expect_error = [&](const std::vector<MarkerMapEntry>& map, const std::string& needle) {
    MarkerAnimation anim;
    anim.setTemplate(rest);
    anim.setMarkerMap(map);
    anim.setMarkers(names, data);
    TriMesh out;
    try {
      anim.next(out);
      ADD_FAILURE() << "no error for " << needle;
    } catch (const InvalidInput& e) {
      EXPECT_NE(std::string(e.what()).find(needle), std::string::npos) << e.what();
    }
  };
  expect_error({{"A", 0, true}, {"B", 50, true}, {"LFHD", 100, true}}, "'LFHD'");
  expect_error({{"A", 0, true}, {"B", 50, true}, {"C", 999999, true}}, "vertex 999999");
  expect_error({{"A", 0, true}, {"A", 50, true}, {"C", 100, true}}, "mapped twice");
  expect_error({}, "map is empty");
  expect_error({{"A", 0, true}, {"B", 50, false}, {"C", 100, false}}, "3 or more");
  MarkerAnimationOptions o;
  o.iterations = 0;
  MarkerAnimation anim;
  EXPECT_THROW(anim.setOptions(o), InvalidInput);
}
