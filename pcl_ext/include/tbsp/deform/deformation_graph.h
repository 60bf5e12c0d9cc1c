#pragma once
/// \file deformation_graph.h
/// \brief Embedded deformation graph (Sumner, Schmid, Pauly 2007) solved by Gauss-Newton with
/// rotations kept exact: the coarse, articulation-friendly deformation model of the template
/// fit's coarse stage (fitting v2), usable on its own for non-rigid registration.
///
/// Nodes are farthest-point samples of the mesh vertices; each vertex follows its k nearest
/// nodes (Dijkstra distance on the edge graph, so parts that touch in space but not on the
/// surface — two ears, a hand resting on a hip — are not bound to each other's nodes) with Sumner's weights
/// w_j = (1 − d_j / d_{k+1})², normalised:
///
///     v' = Σ_j w_j (R_j (v − g_j) + g_j + t_j)
///
/// Node j carries a rotation R_j (exactly orthonormal: updated as R ← exp([ω]×) R) and a
/// translation t_j. solve() minimises
///
///     Σ_c w_c |r_c|²  +  α Σ_(j,l) |R_j (g_l − g_j) + g_j + t_j − (g_l + t_l)|²
///
/// over {ω_j, t_j} by Gauss-Newton steps with a small Levenberg damping; r_c is a point-to-point
/// (3 rows) or point-to-plane (1 row) residual of a vertex. The second term (E_reg of Sumner,
/// with rotations instead of his E_rot penalty) makes the graph as-rigid-as-possible between
/// neighbouring nodes; its weight α sets the stiffness (large: near rigid; small: free).
/// The normal equations (6 unknowns per node) are sparse and solved by Eigen's simplicial
/// LDLᵀ (the systems have a few thousand unknowns; CHOLMOD's supernodal path gains nothing
/// there). Written by hand: no Debian library offers an embedded deformation graph.
///
/// Deterministic: node sampling and assembly order do not depend on threads.

#include <Eigen/Core>
#include <memory>
#include <vector>

namespace tbsp {

class SparseCholesky;

/// \brief A residual on one deformed vertex for DeformationGraph::solve().
struct GraphConstraint {
  int vertex = -1;                                  ///< mesh vertex (row of the build() positions)
  Eigen::Vector3d target = Eigen::Vector3d::Zero(); ///< where the deformed vertex should be (length)
  /// Zero: point-to-point (|v' − target|²). Unit vector: point-to-plane ((n · (v' − target))²).
  Eigen::Vector3d normal = Eigen::Vector3d::Zero();
  double weight = 1.0;                              ///< w_c ≥ 0
};

class DeformationGraph {
 public:
  /// \brief Samples `nodes` nodes (farthest-point, deterministic) on the vertices of (V, F) and
  /// binds every vertex to its `k` nearest nodes by Dijkstra distance (one multi-source search
  /// keeping k + 1 labels per vertex). Transforms start at the identity. A component with fewer
  /// than k + 1 nodes binds to those; one without any node to the Euclidean nearest nodes.
  /// Separate components that touch (within the median edge length) are joined by regulariser
  /// edges there (crossComponentEdges()); + O(#V log #V) when the mesh has several components.
  /// O(nodes · #V + (k + 1)(#V + #E) log #V).
  /// \param nodes number of nodes, 4 ≤ nodes ≤ #V (clamped to #V).
  /// \param k nodes per vertex, 1..8 (default 4, Sumner's choice).
  /// \throws InvalidInput for an empty mesh, bad face indices, or k out of range.
  void build(const Eigen::MatrixX3d& V, const Eigen::MatrixX3i& F, int nodes, int k = 4);

