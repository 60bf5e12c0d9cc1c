// Heat-method geodesics against analytic distances: great circles on a sphere, Euclidean
// distances on a plane (regular and irregular triangulations), and batch/error behaviour.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>

#include "tbsp/core/error.h"
#include "tbsp/mesh/heat_geodesics.h"
#include "tbsp/mesh/primitives.h"

using namespace tbsp;

namespace {
struct ErrStats {
  double mean_rel = 0, max_rel = 0;
};
ErrStats compare(const Eigen::VectorXd& d, const Eigen::VectorXd& exact, double skip_below) {
  ErrStats s;
  long n = 0;
  for (Eigen::Index i = 0; i < d.size(); ++i) {
    if (exact(i) < skip_below) continue;
    const double rel = std::abs(d(i) - exact(i)) / exact(i);
    s.mean_rel += rel;
    s.max_rel = std::max(s.max_rel, rel);
    ++n;
  }
  s.mean_rel /= std::max<long>(1, n);
  return s;
}
}  // namespace

TEST(HeatGeodesics, SphereGreatCircleDistances) {
  const TriMesh m = make_icosphere(5, 1.0);  // 10242 vertices
  HeatGeodesics hg(m.V, m.F);
  const std::vector<int> src{0, 777, 5000};
  const Eigen::MatrixXd D = hg.distancesFromVertices(src);
  ASSERT_EQ(D.rows(), m.V.rows());
  ASSERT_EQ(D.cols(), 3);
  for (int s = 0; s < 3; ++s) {
    Eigen::VectorXd exact(m.V.rows());
    const Eigen::Vector3d p = m.V.row(src[s]).normalized();
    for (Eigen::Index i = 0; i < m.V.rows(); ++i) exact(i) = std::acos(std::clamp(p.dot(m.V.row(i).normalized()), -1.0, 1.0));
    EXPECT_NEAR(D(src[s], s), 0.0, 1e-9);
    const ErrStats e = compare(D.col(s), exact, 3 * hg.meanEdgeLength());
    std::printf("sphere, source %d: mean relative error %.4f, max %.4f\n", s, e.mean_rel, e.max_rel);
    EXPECT_LT(e.mean_rel, 0.02) << "source " << s;
    EXPECT_LT(e.max_rel, 0.08) << "source " << s;
    // Antipode at π.
    Eigen::Index far = 0;
    exact.maxCoeff(&far);
    EXPECT_NEAR(D(far, s), M_PI, 0.05 * M_PI);
  }
}

TEST(HeatGeodesics, PlaneEuclideanDistancesRegularAndJittered) {
  for (double jitter : {0.0, 0.15}) {
    TriMesh m = make_grid(80, 80, 2.0, 2.0, jitter, 7);  // 6561 vertices, spacing 0.025
    m.V.col(0).array() -= 1.0;
    m.V.col(1).array() -= 1.0;
    const double h = 2.0 / 80;
    HeatGeodesics hg(m.V, m.F);
    // Source: the vertex nearest to the centre.
    Eigen::Index c = 0;
    m.V.rowwise().squaredNorm().minCoeff(&c);
    const Eigen::VectorXd d = hg.distancesFromVertices({static_cast<int>(c)}).col(0);
    Eigen::VectorXd exact = (m.V.rowwise() - m.V.row(c)).rowwise().norm();
    // Interior only (the heat method's Neumann boundary bends distances near the border).
    Eigen::VectorXd d_in = d, e_in = exact;
    for (Eigen::Index i = 0; i < m.V.rows(); ++i)
      if (m.V.row(i).head<2>().cwiseAbs().maxCoeff() > 0.8) e_in(i) = 0;
    const ErrStats e = compare(d_in, e_in, 3 * h);
    std::printf("plane, jitter %.2f: mean relative error %.4f, max %.4f\n", jitter, e.mean_rel, e.max_rel);
    EXPECT_LT(e.mean_rel, 0.02) << "jitter " << jitter;
    EXPECT_LT(e.max_rel, 0.06) << "jitter " << jitter;
  }
}

TEST(HeatGeodesics, SurfacePointSourcesAndComponents) {
  TriMesh a = make_grid(20, 20);
  // Two copies side by side: distances into the other copy are infinite.
  TriMesh m;
  m.V.resize(2 * a.V.rows(), 3);
  m.V << a.V, a.V.rowwise() + Eigen::RowVector3d(5, 0, 0);
  m.F.resize(2 * a.F.rows(), 3);
  m.F << a.F, a.F.array() + static_cast<int>(a.V.rows());
  HeatGeodesics hg(m.V, m.F);
  // A source spread over a triangle equals (approximately) the distance from its centroid.
  const int f = 100;
  WeightedSource s{{m.F(f, 0), 1.0 / 3}, {m.F(f, 1), 1.0 / 3}, {m.F(f, 2), 1.0 / 3}};
  const Eigen::MatrixXd D = hg.distances({s});
  const Eigen::Vector3d cen = (m.V.row(m.F(f, 0)) + m.V.row(m.F(f, 1)) + m.V.row(m.F(f, 2))) / 3.0;
  Eigen::Index far = 0;
  (a.V.rowwise() - cen.transpose()).rowwise().norm().maxCoeff(&far);
  EXPECT_NEAR(D(far, 0), (a.V.row(far) - cen.transpose()).norm(), 0.05 * (a.V.row(far) - cen.transpose()).norm());
  EXPECT_TRUE(std::isinf(D(a.V.rows() + 5, 0)));
  EXPECT_THROW(hg.distancesFromVertices({-1}), InvalidInput);
  EXPECT_THROW(hg.distancesFromVertices({static_cast<int>(m.V.rows())}), InvalidInput);
  EXPECT_THROW(hg.distances({WeightedSource{}}), InvalidInput);
  EXPECT_THROW(HeatGeodesics(Eigen::MatrixX3d(0, 3), Eigen::MatrixX3i(0, 3)), InvalidInput);
}
