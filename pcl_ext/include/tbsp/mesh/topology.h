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

/// vertex_adjacency compressed: vertex v's neighbours are neighbours[offsets[v] .. offsets[v+1]),
/// ascending (the same lists). O(#F log #F).
void vertex_adjacency_compressed(const Eigen::MatrixX3i& F, Eigen::Index num_vertices, std::vector<int>& offsets,
                                 std::vector<int>& neighbours);

/// Faces around each vertex, compressed: vertex v's faces are faces[offsets[v] .. offsets[v+1])
/// in ascending face index (a face listing a vertex twice appears twice). O(#F + #V).
void vertex_faces(const Eigen::MatrixX3i& F, Eigen::Index num_vertices, std::vector<int>& offsets, std::vector<int>& faces);

/// Component label per vertex (0..k-1, face-connected; each isolated vertex is its own
/// component). Returns k. O(#F α).
int connected_components(const Eigen::MatrixX3i& F, Eigen::Index num_vertices, Eigen::VectorXi& labels);

/// Adds the neighbours (per `adj`, e.g. vertex_adjacency) of the marked vertices to `region`,
/// `rings` times. O(rings · Σ neighbours).
void grow_region(std::vector<char>& region, const std::vector<std::vector<int>>& adj, int rings = 1);

/// One uniform umbrella (Laplacian) smoothing step on the marked vertices, all moved at once:
/// v ← (1 − λ) v + λ · mean of its neighbours. Unmarked vertices and vertices without
/// neighbours stay. If `moved` is given (sized #V), the vertices moved are set to 1 in it.
void umbrella_step(Eigen::MatrixX3d& V, const std::vector<std::vector<int>>& adj, const std::vector<char>& region,
                   double lambda = 0.5, std::vector<char>* moved = nullptr);

}  // namespace tbsp
