// The four-lane stretch projection and drag of PbdClothSimulator
// (pcl_ext/src/cloth/pbd_stretch_kernel.h) on cases with known answers: a projection at full
// stiffness restores the rest length, split by the inverse masses; drag splits a velocity along
// the normal and across it as eq. 10.5 says; idle, pinned and inactive lanes move nothing.
#include <gtest/gtest.h>

#include <Eigen/Core>
#include <cmath>
#include <vector>

#include "pbd_stretch_kernel.h"

using tbsp::detail::apply_drag_quad;
using tbsp::detail::DragQuad;
using tbsp::detail::project_stretch_quad;
using tbsp::detail::StretchQuad;

// (names unique among the test files a unity build compiles together)
namespace {

Eigen::Vector3d xyz_at(const std::vector<double>& p, int v) { return Eigen::Vector3d(p[3 * v], p[3 * v + 1], p[3 * v + 2]); }
void put_xyz(std::vector<double>& p, int v, const Eigen::Vector3d& x) {
  for (int a = 0; a < 3; ++a) p[std::size_t(3 * v + a)] = x[a];
}

}  // namespace

TEST(PbdStretchKernel, AFullStiffnessProjectionRestoresTheRestLengthSplitByTheInverseMasses) {
  std::vector<double> pred(3 * 8), w{1, 1, 1, 0, 0, 0, 2, 1};
  // lane 0: equal masses, stretched 2 → rest 1; lane 1: b pinned, compressed 0.5 → rest 1;
  // lane 2: both pinned; lane 3: masses 2 : 1 (inverse), stretched along a diagonal
  put_xyz(pred, 0, {0, 0, 0}), put_xyz(pred, 1, {2, 0, 0});
  put_xyz(pred, 2, {0, 1, 0}), put_xyz(pred, 3, {0, 1.5, 0});
  put_xyz(pred, 4, {5, 5, 5}), put_xyz(pred, 5, {7, 5, 5});
  put_xyz(pred, 6, {1, 1, 1}), put_xyz(pred, 7, {2, 2, 2});
  const std::vector<double> before = pred;
  StretchQuad q{{0, 2, 4, 6}, {1, 3, 5, 7}, {1.0, 1.0, 1.0, 0.5}};
  project_stretch_quad(q, 4, 1.0, w.data(), pred.data());
  EXPECT_NEAR((xyz_at(pred, 0) - xyz_at(pred, 1)).norm(), 1.0, 1e-12);
  EXPECT_NEAR(xyz_at(pred, 0).x(), 0.5, 1e-12);  // each end moves half the excess
  EXPECT_NEAR((xyz_at(pred, 2) - xyz_at(pred, 3)).norm(), 1.0, 1e-12);
  EXPECT_EQ(xyz_at(pred, 3), xyz_at(before, 3));  // pinned: only a moves
  EXPECT_NEAR(xyz_at(pred, 2).y(), 0.5, 1e-12);
  EXPECT_EQ(xyz_at(pred, 4), xyz_at(before, 4));  // both pinned: nothing moves
  EXPECT_EQ(xyz_at(pred, 5), xyz_at(before, 5));
  EXPECT_NEAR((xyz_at(pred, 6) - xyz_at(pred, 7)).norm(), 0.5, 1e-12);
  // the excess √3 − 0.5 moves a by 2/3 of it and b by 1/3
  const double excess = std::sqrt(3.0) - 0.5;
  EXPECT_NEAR((xyz_at(pred, 6) - xyz_at(before, 6)).norm(), excess * 2 / 3, 1e-12);
  EXPECT_NEAR((xyz_at(pred, 7) - xyz_at(before, 7)).norm(), excess / 3, 1e-12);
}

