#pragma once
// Internal: the Gram matrix AᵀA of a sparse matrix, with sorted inner indices.
//
// Eigen's general sparse product (A.transpose() * A) takes a transposed copy, a product with a
// per-column hash/sort, and (to get sorted inner indices, which the in-place assembly of the
// Laplacian systems binary-searches) a row-major round trip: ~0.1 s for the 43k-vertex
// Armadillo's cotangent Laplacian, done again each time a fit changes its rest shape. This
// routine reads A's rows once (a row-major copy) and accumulates each result column in a dense
// scatter buffer: one pass, output written in order.

#include <Eigen/SparseCore>

namespace tbsp {
namespace detail {

/// \brief AᵀA (cols × cols), compressed, inner indices sorted in every column.
///
/// Entry (i, j) is Σ_k A(k,i)·A(k,j) summed over k in the order of column j's stored entries
/// (increasing k when A's inner indices are sorted): the same bits on every run and thread count. Exact zeros from cancellation are kept as stored
/// entries (the pattern is the structural one). Complexity O(Σ_k nnz(row k)²) time, O(cols)
/// extra memory. Blocks of columns are computed on the OpenMP threads into separate buffers.
Eigen::SparseMatrix<double> gram_sorted(const Eigen::SparseMatrix<double>& A);

}  // namespace detail
}  // namespace tbsp
