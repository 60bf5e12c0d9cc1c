// PerformanceCapture (thesis §9.2) against ground truth: the synthetic studio's performer (a
// humanoid with a skirt, parts modelled as overlapping closed bodies, a solid texture), rendered
// into 8 calibrated views; the template is the rest pose, tracked through the sequence from the
// images and silhouettes alone and compared with the ground-truth mesh of every frame.
// The 60-frame, 1004 x 1004 acceptance run is `bench_capture_perf --capture-frames 60`
// (docs/performance_capture.md); this test runs 30 frames at 600 x 600 to stay fast.
#include <gtest/gtest.h>

#include <algorithm>
#include <Eigen/Geometry>
#include <cmath>
#include <cstdio>
#include <string>

#include "test_util.h"
#include "tbsp/core/error.h"
#include "tbsp/io/mesh_io.h"
#include "tbsp/io/studio.h"
#include "tbsp/multiview/performance_capture.h"
#include "tbsp/plugins/synth_studio.h"

using namespace tbsp;

namespace {

struct Sequence {
  Studio studio;
  TriMesh rest;
  double diag = 0;
};

Sequence make_sequence(const std::string& name, int frames, int size) {
  const auto dir = test::temp_dir(name);
  synth::StudioOptions so;
  so.frames = frames;
  so.width = so.height = size;
  so.markers = 4;
  synth::write_synthetic_studio(dir.string(), so);
  Sequence s;
  s.studio = read_studio((dir / "studio.yaml").string());
  s.rest = read_mesh((dir / "template.ply").string());
  s.diag = (s.rest.V.colwise().maxCoeff() - s.rest.V.colwise().minCoeff()).norm();
  return s;
}

StudioFrame first_frame(const Studio& st) {
  StudioFrameStream stream(st, {});
  StudioFrame f;
  stream.next(f);
  return f;
}

}  // namespace

TEST(PerformanceCapture, TracksTheSyntheticPerformerWithoutDrift) {
  const Sequence s = make_sequence("perf_capture", 30, 600);
  PerformanceCapture pc;
  pc.setCameras(s.studio.cameraList());
  pc.setTemplate(s.rest);
  StudioFrameStream stream(s.studio, {});
  StudioFrame f;
  std::vector<double> err;
  std::vector<int> anchors;
  double worst_iou = 1;
  while (stream.next(f)) {
    TriMesh m;
    pc.track(f.images, f.silhouettes, f.frame, m);
    const TriMesh gt = read_mesh(s.studio.groundTruthPath(f.frame));
    ASSERT_EQ(m.V.rows(), gt.V.rows());
    ASSERT_EQ(m.F, s.rest.F);  // constant connectivity
    err.push_back((m.V - gt.V).rowwise().norm().mean() / s.diag);
    const CaptureFrameReport& fr = pc.report().frames.back();
    worst_iou = std::min(worst_iou, fr.iou_min);
    std::printf("frame %2d: mean vertex error %.3f %% of the diagonal, view IoU min %.4f mean %.4f (pose %.4f), %d matches (%d anchor), "
                "%d rims, %.2f s\n",
                f.frame, 100 * err.back(), fr.iou_min, fr.iou_mean, fr.iou_pose, fr.temporal_matches + fr.anchor_matches, fr.anchor_matches,
                fr.rim_constraints, fr.t_total);
    if (f.frame > 0) {
      EXPECT_GT(fr.temporal_matches, 200) << "frame " << f.frame;
    }
    anchors.push_back(fr.anchor_matches);
  }
  ASSERT_EQ(err.size(), 30u);
  const double worst = *std::max_element(err.begin(), err.end());
  std::printf("worst frame error %.3f %%, worst view IoU %.4f, last/frame-5 error %.2f\n", 100 * worst, worst_iou, err.back() / err[5]);
  // acceptance (issue 25): <= 1 % on every frame, IoU >= 0.97 per view, no drift; measured
  // 0.50 % / 0.987 / 1.21 (docs/performance_capture.md)
  EXPECT_LT(worst, 0.01);
  // The body turns: first-frame anchors from every view keep matching (measured 1044 at frame 2,
  // 565 at frame 29; same-camera anchors only: ~990 -> ~360).
  EXPECT_GT(anchors.back(), 0.45 * anchors[2]);
  EXPECT_GE(worst_iou, 0.97);
  EXPECT_LE(err.back(), 1.5 * err[5]);
  EXPECT_EQ(pc.report().failed_frames, 0);
}

