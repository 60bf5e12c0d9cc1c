// Silhouette refinement on real images (thesis §6.3, issue acceptance "real images"): the SMPL
// woman of ../shared/data posed by hand-placed joint markers (sample_data/poses/*.json: pixels
// in three views, triangulated) and refined to the silhouettes of
// - the INRIA dancer (8 views, 780x582, 3x4 P matrices, PBM silhouettes; a knee-length dress
//   the naked template does not have), and
// - the Tsinghua dome subject WD2 (20 views, 1024x768, K + radial distortion + [R|t]).
// Figures: docs/silhouette_refinement.md ("Real images").
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

#include <opencv2/imgcodecs.hpp>

#include "test_util.h"
#include "tbsp/io/camera_io.h"
#include "tbsp/io/mesh_io.h"
#include "tbsp/multiview/marker_animation.h"
#include "tbsp/multiview/silhouette_refinement.h"
#include "tbsp/multiview/visual_hull.h"
#include "tbsp/plugins/marker_map_json.h"

using namespace tbsp;

namespace {

const char* kSmpl = "meshes/odedstein__meshes/objects/human/human_woman.obj";
const char* kDancer = "capture/Nikhil-void__Computer-Vision-Projects/Visual Hull 3D Surface Estimation/input_data/";
const char* kDome = "capture/wl-zhao__VisualHull/";

struct RealCase {
  std::vector<Camera> cams;
  std::vector<cv::Mat> silhouettes;
};

cv::Mat read_mask(const std::string& path) {
  cv::Mat m = cv::imread(path, cv::IMREAD_GRAYSCALE);
  if (m.empty()) return m;
  return m >= 128;  // WD2 cam16's mask is not strictly binary
}

struct RealResult {
  ImagePoseReport pose;
  SilhouetteRefinementReport refine;
  double worst_rms = 0, iou_before_mean = 0, iou_after_mean = 0, iou_after_min = 1, gain_min = 1;
  TriMesh posed, refined;
};

RealResult pose_and_refine(const RealCase& c, const std::string& pose_json) {
  const TriMesh tmpl = read_mesh(test::shared(kSmpl));
  const MarkerMap map = load_marker_map(pose_json);
  RealResult r;
  r.posed = pose_template_to_image_markers(tmpl, map.markers, map.image_markers, c.cams, {}, {}, &r.pose);
  SilhouetteRefinement sr;
  sr.setInputFrame(c.cams, c.silhouettes);
  sr.setInputMesh(r.posed);
  sr.refine(r.refined);
  r.refine = sr.report();
  for (const auto& m : r.pose.markers) r.worst_rms = std::max(r.worst_rms, m.rms_px);
  std::printf("  markers (rms px):");
  for (const auto& m : r.pose.markers) std::printf(" %s %.1f", m.marker.c_str(), m.rms_px);
  std::printf("\n  alignment scale %.3f rms %.3f; residual median %.3f max %.3f (world units); %d refinement iterations, %.1f s\n",
              r.pose.animation.scale, r.pose.animation.alignment_rms, r.pose.animation.frames.front().median_residual,
              r.pose.animation.frames.front().max_residual, r.refine.iterations, r.refine.seconds);
  std::printf("  | view | IoU posed | IoU refined | XOR posed | XOR refined |\n");
  for (const auto& v : r.refine.views) {
    std::printf("  | %s | %.3f | %.3f | %ld | %ld |\n", v.camera.c_str(), v.iou_before, v.iou_after, v.xor_before, v.xor_after);
    r.iou_before_mean += v.iou_before / double(r.refine.views.size());
    r.iou_after_mean += v.iou_after / double(r.refine.views.size());
    r.iou_after_min = std::min(r.iou_after_min, v.iou_after);
    r.gain_min = std::min(r.gain_min, v.iou_after - v.iou_before);
  }
  std::printf("  mean IoU %.3f -> %.3f (worst view after %.3f); XOR %ld -> %ld pixels\n", r.iou_before_mean, r.iou_after_mean, r.iou_after_min,
              r.refine.xor_before, r.refine.xor_after);
  return r;
}

// The bounds a case must meet (each set from the measured figures, with margin).
struct Bounds {
  double max_click_rms_px, min_view_iou, min_mean_iou, min_view_gain;
  long xor_divisor;  ///< all-view XOR after <= before / this
};
void expect_within(const RealResult& r, const Bounds& b) {
  EXPECT_LE(r.worst_rms, b.max_click_rms_px);
  EXPECT_GE(r.iou_after_min, b.min_view_iou);
  EXPECT_GE(r.iou_after_mean, b.min_mean_iou);
  EXPECT_GE(r.gain_min, b.min_view_gain);
  EXPECT_LT(r.refine.xor_after, r.refine.xor_before / b.xor_divisor);
}

// The visual hull of the real silhouettes (multiview/visual_hull.h): the refined mesh lies in it,
// and the marker-posed template turned by 10°, scaled by 1.05 and moved is brought back by the
// hull registration to about the IoU of the marker pose. Returns the fraction of refined
// vertices inside the hull (within one voxel).
double hull_check(const RealCase& c, const RealResult& r) {
  VisualHullOptions ho;
  const VisualHull h = compute_visual_hull(c.cams, c.silhouettes, ho);
  long inside = 0;
  for (Eigen::Index i = 0; i < r.refined.V.rows(); ++i) {
    const Eigen::Vector3d g = (r.refined.V.row(i).transpose() - h.origin) / h.voxel;
    bool in = false;
    for (int dz = -1; dz <= 1 && !in; ++dz)
      for (int dy = -1; dy <= 1 && !in; ++dy)
        for (int dx = -1; dx <= 1 && !in; ++dx) {
          const int x = int(std::lround(g.x())) + dx, y = int(std::lround(g.y())) + dy, z = int(std::lround(g.z())) + dz;
          in = x >= 0 && y >= 0 && z >= 0 && x < h.dims.x() && y < h.dims.y() && z < h.dims.z() && h.occupied[h.index(x, y, z)];
        }
    inside += in;
  }
  const double frac = double(inside) / double(r.refined.V.rows());
  const Eigen::Vector3d c0 = r.posed.V.colwise().mean().transpose();
  const double diag = (r.posed.V.colwise().maxCoeff() - r.posed.V.colwise().minCoeff()).norm();
  // the up direction: the cameras' mean image-up vector (-y of each camera)
  Eigen::Vector3d up = Eigen::Vector3d::Zero();
  for (const auto& cam : c.cams) up -= cam.R().row(1).transpose();
  Eigen::Matrix4d off = Eigen::Matrix4d::Identity();
  off.topLeftCorner<3, 3>() = 1.05 * Eigen::AngleAxisd(10 * M_PI / 180, up.normalized()).toRotationMatrix();
  off.topRightCorner<3, 1>() = c0 - off.topLeftCorner<3, 3>() * c0 + 0.03 * diag * Eigen::Vector3d(1, 1, 1).normalized();
  TriMesh rough = r.posed;
  rough.V = transform_points(off, r.posed.V);
  const HullRegistration reg = register_to_visual_hull(rough, c.cams, c.silhouettes, ho);
  std::printf("  icp %d iterations, converged %d, rms %.4g\n", reg.icp.iterations, int(reg.icp.converged), reg.icp.rms);
  const double back = (transform_points(reg.icp.transform, rough.V) - r.posed.V).rowwise().norm().mean() / diag;
  std::printf("  visual hull: %ld samples, voxel %.4g, %.1f %% of the refined vertices inside; marker pose turned 10 deg: IoU %.3f -> %.3f "
              "(marker pose %.3f), %.2f %% of the diagonal from the marker pose, %.2f s\n",
              long(h.points.rows()), h.voxel, 100 * frac, reg.iou_before, reg.iou_after, r.iou_before_mean, 100 * back, reg.seconds);
  EXPECT_GT(reg.iou_after, reg.iou_before + 0.1);
  EXPECT_GT(reg.iou_after, r.iou_before_mean - 0.05);
  return frac;
}

}  // namespace

