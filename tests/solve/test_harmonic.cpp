#include <gtest/gtest.h>

#include "tbsp/core/error.h"
#include "tbsp/mesh/primitives.h"
#include "tbsp/mesh/harmonic.h"

using namespace tbsp;

// eq. 3.11: with cotangent weights a linear function is harmonic on a planar mesh, so
// interpolating its boundary values reproduces it exactly in the interior.
TEST(Harmonic, ReproducesLinearFunctionOnPlanarMesh) {
  const TriMesh m = make_grid(25, 18, 2.0, 1.0, 0.15, 5);
  std::vector<int> boundary;
  for (int j = 0; j <= 18; ++j)
    for (int i = 0; i <= 25; ++i)
      if (i == 0 || j == 0 || i == 25 || j == 18) boundary.push_back(j * 26 + i);
  auto f = [](const Eigen::RowVector3d& p) { return Eigen::RowVector2d(3 * p.x() - 2 * p.y() + 0.5, -p.x() + 7 * p.y()); };
  Eigen::MatrixXd vals(boundary.size(), 2);
  for (std::size_t k = 0; k < boundary.size(); ++k) vals.row(Eigen::Index(k)) = f(m.V.row(boundary[k]));
  const Eigen::MatrixXd out = harmonic_interpolation(m.V, m.F, boundary, vals);
  double err = 0;
  for (Eigen::Index i = 0; i < m.V.rows(); ++i) err = std::max(err, (out.row(i) - f(m.V.row(i))).norm());
  EXPECT_LT(err, 1e-10);
  // uniform weights do not have linear precision on an irregular grid
  const Eigen::MatrixXd outu = harmonic_interpolation(m.V, m.F, boundary, vals, LaplacianWeights::Uniform);
  double erru = 0;
  for (Eigen::Index i = 0; i < m.V.rows(); ++i) erru = std::max(erru, (outu.row(i) - f(m.V.row(i))).norm());
  EXPECT_GT(erru, 1e-4);
}

TEST(Harmonic, KeepsConstrainedValuesAndStaysInRange) {
  const TriMesh m = make_icosphere(3);
  const std::vector<int> b{0, 1, 2, 3};
  Eigen::MatrixXd v(4, 1);
  v << 0, 1, 0.25, 0.75;
  HarmonicInterpolator h;
  h.compute(m.V, m.F, b);
  const Eigen::MatrixXd out = h.interpolate(v);
  for (int k = 0; k < 4; ++k) EXPECT_EQ(out(b[std::size_t(k)], 0), v(k, 0));
  // maximum principle (holds up to the small negative cotangent weights of a good mesh)
  EXPECT_GE(out.minCoeff(), -1e-3);
  EXPECT_LE(out.maxCoeff(), 1 + 1e-3);
  // re-use the factorization for another channel set
  const Eigen::MatrixXd out2 = h.interpolate(2 * v);
  EXPECT_LT((out2 - 2 * out).norm(), 1e-10);
}

TEST(Harmonic, RejectsBadInput) {
  const TriMesh m = make_icosphere(1);
  HarmonicInterpolator h;
  EXPECT_THROW(h.compute(m.V, m.F, {}), InvalidInput);
  EXPECT_THROW(h.compute(m.V, m.F, {0, 500}), InvalidInput);
  EXPECT_THROW(h.compute(m.V, m.F, {0, 0}), InvalidInput);
  // second component without a constrained vertex
  TriMesh two;
  two.V.resize(2 * m.V.rows(), 3);
  two.V << m.V, (m.V.rowwise() + Eigen::RowVector3d(5, 0, 0));
  two.F.resize(2 * m.F.rows(), 3);
  two.F << m.F, (m.F.array() + int(m.V.rows())).matrix();
  try {
    h.compute(two.V, two.F, {0});
    FAIL();
  } catch (const InvalidInput& e) {
    EXPECT_NE(std::string(e.what()).find("has no constrained vertex"), std::string::npos) << e.what();
  }
  h.compute(m.V, m.F, {0, 1});
  EXPECT_THROW(h.interpolate(Eigen::MatrixXd::Zero(3, 1)), InvalidInput);
}

// The matrix overload (the deformer passes the cotangent matrix its Laplacian was scaled from):
// the same bits as building it from V and F, for both weightings; a matrix of another mesh is
// refused.
TEST(Harmonic, GivenTheMeshMatrixGivesTheSameBits) {
  const TriMesh m = make_grid(20, 14, 2.0, 1.0, 0.2, 3);
  const std::vector<int> b{0, 7, 160, 311};
  Eigen::MatrixXd v(4, 4);
  v << 1, 0, 0, 0, 0.5, 0.5, 0.5, 0.5, 0, 1, 0, 0, 0.2, -0.3, 0.9, 0.1;
  for (const auto w : {LaplacianWeights::Cotangent, LaplacianWeights::Uniform}) {
    HarmonicInterpolator a, c;
    a.compute(m.V, m.F, b, w);
    Eigen::SparseMatrix<double> C;
    (void)laplacian(m.V, m.F, w, 0.1, &C);
    c.compute(C, m.F, b);
    const Eigen::MatrixXd ra = a.interpolate(v), rc = c.interpolate(v);
    ASSERT_EQ(ra.rows(), rc.rows());
    EXPECT_EQ(ra, rc);
    // a non-trivial field (not the constant the rows' zero sums would give for equal values)
    EXPECT_GT(ra.col(0).maxCoeff() - ra.col(0).minCoeff(), 0.5);
  }
  const TriMesh other = make_grid(5, 5, 1.0, 1.0, 0.0, 1);
  HarmonicInterpolator h;
  EXPECT_THROW(h.compute(cotangent_matrix(other.V, other.F), m.F, b), InvalidInput);
  EXPECT_THROW(h.compute(Eigen::SparseMatrix<double>(m.V.rows(), 3), m.F, b), InvalidInput);
}
