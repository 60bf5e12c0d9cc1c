#pragma once
/// \file sparse_cholesky.h
/// \brief Prefactor-once / solve-many sparse Cholesky for symmetric positive definite systems.
///
/// Backend: CHOLMOD (SuiteSparse, supernodal LLᵀ) when tbsp was built with it, otherwise
/// Eigen's SimplicialLDLT. compute() reuses the symbolic analysis when the sparsity pattern is
/// unchanged, so re-weighting constraints only pays the numeric factorization; solve() is a
/// pair of triangular back-substitutions and can be called any number of times.

#include <Eigen/Core>
#include <Eigen/SparseCore>
#include <cstddef>
#include <memory>
#include <string>

namespace tbsp {

class SparseCholesky {
public:
  enum class Backend { Auto, Cholmod, EigenLDLT };

  explicit SparseCholesky(Backend backend = Backend::Auto);
  ~SparseCholesky();
  SparseCholesky(SparseCholesky&&) noexcept;
  SparseCholesky& operator=(SparseCholesky&&) noexcept;
  SparseCholesky(const SparseCholesky&) = delete;
  SparseCholesky& operator=(const SparseCholesky&) = delete;

  /// \brief Factorizes the SPD matrix A (only its lower triangle is read).
  /// \throws NumericalFailure when A is not positive definite (a rank-deficient system:
  /// usually too few constraints), InvalidInput when A is not square.
  void compute(const Eigen::SparseMatrix<double>& A);

  /// \brief Takes over `other`'s symbolic analysis (fill-reducing ordering, supernodes) and the
  /// sparsity pattern it was made for, so that the next compute() of a matrix with that pattern
  /// runs the numeric factorization only; a matrix with another pattern is analysed anew as
  /// usual. The factors are identical to analysing anew (the analysis depends on the pattern
  /// alone). For solvers of systems that share a mesh's connectivity (two fits of one
  /// template): the ordering of a 43k-vertex Laplacian system costs ~0.15 s. Drops this
  /// solver's own factorization; numAnalyses() is not changed. Copies O(nnz(L)) memory; not
  /// while `other` computes. Nothing happens when `other` has no analysis, uses another
  /// backend, or the backend is Eigen's (its analysis cannot be copied: the next compute()
  /// analyses as usual).
  void copyAnalysis(const SparseCholesky& other);

  /// \brief Solves A X = B for every column of B. \pre compute() succeeded.
  /// \throws NumericalFailure if nothing is factorized or the result is not finite.
  Eigen::MatrixXd solve(const Eigen::MatrixXd& B) const;
  /// \brief The same, into X: X's storage is reused when it already has B's size, so repeated
  /// solves (interactive dragging) allocate nothing.
  ///
  /// With CHOLMOD, both triangular solves run in tbsp's own supernodal kernel: every stored
  /// factor entry is read once per triangular solve and updates all columns of B at once
  /// (O(nnz(L)·cols) flops, memory-bound; see docs/benchmarks.md). Not safe to call on one
  /// object from several threads while compute() runs; concurrent solve() calls are fine.
  void solve(const Eigen::MatrixXd& B, Eigen::MatrixXd& X) const;

  /// \brief With CHOLMOD: run CHOLMOD's own cholmod_solve (BLAS per supernode) instead of
  /// tbsp's kernel; for comparisons (bench_deform) and as a fallback. Default false.
  void setCholmodSolve(bool on);

  /// Stored entries of the factor (CHOLMOD: supernodal blocks, padding included); 0 before
  /// compute(). Its size in bytes, ×8, is what one solve streams twice.
  std::size_t factorNonZeros() const;

  bool isFactorized() const;
  Eigen::Index rows() const;
  /// "cholmod-supernodal" or "eigen-simplicial-ldlt".
  std::string backendName() const;
  /// True if CHOLMOD is compiled in.
  static bool cholmodAvailable();
  /// Number of symbolic analyses performed so far (tests check reuse).
  int numAnalyses() const;
  /// Number of numeric factorizations performed so far.
  int numFactorizations() const;

private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace tbsp