TEST(PerformanceCapture, BadInputIsAClearError) {
  const Sequence s = make_sequence("perf_capture_bad", 1, 120);
  const StudioFrame f = first_frame(s.studio);
  const std::vector<Camera> cams = s.studio.cameraList();
  auto fresh = [&]() {
    auto pc = std::make_unique<PerformanceCapture>();
    pc->setCameras(cams);
    pc->setTemplate(s.rest);
    return pc;
  };
  TriMesh out;
  out.V = Eigen::MatrixX3d::Constant(1, 3, 7.0);
  auto expect_error = [&](PerformanceCapture& pc, const std::vector<cv::Mat>& im, const std::vector<cv::Mat>& sil, const std::string& needle) {
    try {
      pc.track(im, sil, 0, out);
      ADD_FAILURE() << "no error, expected one naming '" << needle << "'";
    } catch (const InvalidInput& e) {
      EXPECT_NE(std::string(e.what()).find(needle), std::string::npos) << e.what();
    }
    EXPECT_EQ(out.V.rows(), 1);  // untouched
  };
  {  // a silhouette of the wrong size
    auto sil = f.silhouettes;
    sil[2] = cv::Mat(50, 60, CV_8U, cv::Scalar(255));
    expect_error(*fresh(), f.images, sil, "calibrated size");
  }
  {  // an empty silhouette
    auto sil = f.silhouettes;
    sil[1] = cv::Mat(sil[1].size(), CV_8U, cv::Scalar(0));  // a new buffer: the frame's own stays intact
    expect_error(*fresh(), f.images, sil, "empty");
  }
  {  // an image missing
    auto im = f.images;
    im.pop_back();
    expect_error(*fresh(), im, f.silhouettes, "one image per camera");
  }
  {  // the template outside every view
    auto pc = fresh();
    TriMesh far = s.rest;
    far.V.rowwise() += Eigen::RowVector3d(0, 0, 1000);
    pc->setTemplate(far);
    expect_error(*pc, f.images, f.silhouettes, "outside every view");
  }
  {  // no cameras
    PerformanceCapture pc;
    pc.setTemplate(s.rest);
    expect_error(pc, f.images, f.silhouettes, "no cameras");
  }
  PerformanceCaptureOptions bad;
  bad.handles = 2;
  EXPECT_THROW(PerformanceCapture().setOptions(bad), InvalidInput);
  bad = PerformanceCaptureOptions{};
  bad.features = bad.silhouettes = false;
  EXPECT_THROW(PerformanceCapture().setOptions(bad), InvalidInput);
  bad = PerformanceCaptureOptions{};
  bad.reject_px = bad.robust_px;
  EXPECT_THROW(PerformanceCapture().setOptions(bad), InvalidInput);
  bad = PerformanceCaptureOptions{};
  bad.anchor_weight = 0;
  EXPECT_THROW(PerformanceCapture().setOptions(bad), InvalidInput);
  bad = PerformanceCaptureOptions{};
  bad.keyframe_interval = -1;
  EXPECT_THROW(PerformanceCapture().setOptions(bad), InvalidInput);
  bad = PerformanceCaptureOptions{};
  bad.keyframe_iou = 1.5;
  EXPECT_THROW(PerformanceCapture().setOptions(bad), InvalidInput);
}

