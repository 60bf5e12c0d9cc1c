#pragma once
/// \file rotations.h
/// \brief Rotation extraction (polar decomposition, thesis eq. 3.14-3.15) and quaternion helpers.

#include <Eigen/Core>
#include <Eigen/Geometry>

namespace tbsp {

/// \brief The rotation R of the polar decomposition F = R S (S symmetric positive definite),
/// warm-started from a rotation R0 close to the answer (thesis eq. 3.15 and eq. 7.7-7.8): with
/// H₀ = R0ᵀ F, the Newton iteration H ← ½(γH + H⁻ᵀ/γ) (determinant scaling γ = det(H)^(-1/3)
/// while |det H − 1| > 1e-4, Higham 1986) runs until a step changes H by less than 1e-7 (at
/// most 30 steps; it converges quadratically), and R = R0 H. The one polar decomposition of
/// tbsp: the rotation field (ch. 3) and the tet deformer's rotation extraction (ch. 7) use it.
///
/// Reflection-safe: when det(R0ᵀF) ≤ 1e-10 ‖F‖³ (a reflection, a collapsed tet, a planar edge
/// set in eq. 3.13) the iteration would return a reflection or diverge, so R comes from the SVD
/// F = UΣVᵀ as U diag(1,1,det(UVᵀ)) Vᵀ, the closest proper rotation. det R = +1 always; a
/// non-finite F gives R0. O(1), about 5 steps from a good start.
/// \param F the matrix to decompose.
/// \param R0 the warm start (a rotation).
/// \param[out] iterations Newton steps used (0 when the SVD path was taken).
Eigen::Matrix3d polar_rotation(const Eigen::Matrix3d& F, const Eigen::Matrix3d& R0, int* iterations = nullptr);

/// \brief polar_rotation(T, identity): the closest proper rotation to T (eq. 3.15).
/// \param T the matrix. \param[out] iterations as polar_rotation.
Eigen::Matrix3d closest_rotation(const Eigen::Matrix3d& T, int* iterations = nullptr);

/// \brief Flips quaternion signs so that q_i · q_ref ≥ 0, where q_ref for each entry is given by
/// `parent` (−1 = root, kept as is). Parents must come before children (BFS order in `order`).
void make_hemisphere_consistent(std::vector<Eigen::Quaterniond>& q, const std::vector<int>& order,
                                const std::vector<int>& parent);

}  // namespace tbsp
