#pragma once
/// \file rotation_field.h
/// \brief Dense rotation field from sparse constraints (thesis §3.2.3, Fig. 3.7).
///
/// 1. Constraint skeleton graph: nodes at the constrained vertices, edges of the minimum
///    spanning tree over approximate geodesic (Dijkstra) distances, plus each node's 3 nearest
///    neighbours (ConstraintGraph).
/// 2. Per node, the transform T of eq. 3.13 mapping the rest edge vectors to the target edge
///    vectors, and its rotation by polar decomposition (eq. 3.15, closest_rotation()).
/// 3. Quaternions made hemisphere-consistent along the tree, harmonically interpolated
///    component-wise (eq. 3.11), normalised and turned into one rotation per vertex.

#include <Eigen/Core>
#include <optional>
#include <utility>
#include <vector>

#include "tbsp/core/progress.h"
#include "tbsp/mesh/cotan_laplacian.h"
#include "tbsp/mesh/harmonic.h"

namespace tbsp {

/// \brief The constraint skeleton graph of Fig. 3.7(b).
struct ConstraintGraph {
  std::vector<int> nodes;                        ///< mesh vertex of each node (distinct)
  std::vector<std::pair<int, int>> edges;        ///< node index pairs (a < b), unique
  std::vector<std::vector<int>> neighbours;      ///< per node, adjacent nodes
  std::vector<int> tree_parent;                  ///< MST parent per node (−1 for roots)
  std::vector<int> tree_order;                   ///< nodes in BFS order over the MST forest
  Eigen::MatrixXd geodesic;                      ///< node by node Dijkstra distances

  /// \brief Builds the graph: MST (Prim) on geodesic distances plus `extra_neighbours`
  /// nearest nodes each. Nodes on different components are left unconnected.
  /// O(k (#V + #E) log #V + k²) for k nodes.
  /// \throws InvalidInput for duplicate or out-of-range node vertices.
  static ConstraintGraph build(const Eigen::MatrixX3d& V, const Eigen::MatrixX3i& F, const std::vector<int>& nodes,
                               int extra_neighbours = 3, const ProgressCallback& progress = {});
};

/// \brief Per-node rotations from rest positions P and target positions Q (k by 3, one row
/// per node), eq. 3.13 + 3.15: T_i is the least-squares map of the edge vectors (p_i − p_j) to
/// (q_i − q_j) over the node's neighbours. When the edge vectors do not span 3D (fewer than 3
/// neighbours or coplanar) T_i is replaced by the Procrustes cross-covariance Σ e'eᵀ, whose
/// closest rotation is the best rigid fit. Nodes without neighbours get the identity.
std::vector<Eigen::Matrix3d> node_rotations(const ConstraintGraph& graph, const Eigen::MatrixX3d& P,
                                            const Eigen::MatrixX3d& Q);

/// \brief Interpolates sparse rotations to all vertices (quaternion harmonic interpolation).
///
/// Prefactor once per mesh and node set with compute(); then interpolate() for each new set
/// of node rotations is two back-substitutions.
class RotationField {
public:
  /// \param V, F the mesh (#V by 3, #F by 3).
  /// \param nodes the vertices whose rotations interpolate() is given.
  /// \param tree_parent, tree_order hemisphere-consistency order over the nodes (from
  /// ConstraintGraph; pass empty vectors to keep the signs given).
  /// \param weights Laplacian weights of the harmonic system (cotangent by default).
  void compute(const Eigen::MatrixX3d& V, const Eigen::MatrixX3i& F, const std::vector<int>& nodes,
               std::vector<int> tree_parent = {}, std::vector<int> tree_order = {},
               LaplacianWeights weights = LaplacianWeights::Cotangent);
  /// \brief The same with the mesh's matrix C given (cotangent_matrix(V, F), or
  /// uniform_graph_laplacian for uniform weights; see HarmonicInterpolator::compute): same
  /// result, without assembling it again.
  void compute(const Eigen::SparseMatrix<double>& C, const Eigen::MatrixX3i& F, const std::vector<int>& nodes,
               std::vector<int> tree_parent = {}, std::vector<int> tree_order = {});
  /// \brief One rotation per node (in the order of `nodes`) → one rotation per vertex.
  /// Vertices where the interpolated quaternion vanishes
  /// (opposite rotations cancelling, practically impossible after the hemisphere step) get the
  /// identity; the result is never NaN.
  std::vector<Eigen::Matrix3d> interpolate(const std::vector<Eigen::Matrix3d>& node_rotations) const;

private:
  HarmonicInterpolator harmonic_;
  std::vector<int> parent_, order_;
};

}  // namespace tbsp
