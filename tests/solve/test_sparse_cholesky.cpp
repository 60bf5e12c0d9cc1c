#include <gtest/gtest.h>

#include <Eigen/Dense>

#include "tbsp/core/error.h"
#include "tbsp/mesh/cotan_laplacian.h"
#include "tbsp/mesh/primitives.h"
#include "tbsp/solve/sparse_cholesky.h"

using namespace tbsp;

namespace {
Eigen::SparseMatrix<double> spd_system(double shift) {
  const TriMesh m = make_icosphere(2);
  Eigen::SparseMatrix<double> A = -cotangent_matrix(m.V, m.F);
  for (int i = 0; i < A.rows(); ++i) A.coeffRef(i, i) += shift;
  return A;
}
}  // namespace

class SparseCholeskyBackends : public ::testing::TestWithParam<SparseCholesky::Backend> {};

TEST_P(SparseCholeskyBackends, SolvesAndReusesTheAnalysis) {
  if (GetParam() == SparseCholesky::Backend::Cholmod && !SparseCholesky::cholmodAvailable()) GTEST_SKIP();
  const Eigen::SparseMatrix<double> A = spd_system(0.1);
  SparseCholesky s(GetParam());
  s.compute(A);
  const Eigen::MatrixXd B = Eigen::MatrixXd::Random(A.rows(), 3);
  const Eigen::MatrixXd X = s.solve(B);
  const Eigen::MatrixXd Xd = Eigen::MatrixXd(A).ldlt().solve(B);
  EXPECT_LT((X - Xd).norm() / Xd.norm(), 1e-10);
  s.compute(spd_system(0.2));  // same pattern: numeric factorization only
  EXPECT_EQ(s.numAnalyses(), 1);
  EXPECT_EQ(s.numFactorizations(), 2);
  Eigen::SparseMatrix<double> bigger = spd_system(0.1);
  bigger.coeffRef(0, 5) += 1e-3;
  bigger.coeffRef(5, 0) += 1e-3;
  s.compute(bigger);
  EXPECT_EQ(s.numAnalyses(), 2);
}

TEST_P(SparseCholeskyBackends, SingularSystemIsANumericalFailure) {
  if (GetParam() == SparseCholesky::Backend::Cholmod && !SparseCholesky::cholmodAvailable()) GTEST_SKIP();
  SparseCholesky s(GetParam());
  EXPECT_THROW(s.compute(spd_system(-0.5)), NumericalFailure);  // indefinite
  EXPECT_THROW(s.solve(Eigen::MatrixXd::Zero(3, 1)), NumericalFailure);
  EXPECT_THROW(s.compute(Eigen::SparseMatrix<double>(3, 4)), InvalidInput);
}

INSTANTIATE_TEST_SUITE_P(Backends, SparseCholeskyBackends,
                         ::testing::Values(SparseCholesky::Backend::Cholmod, SparseCholesky::Backend::EigenLDLT));

#ifdef _OPENMP
#include <omp.h>
// compute()/solve() turn on OpenMP dynamic adjustment while CHOLMOD runs (its fixed 4-thread
// teams oversubscribe small machines) and restore the caller's setting afterwards
TEST(SparseCholeskyThreads, CallerDynamicSettingIsRestored) {
  for (int before : {0, 1}) {
    omp_set_dynamic(before);
    SparseCholesky s;
    s.compute(spd_system(1.0));
    EXPECT_EQ(omp_get_dynamic(), before);
    const Eigen::MatrixXd x = s.solve(Eigen::MatrixXd::Ones(s.rows(), 2));
    EXPECT_EQ(omp_get_dynamic(), before);
    EXPECT_TRUE(x.allFinite());
  }
  omp_set_dynamic(0);
}
#endif
