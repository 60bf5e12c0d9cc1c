#include <gtest/gtest.h>

#include <random>

#include <Eigen/Geometry>

#include "tbsp/core/error.h"
#include "tbsp/multiview/camera.h"

using namespace tbsp;

namespace {
Camera example_camera(const Distortion& d = {}) {
  Eigen::Matrix3d K;
  K << 1200.5, 0.7, 503.2, 0, 1195.1, 498.9, 0, 0, 1;
  const Eigen::Matrix3d R = Eigen::AngleAxisd(0.4, Eigen::Vector3d(0.3, -1, 0.2).normalized()).toRotationMatrix();
  return Camera("cam0", 1004, 1004, K, R, Eigen::Vector3d(0.1, -0.2, 3.5), d);
}
}  // namespace

TEST(Camera, ProjectionMatrixDecomposesBackToKRt) {
  const Camera c = example_camera();
  for (double scale : {1.0, -3.7, 1e-4}) {
    const Camera d = Camera::fromProjection("p", 1004, 1004, scale * c.P());
    EXPECT_LT((d.K() - c.K()).norm(), 1e-8 * c.K().norm()) << scale;
    EXPECT_LT((d.R() - c.R()).norm(), 1e-10) << scale;
    EXPECT_LT((d.t() - c.t()).norm(), 1e-10) << scale;
    EXPECT_LT((d.center() - c.center()).norm(), 1e-10);
  }
}

TEST(Camera, ProjectBackProjectAndRayAreConsistentWithDistortion) {
  Distortion dist;
  dist.k1 = -0.21; dist.k2 = 0.05; dist.p1 = 0.001; dist.p2 = -0.0007; dist.k3 = 0.002;
  const Camera c = example_camera(dist);
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(-0.6, 0.6);
  for (int i = 0; i < 200; ++i) {
    const Eigen::Vector3d X(u(rng), u(rng), u(rng));
    const Eigen::Vector2d px = c.project(X);
    const Eigen::Vector3d Y = c.backProject(px, c.depth(X));
    EXPECT_LT((X - Y).norm(), 1e-9);
    const Ray r = c.ray(px);
    const Eigen::Vector3d v = X - r.origin;
    EXPECT_LT((v - v.dot(r.direction) * r.direction).norm(), 1e-9);
    EXPECT_GT(v.dot(r.direction), 0);
  }
  // Distortion really changes the projection.
  const Camera plain = example_camera();
  EXPECT_GT((plain.project({0.5, 0.5, 0.3}) - c.project({0.5, 0.5, 0.3})).norm(), 0.2);
}

TEST(Camera, TriangulationRecoversPointsFromTwoViews) {
  const Camera a = example_camera();
  const Camera b = Camera::lookAt("b", 1004, 1004, 0.8, {2.5, 0.3, 2.0}, {0, 0, 0}, {0, 1, 0});
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> u(-0.4, 0.4);
  for (int i = 0; i < 50; ++i) {
    const Eigen::Vector3d X(u(rng), u(rng), u(rng));
    const Eigen::Vector3d Y = triangulate({a, b}, {a.project(X), b.project(X)});
    EXPECT_LT((X - Y).norm(), 1e-9);
  }
  EXPECT_THROW(triangulate({a}, {a.project({0, 0, 0})}), InvalidInput);
  EXPECT_THROW(triangulate({a, b}, {a.project({0, 0, 0})}), InvalidInput);
}

TEST(Camera, LookAtPutsTheTargetAtThePrincipalPoint) {
  const Camera c = Camera::lookAt("c", 640, 480, 1.0, {1, 2, 3}, {0, 0.5, 0}, {0, 1, 0});
  const Eigen::Vector2d p = c.project({0, 0.5, 0});
  EXPECT_NEAR(p.x(), 319.5, 1e-9);
  EXPECT_NEAR(p.y(), 239.5, 1e-9);
  EXPECT_NEAR(c.horizontalFov(), 1.0, 1e-12);
  // "up" in the world is up (smaller v) in the image.
  EXPECT_LT(c.project({0, 1.5, 0}).y(), p.y());
}

TEST(Camera, InvalidParametersGiveClearErrors) {
  Eigen::Matrix3d K = Eigen::Matrix3d::Identity();
  K(0, 0) = -5;
  try {
    Camera("bad", 10, 10, K, Eigen::Matrix3d::Identity(), Eigen::Vector3d::Zero());
    FAIL();
  } catch (const InvalidInput& e) {
    EXPECT_NE(std::string(e.what()).find("'bad'"), std::string::npos);
    EXPECT_NE(std::string(e.what()).find("focal"), std::string::npos);
  }
  Eigen::Matrix3d R = Eigen::Matrix3d::Identity();
  R(0, 0) = -1;  // reflection
  EXPECT_THROW(Camera("r", 10, 10, Eigen::Matrix3d::Identity(), R, Eigen::Vector3d::Zero()), InvalidInput);
  EXPECT_THROW(Camera("s", 0, 10, Eigen::Matrix3d::Identity(), Eigen::Matrix3d::Identity(), Eigen::Vector3d::Zero()), InvalidInput);
  Matrix34d P = Matrix34d::Zero();
  P(0, 0) = P(1, 1) = 1;  // rank 2
  try {
    Camera::fromProjection("sing", 10, 10, P);
    FAIL();
  } catch (const InvalidInput& e) {
    EXPECT_NE(std::string(e.what()).find("singular"), std::string::npos);
  }
  P(2, 2) = std::numeric_limits<double>::quiet_NaN();
  EXPECT_THROW(Camera::fromProjection("nan", 10, 10, P), InvalidInput);
}

// resized(s): a point's pixel follows u' = s_x (u + 0.5) − 0.5 with s_x = w'/w (cv::resize's
// pixel-centre convention), with distortion; cropped(x, y): the pixel shifts by (−x, −y).
TEST(Camera, ResizedAndCroppedCamerasMapPixelsAnalytically) {
  Distortion dist;
  dist.k1 = -0.21; dist.k2 = 0.05; dist.p1 = 0.001;
  const Camera c = example_camera(dist);
  const Camera half = c.resized(0.5), odd = c.resized(0.3);
  EXPECT_EQ(half.width(), 502);
  EXPECT_EQ(odd.width(), 301);  // lround(301.2)
  const double sx = 301.0 / 1004.0;
  const Camera crop = c.cropped(200, -30, 400, 300);
  EXPECT_EQ(crop.width(), 400);
  EXPECT_EQ(crop.height(), 300);
  std::mt19937 rng(9);
  std::uniform_real_distribution<double> u(-0.5, 0.5);
  for (int i = 0; i < 100; ++i) {
    const Eigen::Vector3d X(u(rng), u(rng), u(rng));
    const Eigen::Vector2d p = c.project(X);
    EXPECT_LT((half.project(X) - (0.5 * (p.array() + 0.5) - 0.5).matrix()).norm(), 1e-9);
    EXPECT_NEAR(odd.project(X).x(), sx * (p.x() + 0.5) - 0.5, 1e-9);
    EXPECT_LT((crop.project(X) - (p - Eigen::Vector2d(200, -30))).norm(), 1e-9);
    EXPECT_LT((crop.backProject(crop.project(X), crop.depth(X)) - X).norm(), 1e-9);
  }
  EXPECT_THROW(c.resized(0), InvalidInput);
  EXPECT_THROW(c.resized(std::nan("")), InvalidInput);
  EXPECT_THROW(c.cropped(0, 0, 0, 10), InvalidInput);
}
