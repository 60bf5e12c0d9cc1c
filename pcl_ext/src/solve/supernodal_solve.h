#pragma once
// Internal: triangular solves with a CHOLMOD supernodal LLᵀ factor for a few right-hand sides.
//
// CHOLMOD's own cholmod_solve calls BLAS (dtrsm + dgemm) once per supernode. With the three
// right-hand sides of a deformation re-solve, OpenBLAS spends most of that time packing each
// supernode's block into its GEMM layout, i.e. reading the factor more than once, plus the
// per-call overhead on tens of thousands of small supernodes; cholmod_solve also allocates its
// result and workspace on every call. This kernel reads every stored entry of the factor exactly
// once per triangular solve, keeps the right-hand sides interleaved (row-major, K per row) so
// one factor entry updates all of them, and works in caller-owned buffers. Written by hand
// because no Debian library offers a supernodal multi-RHS solve without BLAS packing.
// The arithmetic order is fixed by the factor: results do not depend on threads or runs.

#include <cstddef>
#include <vector>

namespace tbsp {
namespace detail {

/// \brief View of a CHOLMOD supernodal LLᵀ factor (int indices, real double values).
struct SupernodalFactorView {
  int n = 0;            ///< matrix size
  int nsuper = 0;       ///< number of supernodes
  const int* perm = nullptr;   ///< fill-reducing permutation, size n (row k of L is row perm[k] of A)
  const int* super = nullptr;  ///< size nsuper+1: first column of each supernode
  const int* pi = nullptr;     ///< size nsuper+1: offsets of each supernode's row indices in s
  const int* px = nullptr;     ///< size nsuper+1: offsets of each supernode's values in x
  const int* s = nullptr;      ///< row indices of every supernode (its own columns first)
  const double* x = nullptr;   ///< column-major nsrow x nscol value blocks
  /// Largest number of rows of one supernode (the size of the gather buffer).
  int max_rows = 0;
  /// Stored values (the factor's memory footprint in doubles, padding included).
  std::size_t values() const { return nsuper > 0 ? std::size_t(px[nsuper]) : 0; }
};

/// \brief A split of the supernodal elimination tree into two independent parts (subtrees)
/// and the top they share, so both triangular solves can run the parts on two threads. The
/// arithmetic is the same whether the parts run side by side or one after the other: results do
/// not depend on the thread count.
struct SupernodalPlan {
  std::vector<int> part[2];  ///< supernodes of each part, increasing (children first)
  std::vector<int> top;      ///< the rest (ancestors of both parts), increasing
  std::vector<int> top_index;  ///< per column: its index among the top's columns, or -1
  std::vector<int> top_row;    ///< the top's columns
  int top_rows = 0;
};

/// \brief Builds the split (O(n + nsuper log nsuper)); the factor's structure only.
SupernodalPlan make_supernodal_plan(const SupernodalFactorView& L);

/// \brief Doubles of workspace supernodal_solve needs for K right-hand sides.
std::size_t supernodal_work_size(const SupernodalFactorView& L, const SupernodalPlan& plan, int K);

/// \brief Solves A X = B with A = P' L Lᵀ P for K right-hand sides.
/// \param B column-major n x K (leading dimension ldb), X the same (may alias B).
/// \param work supernodal_work_size() doubles.
/// \param threads run the plan's two parts on two OpenMP threads (ignored inside a parallel
/// region); the result is bit-identical either way.
void supernodal_solve(const SupernodalFactorView& L, const SupernodalPlan& plan, int K, const double* B,
                      std::ptrdiff_t ldb, double* X, std::ptrdiff_t ldx, double* work, bool threads);

}  // namespace detail
}  // namespace tbsp
