// RadiusGrid: the same neighbours as nanoflann's radius search, a fixed order, clear errors.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <utility>
#include <vector>

#include "tbsp/core/error.h"
#include "tbsp/mesh/point_search.h"
#include "tbsp/mesh/radius_grid.h"

using namespace tbsp;

namespace {
std::vector<std::pair<Eigen::Index, double>> grid_neighbours(const RadiusGrid& g, const Eigen::Vector3d& q) {
  std::vector<std::pair<Eigen::Index, double>> out;
  g.forEachWithin(q, [&](Eigen::Index i, double d2) { out.emplace_back(i, d2); });
  return out;
}
}  // namespace

TEST(RadiusGrid, FindsTheSamePointsAsTheKdTree) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-1, 1);
  Eigen::MatrixX3d P(3000, 3);
  for (Eigen::Index i = 0; i < P.rows(); ++i) {
    // a sheet (as a scan) and some points off it; a few exact duplicates
    const double x = u(rng), y = u(rng);
    P.row(i) << x, y, (i % 5 == 0) ? u(rng) : 0.1 * x * y;
  }
  P.row(10) = P.row(11);
  const PointSearch tree(P);
  for (const double r : {0.02, 0.1, 0.37, 5.0}) {
    const RadiusGrid g(P, r);
    EXPECT_EQ(g.size(), 3000u);
    std::vector<std::pair<Eigen::Index, double>> want;
    for (int q = 0; q < 300; ++q) {
      // queries inside the box, at its faces and well outside it
      const double s = q < 200 ? 1.0 : 1.5;
      const Eigen::Vector3d p(s * u(rng), s * u(rng), s * u(rng));
      tree.radius(p, r, want);
      auto got = grid_neighbours(g, p);
      std::sort(want.begin(), want.end());
      std::sort(got.begin(), got.end());
      ASSERT_EQ(got.size(), want.size()) << "radius " << r << " query " << q;
      for (std::size_t k = 0; k < got.size(); ++k) {
        EXPECT_EQ(got[k].first, want[k].first);
        EXPECT_NEAR(got[k].second, want[k].second, 1e-15);
      }
    }
  }
}

TEST(RadiusGrid, VisitsInTheSameOrderEveryTime) {
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(0, 1);
  Eigen::MatrixX3d P(2000, 3);
  for (Eigen::Index i = 0; i < P.rows(); ++i) P.row(i) << u(rng), u(rng), u(rng);
  const RadiusGrid a(P, 0.2), b(P, 0.2);
  const Eigen::Vector3d q(0.5, 0.4, 0.6);
  const auto na = grid_neighbours(a, q), nb = grid_neighbours(b, q);
  ASSERT_GT(na.size(), 50u);
  EXPECT_EQ(na, nb);
}

// The storage order is the documented one — cell by cell in ascending key (x fastest, then y, z;
// cells `radius` wide from the points' minimum corner), rows ascending within a cell — whether
// the grid is built by its counting sort (dense points) or by a comparison sort (a few points
// in a box of many cells): the fitter's sums follow this order, so their bits depend on it.
TEST(RadiusGrid, StoresThePointsCellByCellInAscendingKeyAndRowOrder) {
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> u(0, 1);
  for (const bool dense : {true, false}) {
    Eigen::MatrixX3d P(dense ? 5000 : 40, 3);
    for (Eigen::Index i = 0; i < P.rows(); ++i) P.row(i) << u(rng), u(rng), u(rng);
    P.row(7) = P.row(3);  // a duplicate: the same cell, rows 3 then 7
    const double r = dense ? 0.05 : 0.01;  // 21^3 cells for 5000 points; 101^3 for 40
    const RadiusGrid g(P, r);
    const Eigen::RowVector3d lo = P.colwise().minCoeff(), hi = P.colwise().maxCoeff();
    std::int64_t dims[3];
    for (int d = 0; d < 3; ++d) dims[d] = std::int64_t(std::floor((hi(d) - lo(d)) / r)) + 1;
    auto key = [&](Eigen::Index i) {
      std::int64_t c[3];
      for (int d = 0; d < 3; ++d) c[d] = std::min<std::int64_t>(dims[d] - 1, std::int64_t(std::floor((P(i, d) - lo(d)) / r)));
      return std::make_pair((c[2] * dims[1] + c[1]) * dims[0] + c[0], i);
    };
    std::vector<std::pair<std::int64_t, Eigen::Index>> want;
    for (Eigen::Index i = 0; i < P.rows(); ++i) want.push_back(key(i));
    std::sort(want.begin(), want.end());
    ASSERT_EQ(g.rows().size(), want.size()) << (dense ? "dense" : "sparse");
    for (std::size_t s = 0; s < want.size(); ++s) ASSERT_EQ(Eigen::Index(g.rows()[s]), want[s].second) << (dense ? "dense" : "sparse") << " slot " << s;
  }
}

