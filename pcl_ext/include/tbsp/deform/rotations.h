#pragma once
/// \file rotations.h
/// \brief Rotation extraction (polar decomposition, thesis eq. 3.14-3.15) and quaternion helpers.

#include <Eigen/Core>
#include <Eigen/Geometry>

namespace tbsp {

/// \brief The rotation R of the polar decomposition T = R S (S symmetric), thesis eq. 3.15:
/// H₀ = T, H_{k+1} = ½(H_k + H_k⁻ᵀ) until ‖H_{k+1} − H_k‖ < 1e-12 (at most 50 steps).
///
/// Reflection-safe: when det T ≤ 0 or T is ill-conditioned (σ_min/σ_max < 1e-8, e.g. a planar
/// edge set in eq. 3.13), the iteration would return a reflection or diverge, so R comes from the
/// SVD T = UΣVᵀ as U diag(1,1,det(UVᵀ)) Vᵀ, the closest proper rotation. det R = +1 always.
/// \param[out] iterations number of eq. 3.15 steps used (0 when the SVD path was taken).
Eigen::Matrix3d closest_rotation(const Eigen::Matrix3d& T, int* iterations = nullptr);

/// \brief Flips quaternion signs so that q_i · q_ref ≥ 0, where q_ref for each entry is given by
/// `parent` (−1 = root, kept as is). Parents must come before children (BFS order in `order`).
void make_hemisphere_consistent(std::vector<Eigen::Quaterniond>& q, const std::vector<int>& order,
                                const std::vector<int>& parent);

}  // namespace tbsp
