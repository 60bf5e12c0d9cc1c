#pragma once
/// \file cotan_laplacian.h
/// \brief Discrete Laplace-Beltrami operators (thesis §3.1, eq. 3.1-3.3).
///
/// Sign convention (as libigl): off-diagonal entries are the edge weights, the diagonal is
/// **minus** their sum, so every row sums to 0 and δ = L V gives δ_i = Σ_j w_ij (v_j − v_i)
/// (eq. 3.1). With cotangent weights δ_i ≈ −H_i n_i where H_i = κ1 + κ2 (twice the mean
/// curvature) and n_i the outward normal: on a sphere of radius r, δ_i ≈ −(2/r) n_i.
///
/// Robustness: a face whose triangle inequality holds with a margin below 1e-4 × the mean edge
/// length (zero-area, collinear or coincident corners) is *intrinsically mollified* (Sharp &
/// Crane 2020): its three edge lengths grow by the same amount until the margin is reached, and
/// its cotangents and area come from those lengths (Heron). Its three cotangents thus belong to
/// one real triangle and its stiffness block stays positive semi-definite, so a zero-area face
/// does not make the deformation and interpolation systems indefinite. Other faces: cos/sin with
/// sin floored at 1e-12 · |a||b|, clamped to ±kMaxCotangent. Mixed Voronoi areas are floored at
/// 1e-8 × the mean vertex area, and a row without any usable weight falls back to the uniform
/// row, so obtuse, needle and zero-area triangles never produce Inf/NaN or empty rows.

#include <Eigen/Core>
#include <Eigen/SparseCore>

namespace tbsp {

/// Edge weighting scheme of the Laplacian.
enum class LaplacianWeights {
  Cotangent,  ///< w_ij = (cot α_ij + cot β_ij) / (2 A_i), mixed Voronoi areas (eq. 3.2)
  Uniform     ///< w_ij = 1 / deg(i): δ_i = centroid of the one-ring − v_i
};

/// Largest |cot| used (angles below ~0.0057° or above ~179.994° are clamped).
constexpr double kMaxCotangent = 1e4;

/// \brief Symmetric cotangent stiffness matrix C (#V by #V): C_ij = ½(cot α_ij + cot β_ij)
/// summed over the faces of edge ij, C_ii = −Σ_j C_ij. Negative semi-definite; boundary
/// edges contribute their single angle. O(#F).
Eigen::SparseMatrix<double> cotangent_matrix(const Eigen::MatrixX3d& V, const Eigen::MatrixX3i& F);

/// \brief Cotangent of the angle at every corner (#F by 3: column c is the corner F(f, c)),
/// robust as cotangent_matrix (mollified degenerate faces, clamped). Used by the operators that
/// need per-face gradients (heat geodesics). O(#F).
Eigen::MatrixX3d face_cotangents(const Eigen::MatrixX3d& V, const Eigen::MatrixX3i& F);

/// \brief Mixed Voronoi vertex areas (Meyer et al. 2002), #V: Voronoi region inside
/// non-obtuse triangles, half/quarter of the triangle area for obtuse ones (Fig. 3.2). The areas
/// of all vertices sum to the surface area. Isolated vertices get 0. O(#F).
Eigen::VectorXd voronoi_areas(const Eigen::MatrixX3d& V, const Eigen::MatrixX3i& F);

/// \brief Mean of voronoi_areas over the vertices of the faces F (isolated vertices left out;
/// 0 when no vertex has an area): LaplacianDeformer's area normalization Ā (L̂ = Ā L). O(#F).
double mean_voronoi_area(const Eigen::MatrixX3d& V, const Eigen::MatrixX3i& F);

/// \brief Uniform graph Laplacian (symmetric): off-diagonal 1 per edge, diagonal −degree.
Eigen::SparseMatrix<double> uniform_graph_laplacian(const Eigen::MatrixX3i& F, Eigen::Index num_vertices);

/// \brief The symmetric matrix a Laplacian's rows are scaled from: cotangent_matrix(V, F) for
/// cotangent weights, uniform_graph_laplacian(F, #V) for uniform ones. O(#F).
Eigen::SparseMatrix<double> laplacian_stiffness(const Eigen::MatrixX3d& V, const Eigen::MatrixX3i& F, LaplacianWeights weights);

/// \brief The Laplacian of eq. 3.2 as a #V by #V matrix (rows sum to 0, not symmetric):
/// cotangent: L = M⁻¹ C with M = diag(2 · voronoi_areas) so that w_ij = (cot α + cot β)/(2 A_i);
/// uniform: L = D⁻¹ G (G the graph Laplacian, D the degrees).
/// Rows of isolated vertices are empty. O(#F).
/// \param V, F the mesh (#V by 3, #F by 3).
/// \param weights cotangent (default) or uniform.
/// \param sliver_guard 0 (default): cotangent rows divide by the vertex area A_i (floored at
/// 1e-8 of the mean only against division by zero). > 0: A_i is floored at sliver_guard · ē_i²
/// (ē_i the mean length of the vertex's edges; a regular vertex has A_i ≈ 0.87 ē_i²), so a
/// vertex surrounded by slivers gets a bounded row instead of one that outweighs the rest of a
/// least-squares system by orders of magnitude. The fitter's Laplacian updating uses 0.1 (its
/// intermediate meshes can have slivers).
/// \param stiffness if not null, receives the symmetric matrix the rows are scaled from:
/// laplacian_stiffness(V, F, weights), the same bits
/// (for a harmonic system on the same mesh, HarmonicInterpolator::compute, without building
/// it twice).
Eigen::SparseMatrix<double> laplacian(const Eigen::MatrixX3d& V, const Eigen::MatrixX3i& F,
                                      LaplacianWeights weights = LaplacianWeights::Cotangent,
                                      double sliver_guard = 0, Eigen::SparseMatrix<double>* stiffness = nullptr);

}  // namespace tbsp
