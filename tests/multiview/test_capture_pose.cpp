// The pose step of PerformanceCapture (internal: pcl_ext/src/multiview/capture_pose.h): the
// normal equations assembled by BLAS rank-k updates against the textbook sum, the handle solve
// recovering a known handle move, the rim matches its silhouette constraints come from, and
// the mask gradient and overlap measures those use.
#include <gtest/gtest.h>

#include <random>

#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include "capture_pose.h"
#include "silhouette_match.h"
#include "tbsp/mesh/primitives.h"
#include "tbsp/multiview/rasterizer.h"

using namespace tbsp;
using namespace tbsp::detail;

namespace {

// Constraints on the rows of M at random points: a ray or a plane through p + m_i·Δh.
std::vector<RayConstraint> make_constraints(const Eigen::MatrixXd& M, const Eigen::MatrixX3d& dh, unsigned seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> g(0, 1);
  std::uniform_real_distribution<double> u(0.5, 2.0);
  auto unit = [&]() { return Eigen::Vector3d(g(rng), g(rng), g(rng)).normalized(); };
  std::vector<RayConstraint> C(std::size_t(M.rows()));
  for (Eigen::Index i = 0; i < M.rows(); ++i) {
    RayConstraint& c = C[std::size_t(i)];
    c.v[0] = int(i);
    c.w[0] = 1;
    c.p = Eigen::Vector3d(g(rng), g(rng), g(rng));
    const Eigen::Vector3d q = c.p + (M.row(i) * dh).transpose();  // where the point must go
    c.pixel_size = u(rng);
    c.weight = u(rng);
    if (i % 3 == 0) {  // plane (a silhouette rim)
      c.plane_normal = unit();
      c.origin = q + c.plane_normal.cross(unit());  // in the plane
      c.dir = unit();
      c.feature = false;
    } else {
      c.dir = unit() * u(rng);  // not normalized: the projector normalizes it
      c.origin = q - 2.5 * c.dir;
    }
  }
  return C;
}

}  // namespace

TEST(CapturePose, RankUpdateNormalsEqualTheDirectSum) {
  const Eigen::Index H = 7, nc = 2500;  // > one block of 1024 rows
  std::mt19937 rng(3);
  std::normal_distribution<double> g(0, 1);
  Eigen::MatrixXd M(nc, H);
  for (Eigen::Index i = 0; i < M.size(); ++i) M.data()[i] = g(rng);
  const std::vector<RayConstraint> C = make_constraints(M, Eigen::MatrixX3d::Zero(H, 3), 5);
  std::vector<double> omega(C.size());
  for (std::size_t i = 0; i < C.size(); ++i) omega[i] = i % 11 == 0 ? 0.0 : C[i].weight * (1 + 0.1 * double(i % 5));
  Eigen::MatrixXd direct = Eigen::MatrixXd::Zero(3 * H, 3 * H);
  for (std::size_t i = 0; i < C.size(); ++i) {
    const Eigen::Matrix3d P = constraint_projector(C[i]);
    const Eigen::MatrixXd mm = M.row(Eigen::Index(i)).transpose() * M.row(Eigen::Index(i));
    for (int c = 0; c < 3; ++c)
      for (int q = 0; q < 3; ++q) direct.block(c * H, q * H, H, H) += omega[i] * P(c, q) / (C[i].pixel_size * C[i].pixel_size) * mm;
  }
  const Eigen::MatrixXd N = assemble_constraint_normals(M, C, omega);
  EXPECT_LT((N - direct).cwiseAbs().maxCoeff(), 1e-11 * direct.cwiseAbs().maxCoeff());
  EXPECT_EQ((N - N.transpose()).cwiseAbs().maxCoeff(), 0.0);
  for (const RayConstraint& c : C) {  // the basis spans the projector
    Eigen::Vector3d u[2];
    const int r = constraint_projector_basis(c, u);
    Eigen::Matrix3d P = Eigen::Matrix3d::Zero();
    for (int k = 0; k < r; ++k) P += u[k] * u[k].transpose();
    EXPECT_LT((P - constraint_projector(c)).cwiseAbs().maxCoeff(), 1e-14);
  }
}

