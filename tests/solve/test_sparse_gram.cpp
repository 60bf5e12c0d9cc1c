// detail::gram_sorted (pcl_ext/src/solve/sparse_gram.h): AᵀA against a dense product, the
// structural pattern, sorted columns, the same bits on any thread count.
#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <random>
#include <set>

#include "sparse_gram.h"
#include "tbsp/mesh/cotan_laplacian.h"
#include "tbsp/mesh/primitives.h"

#ifdef _OPENMP
#include <omp.h>
#endif

namespace {

Eigen::SparseMatrix<double> random_sparse_for_gram(int rows, int cols, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_int_distribution<int> row(0, rows - 1), per_col(0, 6);
  std::uniform_real_distribution<double> val(-2.0, 2.0);
  std::vector<Eigen::Triplet<double>> t;
  for (int c = 0; c < cols; ++c) {
    if (c % 17 == 5) continue;  // some empty columns
    std::set<int> used;
    const int k = per_col(rng);
    for (int m = 0; m < k; ++m) used.insert(row(rng));
    for (int r : used) t.emplace_back(r, c, val(rng));
  }
  Eigen::SparseMatrix<double> A(rows, cols);
  A.setFromTriplets(t.begin(), t.end());
  return A;
}

void expect_gram_of(const Eigen::SparseMatrix<double>& A, const Eigen::SparseMatrix<double>& G) {
  ASSERT_EQ(G.rows(), A.cols());
  ASSERT_EQ(G.cols(), A.cols());
  ASSERT_TRUE(G.isCompressed());
  const Eigen::MatrixXd Ad(A);
  const Eigen::MatrixXd want = Ad.transpose() * Ad;
  const double scale = std::max(1.0, want.cwiseAbs().maxCoeff());
  EXPECT_LE((Eigen::MatrixXd(G) - want).cwiseAbs().maxCoeff(), 1e-13 * scale);
  // the structural pattern: (i, j) stored iff columns i and j of A share a row
  const Eigen::MatrixXd S = (Ad.array() != 0).cast<double>().matrix();
  const Eigen::MatrixXd share = S.transpose() * S;
  Eigen::Index expected_nnz = 0;
  for (Eigen::Index j = 0; j < share.cols(); ++j)
    for (Eigen::Index i = 0; i < share.rows(); ++i) expected_nnz += share(i, j) > 0;
  EXPECT_EQ(G.nonZeros(), expected_nnz);
  for (Eigen::Index j = 0; j < G.outerSize(); ++j)
    for (Eigen::Index p = G.outerIndexPtr()[j] + 1; p < G.outerIndexPtr()[j + 1]; ++p)
      ASSERT_LT(G.innerIndexPtr()[p - 1], G.innerIndexPtr()[p]) << "column " << j << " not sorted";
}

}  // namespace

TEST(SparseGram, EqualsTheDenseProductWithTheStructuralPatternSorted) {
  for (unsigned seed : {1u, 2u, 3u}) {
    const Eigen::SparseMatrix<double> A = random_sparse_for_gram(90, 150 * int(seed), seed);
    expect_gram_of(A, tbsp::detail::gram_sorted(A));
  }
  // more columns than one block of the routine (2048): against Eigen's sparse product
  const Eigen::SparseMatrix<double> B = random_sparse_for_gram(400, 5000, 4u);
  const Eigen::SparseMatrix<double> G = tbsp::detail::gram_sorted(B);
  const Eigen::SparseMatrix<double> ref = Eigen::SparseMatrix<double>(B.transpose() * B);
  EXPECT_EQ(G.nonZeros(), ref.nonZeros());
  EXPECT_LE((G - ref).cwiseAbs().sum(), 1e-13 * ref.cwiseAbs().sum());
  for (Eigen::Index j = 0; j < G.outerSize(); ++j)
    for (Eigen::Index p = G.outerIndexPtr()[j] + 1; p < G.outerIndexPtr()[j + 1]; ++p)
      ASSERT_LT(G.innerIndexPtr()[p - 1], G.innerIndexPtr()[p]) << "column " << j << " not sorted";
  // an uncompressed input (inserted entries) gives the same matrix
  Eigen::SparseMatrix<double> U(5, 4);
  U.insert(3, 0) = 1.5;
  U.insert(0, 0) = -2.0;
  U.insert(4, 2) = 3.0;
  U.insert(3, 2) = 0.5;
  ASSERT_FALSE(U.isCompressed());
  expect_gram_of(U, tbsp::detail::gram_sorted(U));
}

TEST(SparseGram, ALaplaciansGramIsTheSameBitsOnOneOrTwoThreads) {
  const tbsp::TriMesh m = tbsp::make_icosphere(4);
  const Eigen::SparseMatrix<double> L = tbsp::laplacian(m.V, m.F, tbsp::LaplacianWeights::Cotangent);
  const Eigen::SparseMatrix<double> ref = Eigen::SparseMatrix<double>(L.transpose() * L);
#ifdef _OPENMP
  const int before = omp_get_max_threads();
  omp_set_num_threads(1);
#endif
  const Eigen::SparseMatrix<double> G1 = tbsp::detail::gram_sorted(L);
#ifdef _OPENMP
  omp_set_num_threads(2);
#endif
  const Eigen::SparseMatrix<double> G2 = tbsp::detail::gram_sorted(L);
#ifdef _OPENMP
  omp_set_num_threads(before);
#endif
  ASSERT_EQ(G1.nonZeros(), G2.nonZeros());
  for (Eigen::Index k = 0; k < G1.nonZeros(); ++k) {
    ASSERT_EQ(G1.innerIndexPtr()[k], G2.innerIndexPtr()[k]);
    ASSERT_EQ(G1.valuePtr()[k], G2.valuePtr()[k]);
  }
  EXPECT_EQ(G1.nonZeros(), ref.nonZeros());
  EXPECT_LE((G1 - ref).cwiseAbs().sum(), 1e-12 * ref.cwiseAbs().sum());
}