TEST(PerformanceCapture, SilhouettesOnlyAndHandleOptimizationRun) {
  // The silhouette-only mode, the black-box handle optimization (NLopt) and model-guided stereo
  // after the refinement on 3 frames: they run, keep the overlap high and the optimizer does not
  // make the overlap worse.
  const Sequence s = make_sequence("perf_capture_modes", 3, 300);
  for (const int mode : {0, 1, 2, 3}) {
    const bool optimize = mode == 1, stereo = mode == 2, keyframes = mode == 3;
    PerformanceCaptureOptions o;
    if (keyframes) {  // every tracked frame after the first becomes a keyframe
      o.keyframe_interval = 1;
      o.keyframe_iou = 0.5;
    }
    o.features = mode > 0;  // mode 0 runs on silhouettes alone
    o.optimize_handles = optimize;
    o.stereo_refine = stereo;
    o.max_evaluations = 60;
    o.tets = 3000;
    PerformanceCapture pc;
    pc.setOptions(o);
    pc.setCameras(s.studio.cameraList());
    pc.setTemplate(s.rest);
    StudioFrameStream stream(s.studio, {});
    StudioFrame f;
    while (stream.next(f)) {
      TriMesh m;
      pc.track(f.images, f.silhouettes, f.frame, m);
      const CaptureFrameReport& fr = pc.report().frames.back();
      EXPECT_GT(fr.iou_min, 0.9) << "frame " << f.frame << " mode " << mode;
      if (optimize) {
        EXPECT_GT(fr.evaluations, 10);
        // the objective (1 - IoU + penalties) never increases; the overlap alone may give a little
        EXPECT_GE(fr.opt_iou_after, fr.opt_iou_before - 0.005);
        std::printf("frame %d: handle optimization %d evaluations, control IoU %.4f -> %.4f\n", f.frame, fr.evaluations, fr.opt_iou_before,
                    fr.opt_iou_after);
      } else if (stereo) {
        EXPECT_GT(fr.stereo_points, 100) << "frame " << f.frame;
        EXPECT_GT(fr.t_stereo, 0.0);
      } else if (keyframes) {
        EXPECT_EQ(fr.keyframe, pc.report().frames.size() > 1) << "frame " << f.frame;
        if (pc.report().frames.size() > 2) {
          EXPECT_GT(fr.anchor_matches, 0) << "frame " << f.frame;
        }
      } else {
        EXPECT_EQ(fr.keypoints, 0);
        EXPECT_EQ(fr.stereo_points, 0);
      }
    }
  }
  PerformanceCaptureOptions bad;
  bad.stereo_refine = true;
  bad.features = false;  // stereo needs the images
  EXPECT_THROW(PerformanceCapture().setOptions(bad), InvalidInput);
}

TEST(PerformanceCapture, RegistersARoughlyPlacedTemplateToTheVisualHull) {
  const Sequence s = make_sequence("perf_capture_hull", 4, 600);
  // the template turned by 15° about the vertical through its centroid, scaled by 1.08 and moved
  // by 5 % of its diagonal: a template placed by eye
  const Eigen::Vector3d c = s.rest.V.colwise().mean().transpose();
  Eigen::Matrix4d off = Eigen::Matrix4d::Identity();
  off.topLeftCorner<3, 3>() = 1.08 * Eigen::AngleAxisd(15 * M_PI / 180, Eigen::Vector3d::UnitY()).toRotationMatrix();
  off.topRightCorner<3, 1>() = c - off.topLeftCorner<3, 3>() * c + 0.05 * s.diag * Eigen::Vector3d(1, 0.3, -0.6).normalized();
  TriMesh rough = s.rest;
  rough.V = transform_points(off, s.rest.V);
  double worst_as_placed = 0;
  for (const bool reg : {false, true}) {
    PerformanceCapture pc;
    PerformanceCaptureOptions o;
    o.register_to_hull = reg;
    pc.setOptions(o);
    pc.setCameras(s.studio.cameraList());
    pc.setTemplate(rough);
    StudioFrameStream stream(s.studio, {});
    StudioFrame f;
    double worst = 0, worst_iou = 1;
    while (stream.next(f)) {
      TriMesh m;
      pc.track(f.images, f.silhouettes, f.frame, m);
      const TriMesh gt = read_mesh(s.studio.groundTruthPath(f.frame));
      const double e = (m.V - gt.V).rowwise().norm().mean() / s.diag;
      worst = std::max(worst, e);
      worst_iou = std::min(worst_iou, pc.report().frames.back().iou_min);
      std::printf("%s frame %d: mean vertex error %.3f %%, view IoU min %.4f\n", reg ? "hull-registered" : "as placed", f.frame, 100 * e,
                  pc.report().frames.back().iou_min);
    }
    if (reg) {
      const HullRegistration& h = pc.report().hull;
      ASSERT_TRUE(pc.report().hull_registered) << pc.report().hull_message;
      std::printf("hull registration: %.2f deg, scale %.4f (1/1.08 = %.4f), IoU %.3f -> %.3f, %d samples, %.2f s\n", h.icp.rotation_deg,
                  h.icp.scale, 1 / 1.08, h.iou_before, h.iou_after, h.hull_points, h.seconds);
      EXPECT_GT(h.iou_after, h.iou_before + 0.1);
      EXPECT_LT(worst, 0.01);
      EXPECT_GE(worst_iou, 0.97);
      // as placed, the silhouettes are matched (IoU ~0.975) but the body stays turned: measured 1.6 % against 0.4 %
      EXPECT_GT(worst_as_placed, 2 * worst);
    } else {
      worst_as_placed = worst;
    }
  }
}
