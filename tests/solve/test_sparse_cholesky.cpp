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

// a copied analysis is used for a matrix of its pattern (no analysis of its own, the same bits
// as a solver that analysed it) and ignored for another pattern
TEST_P(SparseCholeskyBackends, CopiedAnalysisGivesTheSameFactorsAndOnlyForItsPattern) {
  const bool cholmod = GetParam() == SparseCholesky::Backend::Cholmod;
  if (cholmod && !SparseCholesky::cholmodAvailable()) GTEST_SKIP();
  const Eigen::SparseMatrix<double> A = spd_system(0.1), A2 = spd_system(0.3);
  Eigen::SparseMatrix<double> other = spd_system(0.1);
  other.coeffRef(0, 5) += 1e-3;
  other.coeffRef(5, 0) += 1e-3;
  SparseCholesky first(GetParam()), fresh(GetParam()), copied(GetParam());
  first.compute(A);
  fresh.compute(A2);
  copied.compute(other);  // its own analysis (another pattern) and factorization give way to the copy
  copied.copyAnalysis(first);
  EXPECT_EQ(copied.isFactorized(), !cholmod);  // SimplicialLDLT cannot be copied: left as it was
  copied.compute(A2);
  EXPECT_EQ(copied.numAnalyses(), cholmod ? 1 : 2);  // CHOLMOD: the copy's pattern, no analysis of its own
  const Eigen::MatrixXd B = Eigen::MatrixXd::Random(A.rows(), 3);
  EXPECT_EQ(fresh.solve(B), copied.solve(B));  // bit for bit
  SparseCholesky reuse(GetParam());
  reuse.copyAnalysis(first);
  reuse.compute(other);  // another pattern than the copy's: analysed anew, still exact
  EXPECT_EQ(reuse.numAnalyses(), 1);
  const Eigen::MatrixXd Xo = reuse.solve(B), Xd = Eigen::MatrixXd(other).ldlt().solve(B);
  EXPECT_LT((Xo - Xd).norm() / Xd.norm(), 1e-10);
  SparseCholesky nothing(GetParam());
  reuse.copyAnalysis(nothing);  // no analysis to copy, or itself: unchanged
  reuse.copyAnalysis(reuse);
  EXPECT_TRUE(reuse.isFactorized());
  EXPECT_EQ(reuse.solve(B), Xo);
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

namespace {
// the bi-Laplacian system of a deformation (LᵀL + a few anchors): big enough for a factor with
// thousands of supernodes and a two-part split
Eigen::SparseMatrix<double> bilaplacian_system() {
  const TriMesh m = make_icosphere(4);
  const Eigen::SparseMatrix<double> L = laplacian(m.V, m.F);
  Eigen::SparseMatrix<double> N = Eigen::SparseMatrix<double>(L.transpose() * L);
  for (int i = 0; i < N.rows(); i += 50) N.coeffRef(i, i) += 1.0;
  return N;
}
}  // namespace

// tbsp's supernodal kernel against CHOLMOD's own cholmod_solve on the same factor, for 1 to 7
// right-hand sides (3 = x, y, z of a deformation; the generic path above 3)
TEST(SparseCholeskyKernel, AgreesWithCholmodSolveForAnyNumberOfColumns) {
  if (!SparseCholesky::cholmodAvailable()) GTEST_SKIP();
  const Eigen::SparseMatrix<double> A = bilaplacian_system();
  SparseCholesky s;
  s.compute(A);
  EXPECT_GT(s.factorNonZeros(), std::size_t(A.nonZeros()));
  for (int k : {1, 2, 3, 4, 7}) {
    const Eigen::MatrixXd B = Eigen::MatrixXd::Random(A.rows(), k);
    s.setCholmodSolve(false);
    const Eigen::MatrixXd X = s.solve(B);
    s.setCholmodSolve(true);
    const Eigen::MatrixXd Xc = s.solve(B);
    EXPECT_LT((X - Xc).norm() / Xc.norm(), 1e-11) << k << " columns";
    EXPECT_LT((A * X - B).norm() / B.norm(), 1e-9) << k << " columns";
  }
}

// solve(B, X) reuses X's storage: a drag loop allocates nothing for the result
TEST(SparseCholeskyKernel, SolveIntoReusesTheResult) {
  const Eigen::SparseMatrix<double> A = bilaplacian_system();
  SparseCholesky s;
  s.compute(A);
  Eigen::MatrixXd X;
  s.solve(Eigen::MatrixXd::Ones(A.rows(), 3), X);
  const double* storage = X.data();
  const Eigen::MatrixXd B = Eigen::MatrixXd::Random(A.rows(), 3);
  s.solve(B, X);
  EXPECT_EQ(X.data(), storage);
  EXPECT_LT((A * X - B).norm() / B.norm(), 1e-9);
  EXPECT_THROW(s.solve(Eigen::MatrixXd::Ones(A.rows() + 1, 3), X), InvalidInput);
}

#ifdef _OPENMP
// the kernel runs two subtrees of the factor side by side; the arithmetic is the same on one
// thread, so the bits are too. Concurrent solves on one object (one workspace per thread)
// give the same bits as well.
TEST(SparseCholeskyKernel, SameBitsOnOneOrTwoThreadsAndConcurrentCallers) {
  const Eigen::SparseMatrix<double> A = bilaplacian_system();
  SparseCholesky s;
  s.compute(A);
  const Eigen::MatrixXd B = Eigen::MatrixXd::Random(A.rows(), 3);
  const int before = omp_get_max_threads();
  omp_set_num_threads(1);
  const Eigen::MatrixXd X1 = s.solve(B);
  omp_set_num_threads(2);
  const Eigen::MatrixXd X2 = s.solve(B);
  omp_set_num_threads(before);
  EXPECT_TRUE((X1.array() == X2.array()).all());
  Eigen::MatrixXd Xt[2];
#pragma omp parallel for num_threads(2)
  for (int t = 0; t < 2; ++t) Xt[t] = s.solve(B);
  EXPECT_TRUE((Xt[0].array() == X1.array()).all());
  EXPECT_TRUE((Xt[1].array() == X1.array()).all());
}
#endif
