#pragma once
/// \file point_normals.h
/// \brief Point-cloud normals: PCA estimation and consistent orientation.

#include <Eigen/Core>

#include "tbsp/mesh/point_search.h"

namespace tbsp {

struct NormalOrientationResult {
  int edges = 0;       ///< neighbour pairs used (aligned normals, offset along the surface)
  int conflicts = 0;   ///< pairs left disagreeing after the spanning forest was built
  int components = 0;  ///< connected components of the pairs (isolated points count as one each)
  int flipped = 0;     ///< normals flipped
};

/// \brief Makes the orientation of normals consistent between neighbours, keeping per connected
/// component the orientation a reference agrees with more.
///
/// `N` (one unit normal per point of `tree`) comes in oriented by some reference — e.g. the
/// nearest vertex normal of a posed template — that is right on most of the surface but can be
/// wrong in patches (a sphere's outward normal over a concave ledge). `confidence` (≥ 0, one per
/// point) says how much the reference is trusted at each point, e.g. |n · n_template|.
///
/// Method (Hoppe et al. 1992, with two guards): neighbour pairs among the k nearest whose
/// normals are aligned (|n_i · n_j| ≥ `min_alignment`) *and* whose offset lies along the surface
/// (|(p_j − p_i) · n| ≤ `max_normal_offset` |p_j − p_i| for both normals) are processed in order
/// of decreasing |n_i · n_j| into a spanning forest with relative signs (union-find with parity,
/// Kruskal). The offset test keeps the two sides of a thin sheet — neighbours along the normal,
/// with opposite outward normals — from being made to agree (down to a thickness of about the
/// sample spacing; thinner sheets cannot be told from one noisy surface), and keeps off-surface
/// outliers out.
/// Per component the sign class with the larger summed confidence keeps its incoming orientation,
/// the other is flipped. Deterministic (ties broken by index).
///
/// Complexity O(n k log(n k)) (one k-NN query per point, a sort of the pairs); memory O(n k).
/// \throws InvalidInput if N or confidence do not match the tree's size, or k < 2.
NormalOrientationResult orient_normals_consistently(const PointSearch& tree, Eigen::MatrixX3d& N,
                                                    const Eigen::VectorXd& confidence, int k = 16,
                                                    double min_alignment = 0.7, double max_normal_offset = 0.5);

/// \brief Unoriented normals by PCA: per point of `tree`, the eigenvector of the smallest
/// eigenvalue of the covariance of its k nearest neighbours (the point included), unit length,
/// sign arbitrary (orient them with a reference, then orient_normals_consistently).
/// A point whose neighbours are all one point gets an arbitrary unit vector.
/// O(n k) after the tree; parallel over points; deterministic.
/// \param tree the points (PointSearch over #P by 3).
/// \param k neighbours per point (≥ 3; the template fitter uses FitParameters::normal_neighbours).
/// \returns #P by 3 unit normals.
/// \throws InvalidInput if k < 3.
Eigen::MatrixX3d estimate_normals_pca(const PointSearch& tree, int k);

}  // namespace tbsp
