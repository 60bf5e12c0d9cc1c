#pragma once
/// \file geodesics.h
/// \brief Approximate geodesic distances: Dijkstra on the mesh edge graph (edge length =
/// Euclidean length). Overestimates the true geodesic by a mesh-dependent factor (typically
/// 2-8 % on irregular triangulations); exact under uniform scaling, which is what the ratios of
/// §5.2 need. Written by hand: a binary-heap Dijkstra on our adjacency is shorter than wiring
/// Boost.Graph or CGAL's exact geodesics for this approximate use.

#include <Eigen/Core>
#include <vector>

#include "tbsp/core/progress.h"

namespace tbsp {

/// \brief Dijkstra distances (#V) from the given source vertices (distance 0 at each source).
/// Unreachable vertices get +infinity. O((#V + #E) log #V).
/// \throws InvalidInput if a source index is out of range.
Eigen::VectorXd dijkstra_distances(const Eigen::MatrixX3d& V, const std::vector<std::vector<int>>& adjacency,
                                   const std::vector<int>& sources);

/// \brief k by k matrix of approximate geodesic distances between the given vertices
/// (symmetrised: (D + Dᵀ)/2; +infinity between different components). One Dijkstra per
/// vertex, run in parallel. O(k (#V + #E) log #V).
Eigen::MatrixXd geodesic_distance_matrix(const Eigen::MatrixX3d& V, const Eigen::MatrixX3i& F,
                                         const std::vector<int>& vertices, const ProgressCallback& progress = {});

/// \brief The Dijkstra shortest edge paths between every pair of the given vertices:
/// paths[a][b] runs from vertices[a] to vertices[b] (both included); empty when a and b are the
/// same vertex or lie on different components. Lets a caller re-measure the same curves on
/// another pose of the mesh with path_length() instead of searching again (§5.2 scale
/// iteration). O(k (#V + #E) log #V) time, O(k² · path length) memory.
/// \throws InvalidInput if an index is out of range.
std::vector<std::vector<std::vector<int>>> geodesic_paths(const Eigen::MatrixX3d& V, const Eigen::MatrixX3i& F,
                                                         const std::vector<int>& vertices);

/// \brief Length of a vertex path (sum of its edge lengths) on the positions V. O(path length).
double path_length(const Eigen::MatrixX3d& V, const std::vector<int>& path);

/// \brief Global scale factor of §5.2: the mean, over all pairs of marked vertices joined by a
/// path, of the ratio of their Dijkstra distances on `V_deformed` to those on `V_reference`
/// (both with connectivity F). λ > 1 means the deformed shape is larger.
/// \throws InvalidInput for fewer than 2 distinct marked vertices, bad indices, mismatched
/// vertex counts, or when no pair of marks is connected with a positive reference distance.
double global_scale_from_geodesics(const Eigen::MatrixX3d& V_reference, const Eigen::MatrixX3d& V_deformed,
                                   const Eigen::MatrixX3i& F, const std::vector<int>& marked);

}  // namespace tbsp
