#pragma once
/// \file topology.h
/// \brief Connectivity helpers: unique edges, vertex adjacency, connected components.

#include <Eigen/Core>
#include <vector>

namespace tbsp {

/// #E by 2 unique undirected edges (i < j), sorted. O(#F log #F).
Eigen::MatrixX2i unique_edges(const Eigen::MatrixX3i& F);

/// Per-vertex sorted neighbour lists (one-ring over faces). O(#F log #F).
std::vector<std::vector<int>> vertex_adjacency(const Eigen::MatrixX3i& F, Eigen::Index num_vertices);

/// Component label per vertex (0..k-1, face-connected; each isolated vertex is its own
/// component). Returns k. O(#F α).
int connected_components(const Eigen::MatrixX3i& F, Eigen::Index num_vertices, Eigen::VectorXi& labels);

}  // namespace tbsp
