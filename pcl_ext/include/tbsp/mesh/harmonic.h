#pragma once
/// \file harmonic.h
/// \brief Harmonic interpolation (thesis §3.2.2, eq. 3.11): solve L s = 0 on the free vertices
/// with the values at the constrained vertices fixed (Dirichlet). Any number of channels (scalar
/// fields, vectors, quaternion components) share one factorization.

#include <Eigen/Core>
#include <vector>

#include "tbsp/mesh/cotan_laplacian.h"
#include "tbsp/solve/sparse_cholesky.h"

namespace tbsp {

/// \brief Prefactored harmonic interpolation on a fixed mesh and fixed constrained set.
///
/// \code
/// tbsp::HarmonicInterpolator h;
/// h.compute(mesh.V, mesh.F, {0, 17, 42});
/// Eigen::MatrixXd colors = h.interpolate(known_colors);   // 3 by 3 in, #V by 3 out
/// \endcode
/// Uses the symmetric form (−C restricted to the free vertices, SPD), which has the same
/// solution as eq. 3.11 with L = M⁻¹C. With cotangent weights, linear functions on planar
/// meshes are reproduced exactly.
class HarmonicInterpolator {
public:
  /// \brief Builds and factorizes the system. O(#F) + one sparse Cholesky.
  /// \throws InvalidInput for an empty constrained set, out-of-range indices, or a component
  /// of the mesh holding no constrained vertex (the value there would be undefined).
  void compute(const Eigen::MatrixX3d& V, const Eigen::MatrixX3i& F, const std::vector<int>& constrained,
               LaplacianWeights weights = LaplacianWeights::Cotangent);

  /// \brief The same with the mesh's matrix given: `C` = cotangent_matrix(V, F) (or
  /// uniform_graph_laplacian(F, #V) for uniform weights), #V by #V, symmetric, off-diagonal ≥ 0
  /// on a well-shaped mesh, rows summing to 0. For callers that already have it (laplacian()'s
  /// `stiffness`): the result is the same to the last bit as compute(V, F, …) and the O(#F)
  /// assembly is skipped. F gives the components (each needs a constrained vertex).
  /// \throws InvalidInput as compute(), and when C is not #V by #V for the #V of F's indices.
  void compute(const Eigen::SparseMatrix<double>& C, const Eigen::MatrixX3i& F, const std::vector<int>& constrained);

  /// \brief Interpolates `values` (one row per constrained vertex, in the order given to
  /// compute(), any number of columns) to all vertices. Constrained vertices keep their values
  /// exactly; isolated unconstrained vertices get 0. O(#V · cols) back-substitution.
  Eigen::MatrixXd interpolate(const Eigen::MatrixXd& values) const;

  const std::vector<int>& constrained() const { return constrained_; }

private:
  Eigen::Index n_ = 0;
  std::vector<int> constrained_;
  std::vector<int> free_index_;  // vertex -> row in the free system, -1 if constrained/isolated
  Eigen::SparseMatrix<double> K_fb_;  // coupling free <- constrained (of −C)
  SparseCholesky solver_;
  bool has_free_ = false;
};

/// \brief One-shot harmonic interpolation (see HarmonicInterpolator).
Eigen::MatrixXd harmonic_interpolation(const Eigen::MatrixX3d& V, const Eigen::MatrixX3i& F,
                                       const std::vector<int>& constrained, const Eigen::MatrixXd& values,
                                       LaplacianWeights weights = LaplacianWeights::Cotangent);

}  // namespace tbsp