TEST(PbdStretchKernel, ALaneGivesTheSameBitsAloneAndIdleLanesStayPut) {
  std::vector<double> pred(3 * 8), w(8, 1.0);
  for (int v = 0; v < 8; ++v) put_xyz(pred, v, {0.1 * v * v, std::sin(v), 0.3 * v});
  put_xyz(pred, 6, {0, 0, 0}), put_xyz(pred, 7, {0, 0, 0});  // a lane of coincident vertices: moves nothing
  StretchQuad q{{0, 2, 4, 6}, {1, 3, 5, 7}, {0.7, 0.2, 1.5, 0.1}};
  std::vector<double> all = pred, two = pred, one = pred;
  project_stretch_quad(q, 4, 0.6, w.data(), all.data());
  project_stretch_quad(q, 2, 0.6, w.data(), two.data());  // lanes 2 and 3 idle
  for (int l = 0; l < 2; ++l) {
    StretchQuad s{{q.a[l]}, {q.b[l]}, {q.rest[l]}};
    project_stretch_quad(s, 1, 0.6, w.data(), one.data());
  }
  for (int v = 0; v < 4; ++v) {
    EXPECT_EQ(xyz_at(all, v), xyz_at(one, v)) << v;
    EXPECT_EQ(xyz_at(two, v), xyz_at(one, v)) << v;
  }
  for (int v = 4; v < 8; ++v) EXPECT_EQ(xyz_at(two, v), xyz_at(pred, v)) << v;
  EXPECT_NE(xyz_at(all, 4), xyz_at(pred, 4));
  EXPECT_EQ(xyz_at(all, 6), xyz_at(pred, 6));
  EXPECT_EQ(xyz_at(all, 7), xyz_at(pred, 7));
}

TEST(PbdDragKernel, SplitsTheVelocityAlongAndAcrossTheNormalAsEquation10_5) {
  const double g[3] = {0, 0, -9.81}, h = 0.005, unit = 0.01, dt = 0.002;
  std::vector<double> vel(3 * 4);
  put_xyz(vel, 0, {1, 0, 3});   // normal (0, 0, 2): u_n = (0, 0, 3), u_t = (1, 0, 0)
  put_xyz(vel, 1, {1, 2, 3});   // zero normal: gravity only
  put_xyz(vel, 2, {-2, 0, 0});  // inactive (pinned): untouched
  put_xyz(vel, 3, {0, 0.5, 0}); // normal along y: all normal drag
  DragQuad q{};
  for (int l = 0; l < 4; ++l) q.vertex[l] = l, q.active[l] = l != 2, q.d_n[l] = 2.0, q.d_t[l] = 4.0;
  q.nz[0] = 2.0, q.ny[3] = -1.0, q.nx[2] = 1.0;
  const std::vector<double> before = vel;
  apply_drag_quad(q, g, h, unit, dt, vel.data());
  // a = g − ½ h (d_n |u_n| / unit · u_n + d_t u_t)
  const Eigen::Vector3d a0 = Eigen::Vector3d(0, 0, -9.81) - 0.5 * h * (2.0 * 3 / unit * Eigen::Vector3d(0, 0, 3) + 4.0 * Eigen::Vector3d(1, 0, 0));
  EXPECT_LT((xyz_at(vel, 0) - (xyz_at(before, 0) + dt * a0)).norm(), 1e-12);
  EXPECT_LT((xyz_at(vel, 1) - (xyz_at(before, 1) + dt * Eigen::Vector3d(0, 0, -9.81))).norm(), 1e-12);
  EXPECT_EQ(xyz_at(vel, 2), xyz_at(before, 2));
  const Eigen::Vector3d a3 = Eigen::Vector3d(0, 0, -9.81) - 0.5 * h * (2.0 * 0.5 / unit * Eigen::Vector3d(0, 0.5, 0));
  EXPECT_LT((xyz_at(vel, 3) - (xyz_at(before, 3) + dt * a3)).norm(), 1e-12);
  // without drag (h = 0) every active lane gets gravity alone
  std::vector<double> v2 = before;
  apply_drag_quad(q, g, 0.0, unit, dt, v2.data());
  EXPECT_LT((xyz_at(v2, 0) - (xyz_at(before, 0) + dt * Eigen::Vector3d(0, 0, -9.81))).norm(), 1e-12);
}
