// The four-lane dihedral bending kernel of PbdClothSimulator (pcl_ext/src/cloth/pbd_bend_kernel.h)
// on hinges with known angles: a projection at stiffness k takes a fold φ to about (1 − k)·φ;
// a lane's result does not depend on its neighbours; idle, degenerate and pinned lanes stay put.
#include <gtest/gtest.h>

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cmath>
#include <vector>

#include "pbd_bend_kernel.h"

using tbsp::detail::BendQuad;
using tbsp::detail::project_bend_quad;

namespace {

// A hinge: edge from (0,0,0) to (1,0,0) (vertices e, e+1), wings e+2 in the x-y plane and e+3
// folded by `fold` radians about the edge (0: flat), written at vertex offset e of `pred`.
void put_hinge(std::vector<double>& pred, int e, double fold) {
  const double v[4][3] = {{0, 0, 0}, {1, 0, 0}, {0.5, 1, 0}, {0.5, -std::cos(fold), std::sin(fold)}};
  for (int k = 0; k < 4; ++k)
    for (int a = 0; a < 3; ++a) pred[std::size_t(3 * (e + k) + a)] = v[k][a];
}

void set_lane(BendQuad& q, int lane, int e, double rest, double k) {
  q.i2[lane] = e, q.i3[lane] = e + 1, q.i0[lane] = e + 2, q.i1[lane] = e + 3;
  q.rest[lane] = rest, q.k[lane] = k;
}

BendQuad idle_quad() {
  BendQuad q;
  for (int l = 0; l < 4; ++l) set_lane(q, l, 0, 0, 0);
  return q;
}

Eigen::Vector3d at(const std::vector<double>& pred, int v) { return Eigen::Vector3d(pred[3 * v], pred[3 * v + 1], pred[3 * v + 2]); }

// the hinge's dihedral angle (0 flat), measured with libm's acos
double fold_of(const std::vector<double>& pred, int e) {
  const Eigen::Vector3d p2 = at(pred, e), p3 = at(pred, e + 1), p0 = at(pred, e + 2), p1 = at(pred, e + 3);
  const Eigen::Vector3d n1 = (p2 - p0).cross(p3 - p0).normalized(), n2 = (p3 - p1).cross(p2 - p1).normalized();
  return std::acos(std::clamp(n1.dot(n2), -1.0, 1.0));
}

}  // namespace

TEST(PbdBendKernel, AProjectionAtHalfStiffnessHalvesASmallFold) {
  std::vector<double> pred(3 * 16), inv_mass(16, 1.0);
  BendQuad q = idle_quad();
  const double folds[4] = {0.2, -0.2, 0.1, 0.3};
  const double rests[4] = {0.0, 0.0, 0.0, 0.3};  // lane 3 is at rest already
  for (int l = 0; l < 4; ++l) {
    put_hinge(pred, 4 * l, folds[l]);
    set_lane(q, l, 4 * l, rests[l], 0.5);
  }
  project_bend_quad(q, inv_mass.data(), pred.data());
  // linearised step: C → C·(1 − k) to first order (the angle error is O(φ³) plus the
  // approximate acos' 7e-5 rad)
  EXPECT_NEAR(fold_of(pred, 0), 0.1, 3e-3);
  EXPECT_NEAR(fold_of(pred, 4), 0.1, 3e-3);  // a fold the other way is opened as far
  EXPECT_NEAR(fold_of(pred, 8), 0.05, 1e-3);
  EXPECT_NEAR(fold_of(pred, 12), 0.3, 2e-4);
}

TEST(PbdBendKernel, ALaneGivesTheSameBitsWhateverItsNeighbours) {
  std::vector<double> alone(3 * 16), crowded(3 * 16), inv_mass(16);
  for (int v = 0; v < 16; ++v) inv_mass[std::size_t(v)] = 1.0 + 0.1 * v;
  for (int h = 0; h < 4; ++h) {
    put_hinge(alone, 4 * h, 0.05 + 0.1 * h);
    put_hinge(crowded, 4 * h, 0.05 + 0.1 * h);
  }
  BendQuad one = idle_quad();
  set_lane(one, 0, 12, 0.02, 0.37);  // hinge 3 by itself in lane 0
  project_bend_quad(one, inv_mass.data(), alone.data());
  BendQuad four = idle_quad();
  for (int l = 0; l < 4; ++l) set_lane(four, l, 4 * l, 0.02, 0.37);  // hinge 3 in lane 3, beside three others
  project_bend_quad(four, inv_mass.data(), crowded.data());
  for (int k = 36; k < 48; ++k) EXPECT_EQ(alone[std::size_t(k)], crowded[std::size_t(k)]) << "coordinate " << k;
  EXPECT_NE(alone[std::size_t(3 * 15 + 2)], std::sin(0.35));  // it did move
}

TEST(PbdBendKernel, IdleDegenerateAndPinnedLanesMoveNothingTheyShouldNot) {
  std::vector<double> pred(3 * 16), inv_mass(16, 1.0);
  for (int h = 0; h < 4; ++h) put_hinge(pred, 4 * h, 0.3);
  // hinge 1: its edge collapsed to a point; hinge 2: every vertex pinned; hinge 3: the edge pinned
  for (int a = 0; a < 3; ++a) pred[std::size_t(3 * 5 + a)] = pred[std::size_t(3 * 4 + a)];
  for (int v = 8; v < 12; ++v) inv_mass[std::size_t(v)] = 0;
  inv_mass[12] = inv_mass[13] = 0;
  BendQuad q = idle_quad();
  set_lane(q, 0, 0, 0, 0);  // idle: stiffness 0
  set_lane(q, 1, 4, 0, 0.5);
  set_lane(q, 2, 8, 0, 0.5);
  set_lane(q, 3, 12, 0, 0.5);
  const std::vector<double> before = pred;
  project_bend_quad(q, inv_mass.data(), pred.data());
  for (int k = 0; k < 3 * 14; ++k) EXPECT_EQ(pred[std::size_t(k)], before[std::size_t(k)]) << "coordinate " << k;
  EXPECT_NEAR(fold_of(pred, 12), 0.15, 3e-3);  // the free wings did the whole correction
  for (double x : pred) EXPECT_TRUE(std::isfinite(x));
}
