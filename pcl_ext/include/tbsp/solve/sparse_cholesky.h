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

  /// \brief Solves A X = B for every column of B. \pre compute() succeeded.
  /// \throws NumericalFailure if nothing is factorized or the result is not finite.
  Eigen::MatrixXd solve(const Eigen::MatrixXd& B) const;

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