TEST(RadiusGrid, SkipsNonFiniteRowsAndHandlesEmptySets) {
  Eigen::MatrixX3d P(4, 3);
  P << 0, 0, 0, std::numeric_limits<double>::quiet_NaN(), 0, 0, 1, 1, 1, 0.05, 0, 0;
  const RadiusGrid g(P, 0.1);
  EXPECT_EQ(g.size(), 3u);
  auto n = grid_neighbours(g, Eigen::Vector3d(0.02, 0, 0));
  std::sort(n.begin(), n.end());
  ASSERT_EQ(n.size(), 2u);
  EXPECT_EQ(n[0].first, 0);
  EXPECT_EQ(n[1].first, 3);
  EXPECT_TRUE(grid_neighbours(g, Eigen::Vector3d(std::numeric_limits<double>::infinity(), 0, 0)).empty());
  const RadiusGrid empty(Eigen::MatrixX3d(0, 3), 1.0);
  EXPECT_EQ(empty.size(), 0u);
  EXPECT_TRUE(grid_neighbours(empty, Eigen::Vector3d::Zero()).empty());
  const RadiusGrid none;
  EXPECT_TRUE(grid_neighbours(none, Eigen::Vector3d::Zero()).empty());
}

TEST(RadiusGrid, RejectsBadRadiiWithAClearError) {
  Eigen::MatrixX3d P(2, 3);
  P << 0, 0, 0, 1, 0, 0;
  EXPECT_THROW(RadiusGrid(P, 0.0), InvalidInput);
  EXPECT_THROW(RadiusGrid(P, -1.0), InvalidInput);
  EXPECT_THROW(RadiusGrid(P, std::numeric_limits<double>::quiet_NaN()), InvalidInput);
}

TEST(RadiusGrid, ARadiusFarBelowTheExtentStillFindsItsNeighbours) {
  // a radius a billionth of the extent: the cells are widened to 2^20 per axis
  Eigen::MatrixX3d P(4, 3);
  P << 0, 0, 0, 1e-10, 0, 0, 3e-9, 0, 0, 1, 1, 1;
  const RadiusGrid g(P, 2e-9);
  auto n = grid_neighbours(g, Eigen::Vector3d(0, 0, 0));
  std::sort(n.begin(), n.end());
  ASSERT_EQ(n.size(), 2u);
  EXPECT_EQ(n[0].first, 0);
  EXPECT_EQ(n[1].first, 1);
  EXPECT_EQ(grid_neighbours(g, Eigen::Vector3d(1, 1, 1)).size(), 1u);
}

TEST(RadiusGrid, SlotsNameTheRowsInStorageOrder) {
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> u(0, 1);
  Eigen::MatrixX3d P(500, 3);
  for (Eigen::Index i = 0; i < P.rows(); ++i) P.row(i) << u(rng), u(rng), u(rng);
  const RadiusGrid g(P, 0.15);
  ASSERT_EQ(g.rows().size(), 500u);
  std::vector<std::uint32_t> sorted = g.rows();
  std::sort(sorted.begin(), sorted.end());
  for (std::uint32_t i = 0; i < 500; ++i) EXPECT_EQ(sorted[i], i);  // each row once
  const Eigen::Vector3d q(0.3, 0.6, 0.5);
  std::vector<std::pair<Eigen::Index, double>> by_row, by_slot;
  g.forEachWithin(q, [&](Eigen::Index i, double d2) { by_row.emplace_back(i, d2); });
  g.forEachSlotWithin(q, [&](std::size_t s, double d2) { by_slot.emplace_back(Eigen::Index(g.rows()[s]), d2); });
  ASSERT_FALSE(by_row.empty());
  EXPECT_EQ(by_row, by_slot);
}