TEST(SilhouetteReal, InriaDancerPosedByHandPlacedMarkersAndRefined) {
  const std::string dir = test::shared(kDancer);
  TBSP_REQUIRE_FILE(dir + "calibration/cam00.xml");
  TBSP_REQUIRE_FILE(test::shared(kSmpl));
  RealCase c;
  for (int k = 0; k < 8; ++k) {
    const std::string n = "cam0" + std::to_string(k);
    c.cams.push_back(read_projection_matrix(dir + "calibration/" + n + ".xml", 780, 582, n));
    c.silhouettes.push_back(read_mask(dir + "silh_" + n + "_00023_0000008550.pbm"));
    ASSERT_FALSE(c.silhouettes.back().empty()) << n;
  }
  const RealResult r = pose_and_refine(c, test::sample("poses/dancer_smpl_pose.json"));
  // Hand clicks of joint centres in 780x582 images: measured <= 8.6 px (a knee under the dress).
  // IoU measured: posed 0.57-0.73, refined 0.90-0.96 per view (the dress is not in the template),
  // gain >= 0.23, XOR 46,881 -> 7,442.
  expect_within(r, {12.0, 0.87, 0.91, 0.15, 3});
  // measured: 97.0 % inside; from 10°: IoU 0.537 -> 0.664 (marker pose 0.638), 1.8 % of the diagonal off
  EXPECT_GT(hull_check(c, r), 0.9);
}

TEST(SilhouetteReal, TsinghuaDomeWd2PosedByHandPlacedMarkersAndRefined) {
  const std::string dir = test::shared(kDome);
  TBSP_REQUIRE_FILE(dir + "calibParamsI.txt");
  TBSP_REQUIRE_FILE(test::shared(kSmpl));
  RealCase c;
  c.cams = read_dome_calibration(dir + "calibParamsI.txt", 1024, 768);
  ASSERT_EQ(c.cams.size(), 20u);
  for (const auto& cam : c.cams) {
    const std::string idx = cam.name().substr(3);
    c.silhouettes.push_back(read_mask(dir + "wd_segmented/WD2_" + idx + "_00020_segmented.png"));
    ASSERT_FALSE(c.silhouettes.back().empty()) << cam.name();
  }
  const RealResult r = pose_and_refine(c, test::sample("poses/wd2_smpl_pose.json"));
  // Clicks measured <= 19 px (an elbow) in 1024x768 images; IoU posed 0.60-0.69, refined
  // 0.95-0.97 in all 20 views, XOR 625,687 -> 46,328.
  expect_within(r, {25.0, 0.93, 0.95, 0.2, 5});
  // measured: 93.3 % inside (20 views: a vertex a few pixels outside any one silhouette is out);
  // from 10°: IoU 0.575 -> 0.771 (marker pose 0.647), 3.5 % of the diagonal off
  EXPECT_GT(hull_check(c, r), 0.9);
}