  /// \brief Deformed positions of all vertices under the current transforms. O(k #V).
  Eigen::MatrixX3d deform() const;
  /// \brief Deformed position of one vertex. O(k).
  Eigen::Vector3d deformVertex(int v) const;
  /// \brief Per vertex, the closest rotation to the weighted mean of its nodes' rotations
  /// (the local rotation the graph applies there). O(k #V).
  std::vector<Eigen::Matrix3d> vertexRotations() const;
  /// \brief The same for one vertex. O(k).
  Eigen::Matrix3d vertexRotation(int v) const;
  /// \brief A rest normal n of vertex v turned by the graph: Σ w_j R_j n, normalised (cheaper
  /// than vertexRotation(v) · n; equal where the nodes agree). O(k).
  Eigen::Vector3d turnedNormal(int v, const Eigen::Vector3d& n) const;

  /// \brief Gauss-Newton steps on the constraints with stiffness α (> 0). Returns the largest
  /// move of a vertex bound to a constrained node in the last step (length), so callers can
  /// stop when it is small. Unconstrained parts follow through the regulariser. O(steps ·
  /// (#constraints k² + solve)).
  /// \throws InvalidInput before build(), for a constraint naming a vertex out of range, a
  /// negative or non-finite weight, or α ≤ 0.
  double solve(const std::vector<GraphConstraint>& constraints, double alpha, int steps = 1);

  /// \brief Back to the identity transforms.
  void reset();
  /// \brief Transforms that carry the rest shape onto the positions X (#V rows, the build()
  /// vertices in order): per node, the rigid transform (Kabsch) that best maps its bound
  /// vertices' rest positions onto X, weighted by their binding weights. deform() then
  /// reproduces X up to what rigid pieces blended smoothly can express: a start pose for
  /// solve() that keeps the rest shape as the regulariser's reference. O(k #V).
  /// \throws InvalidInput before build() or when X has the wrong number of rows or is not finite.
  void fitTransformsTo(const Eigen::MatrixX3d& X);

  int nodeCount() const { return int(g_.rows()); }
  /// Node positions g_j in the rest pose (rows), their mesh vertices, the node edges (j < l).
  const Eigen::MatrixX3d& nodePositions() const { return g_; }
  const std::vector<int>& nodeVertices() const { return node_vertex_; }
  const std::vector<std::pair<int, int>>& edges() const { return edges_; }
  /// How many of edges() join nodes of separate surface components that touch (build(): a
  /// vertex within the mesh's median edge length of another component's vertex links the two
  /// vertices' nearest nodes), so that a body modelled as parts (limbs pushed into or set
  /// against a torso) moves as one; 0 for a connected mesh and for parts farther apart.
  std::size_t crossComponentEdges() const { return cross_edges_; }
  /// Current node rotations and translations.
  const std::vector<Eigen::Matrix3d>& rotations() const { return R_; }
  const std::vector<Eigen::Vector3d>& translations() const { return t_; }

 private:
  void link_components(const Eigen::MatrixX3d& V, const Eigen::MatrixX3i& F, std::vector<std::pair<int, int>>& e);
  Eigen::MatrixX3d V_;                 // rest positions
  Eigen::MatrixX3d g_;                 // node rest positions
  std::vector<int> node_vertex_;
  int k_ = 4;
  Eigen::MatrixXi bind_;               // #V by k node indices
  Eigen::MatrixXd weight_;             // #V by k weights (rows sum to 1)
  std::vector<std::pair<int, int>> edges_;
  std::size_t cross_edges_ = 0;        // edges between separate surface components
  std::vector<std::vector<int>> nb_;   // per node: itself and its edge neighbours, ascending
  std::vector<std::size_t> start_;     // block offsets of nb_ (CSR)
  std::vector<Eigen::Matrix3d> R_;
  std::vector<Eigen::Vector3d> t_;
  // the factorization, kept between solves (one symbolic analysis per graph); a copied graph
  // starts with its own, empty one
  struct Factor {
    Factor();
    Factor(const Factor&);
    Factor& operator=(const Factor&);
    Factor(Factor&&) noexcept;
    Factor& operator=(Factor&&) noexcept;
    ~Factor();
    std::unique_ptr<SparseCholesky> chol;
    struct Pattern;                    // the system matrix, its values filled in place (solve())
    std::unique_ptr<Pattern> pattern;
  } factor_;
};

}  // namespace tbsp
