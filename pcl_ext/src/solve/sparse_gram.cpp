// AᵀA with sorted inner indices (sparse_gram.h).
#include "sparse_gram.h"

#include <algorithm>
#include <vector>

namespace tbsp {
namespace detail {

Eigen::SparseMatrix<double> gram_sorted(const Eigen::SparseMatrix<double>& A_in) {
  Eigen::SparseMatrix<double> copy;
  if (!A_in.isCompressed()) {
    copy = A_in;
    copy.makeCompressed();
  }
  const Eigen::SparseMatrix<double>& A = A_in.isCompressed() ? A_in : copy;
  const Eigen::SparseMatrix<double, Eigen::RowMajor> R = A;  // the rows of A
  const int n = int(A.cols());
  // columns in fixed blocks; each block's entries in its own buffers, joined in order below
  constexpr int kBlock = 2048;
  const int nb = (n + kBlock - 1) / kBlock;
  std::vector<std::vector<int>> block_index(static_cast<std::size_t>(nb));
  std::vector<std::vector<double>> block_value(static_cast<std::size_t>(nb));
  std::vector<int> col_nnz(static_cast<std::size_t>(n), 0);
#pragma omp parallel
  {
    std::vector<double> acc(static_cast<std::size_t>(n), 0.0);
    std::vector<int> mark(static_cast<std::size_t>(n), -1), touched;
#pragma omp for schedule(dynamic, 1)
    for (int b = 0; b < nb; ++b) {
      std::vector<int>& bi = block_index[std::size_t(b)];
      std::vector<double>& bv = block_value[std::size_t(b)];
      for (int j = b * kBlock; j < std::min(n, (b + 1) * kBlock); ++j) {
        touched.clear();
        for (Eigen::SparseMatrix<double>::InnerIterator it(A, j); it; ++it) {  // stored order
          const double akj = it.value();
          for (Eigen::SparseMatrix<double, Eigen::RowMajor>::InnerIterator r(R, it.row()); r; ++r) {
            const int i = int(r.col());
            if (mark[std::size_t(i)] != j) {
              mark[std::size_t(i)] = j;
              acc[std::size_t(i)] = 0.0;
              touched.push_back(i);
            }
            acc[std::size_t(i)] += r.value() * akj;
          }
        }
        std::sort(touched.begin(), touched.end());
        col_nnz[std::size_t(j)] = int(touched.size());
        for (int i : touched) {
          bi.push_back(i);
          bv.push_back(acc[std::size_t(i)]);
        }
      }
    }
  }
  Eigen::SparseMatrix<double> G(n, n);
  std::size_t nnz = 0;
  for (const auto& b : block_index) nnz += b.size();
  G.resizeNonZeros(Eigen::Index(nnz));
  G.outerIndexPtr()[0] = 0;
  for (int j = 0; j < n; ++j) G.outerIndexPtr()[j + 1] = G.outerIndexPtr()[j] + col_nnz[std::size_t(j)];
  std::size_t at = 0;
  for (int b = 0; b < nb; ++b) {
    std::copy(block_index[std::size_t(b)].begin(), block_index[std::size_t(b)].end(), G.innerIndexPtr() + at);
    std::copy(block_value[std::size_t(b)].begin(), block_value[std::size_t(b)].end(), G.valuePtr() + at);
    at += block_index[std::size_t(b)].size();
  }
  return G;
}

}  // namespace detail
}  // namespace tbsp