TEST(CapturePose, SolveHandlesRecoversAKnownHandleMove) {
  const Eigen::Index H = 6, nc = 400;
  std::mt19937 rng(11);
  std::normal_distribution<double> g(0, 1);
  Eigen::MatrixXd R(nc, H);  // response: one template vertex per constraint
  for (Eigen::Index i = 0; i < R.size(); ++i) R.data()[i] = g(rng);
  Eigen::MatrixX3d dh(H, 3);
  for (Eigen::Index i = 0; i < dh.size(); ++i) dh.data()[i] = 0.3 * g(rng);
  std::vector<RayConstraint> C = make_constraints(R, dh, 13);
  // a few gross outliers (40 px): rejected by the robust re-solves
  for (std::size_t i = 1; i < C.size(); i += 50) C[i].origin += 40.0 * C[i].pixel_size * C[i].dir.normalized().unitOrthogonal();
  HandleSolveOptions o;
  o.smoothness = 0;
  o.prior = 1e-12;
  o.reject_px = 8;  // below the outliers' residuals after the first solve (the default, 40, is meant for gated matches)
  const Eigen::MatrixXd K = Eigen::MatrixXd::Zero(H, H);
  const HandleSolveResult res = solve_handles(R, K, C, o);
  EXPECT_LT((res.dh - dh).cwiseAbs().maxCoeff(), 1e-8);
  EXPECT_EQ(res.feature_inliers + res.rim_inliers, int(C.size()) - 8);
  EXPECT_LT(res.median_residual_px, 1e-8);
}

// Rim matching (internal: pcl_ext/src/multiview/silhouette_match.h): an exact mesh against its own
// silhouette gets no offsets at all (the input contour is measured against the rendered contour,
// not against the rim vertex, which can project inside it), and a mesh 3 % too large is pulled
// in by about its excess projected radius.
TEST(RimMatch, ExactMeshHasNoOffsetAndAScaledOneIsPulledBack) {
  const TriMesh sphere = make_icosphere(4, 1.0);
  Eigen::Matrix3d K;
  K << 600, 0, 199.5, 0, 600, 199.5, 0, 0, 1;
  const Camera cam("c", 400, 400, K, Eigen::Matrix3d::Identity(), Eigen::Vector3d(0.03, -0.02, 5.0));
  const Rasterizer raster;
  const RenderBuffers truth = raster.renderViews(sphere, {cam})[0];
  cv::Mat silhouette(truth.height, truth.width, CV_8U, const_cast<std::uint8_t*>(truth.mask.data()));
  SilhouetteView view;
  view.set(silhouette.clone());
  const std::vector<RimMatch> exact = match_rims(sphere, cam, truth, view, RimMatchOptions{});
  ASSERT_GT(exact.size(), 50u);
  for (const RimMatch& m : exact) EXPECT_EQ(m.distance_px, 0.0) << "vertex " << m.vertex;

  TriMesh larger = sphere;
  larger.V *= 1.03;
  const RenderBuffers b = raster.renderViews(larger, {cam})[0];
  const std::vector<RimMatch> pulled = match_rims(larger, cam, b, view, RimMatchOptions{});
  ASSERT_GT(pulled.size(), 50u);
  // projected radius of a sphere of radius r at distance d: f r / sqrt(d² − r²)
  auto radius_px = [](double r) { return 600 * r / std::sqrt(25.0 - r * r); };
  const double excess = radius_px(1.03) - radius_px(1.0);  // 3.7 px
  const Eigen::Vector2d centre = cam.project(Eigen::Vector3d::Zero());
  double mean = 0;
  for (const RimMatch& m : pulled) {
    const double shift = (m.pixel - centre).norm() - (cam.project(larger.V.row(m.vertex).transpose()) - centre).norm();
    mean += shift / double(pulled.size());
    EXPECT_NEAR(shift, -excess, 1.5) << "vertex " << m.vertex;
  }
  EXPECT_NEAR(mean, -excess, 0.25);
}

// The point-wise mask gradient equals OpenCV's whole-image GaussianBlur (5x5, σ 1.2) + Sobel
// (the filters it replaces) at every pixel, the image borders (reflect-101) included.
TEST(RimMatch, PointwiseMaskGradientEqualsTheWholeImageFilters) {
  cv::Mat mask(90, 120, CV_8U, cv::Scalar(0));
  std::mt19937 rng(5);
  std::uniform_int_distribution<int> u(0, 119);
  for (int i = 0; i < 12; ++i) {  // blobs, some across the borders
    const int cx = u(rng), cy = u(rng) * 90 / 120, r = 3 + u(rng) % 15;
    for (int y = std::max(0, cy - r); y < std::min(90, cy + r + 1); ++y)
      for (int x = std::max(0, cx - r); x < std::min(120, cx + r + 1); ++x)
        if ((x - cx) * (x - cx) + (y - cy) * (y - cy) <= r * r) mask.at<std::uint8_t>(y, x) = 255;
  }
  cv::Mat f, b, gx, gy;
  mask.convertTo(f, CV_32F, 1.0 / 255.0);
  cv::GaussianBlur(f, b, cv::Size(5, 5), 1.2);
  cv::Sobel(b, gx, CV_32F, 1, 0, 3);
  cv::Sobel(b, gy, CV_32F, 0, 1, 3);
  double worst = 0, largest = 0;
  for (int y = 0; y < 90; ++y)
    for (int x = 0; x < 120; ++x) {
      const Eigen::Vector2d g = mask_gradient_at(mask, x, y);
      worst = std::max({worst, std::abs(g.x() - gx.at<float>(y, x)), std::abs(g.y() - gy.at<float>(y, x))});
      largest = std::max(largest, g.norm());
    }
  EXPECT_GT(largest, 1.0);   // the blobs' edges are in the image
  EXPECT_LT(worst, 1e-5);    // float rounding of the OpenCV filters
  EXPECT_EQ(mask_gradient_at(mask, -1, 3), Eigen::Vector2d::Zero());
  EXPECT_EQ(mask_gradient_at(mask, 120, 3), Eigen::Vector2d::Zero());
}

// The overlap from a render's covered box and a prepared input equals the whole-image count.
TEST(RimMatch, OverlapFromTheCoveredBoxEqualsTheWholeImageCount) {
  const TriMesh sphere = make_icosphere(3, 1.0);
  const Camera cam = Camera::lookAt("c", 160, 120, 1.0, {0, 0, 4}, {0, 0, 0}, {0, 1, 0});
  cv::Mat input(120, 160, CV_8U, cv::Scalar(0));
  cv::circle(input, {70, 50}, 30, cv::Scalar(200), -1);
  cv::rectangle(input, {0, 100}, {159, 119}, cv::Scalar(140), -1);  // outside the sphere's box
  cv::rectangle(input, {10, 10}, {20, 20}, cv::Scalar(100), -1);    // below the 128 threshold
  SilhouetteView view;
  view.set(input);
  for (double shift : {0.0, 0.8, 30.0}) {
    TriMesh m = sphere;
    m.V.col(0).array() += shift;
    RenderBuffers b;
    Rasterizer().render(m, cam, b);
    const SilhouetteOverlap whole = silhouette_overlap(b.mask, input), box = silhouette_overlap(b, view);
    EXPECT_EQ(box.xor_px, whole.xor_px) << "shift " << shift;
    EXPECT_EQ(box.iou, whole.iou) << "shift " << shift;
  }
}
