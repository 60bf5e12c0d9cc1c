#pragma once
/// \file laplacian_deformer.h
/// \brief Linear differential (Laplacian) mesh deformation, thesis §3.1-3.2.3.
///
/// Minimises (eq. 3.6 / 3.12)
///   E(x) = Σ_i ‖(L̂ x)_i − λ R_i δ_i‖² + Σ_j w_j² ‖c_j(x) − q_j‖²
/// where L̂ = Ā·L is the Laplacian of eq. 3.2 scaled by the mean vertex area Ā (so that L̂ x has
/// units of length and the constraint weights mean the same on a 1 mm and a 1 km mesh),
/// δ = L̂ V the rest differential coordinates, R_i an optional per-vertex rotation (the rotation
/// field of §3.2.3), λ a global scale (§5.2) and c_j the soft constraints. Hard constraints
/// are eliminated from the system (their vertices are fixed exactly).
///
/// Constraint kinds (§3.2.1): 3D position (eq. 3.9), line = two planes (eq. 3.10), plane.
/// Each is attached to a vertex or to a surface point (face + barycentric coordinates).
/// When only position constraints exist, x, y and z share one factorization of the
/// #free by #free normal matrix; line/plane constraints couple the coordinates and switch to
/// one 3·#free system.
///
/// Prefactor once, solve many: the factorization is cached and redone only when the matrix
/// changes (mesh, weights, constraint set, hard set, line/plane orientations). Moving targets
/// (setPositionTarget, or a line/plane moved parallel to itself), changing the rotations or
/// the scale only rebuild the right-hand side: one back-substitution per solve.
///
/// \code
/// tbsp::LaplacianDeformer d;
/// d.setMesh(mesh);
/// int h = d.addPositionConstraint(tbsp::SurfacePoint::atVertex(12), {0.1, 0.2, 0.3});
/// d.addHardConstraint(40, mesh.V.row(40));
/// Eigen::MatrixX3d V1 = d.deform();        // factorizes
/// d.setPositionTarget(h, {0.2, 0.2, 0.3});
/// Eigen::MatrixX3d V2 = d.deform();        // re-uses the factorization
/// \endcode
///
/// Accepts: triangle meshes with finite coordinates and valid indices, open or closed, any
/// genus, with degenerate faces (clamped Laplacian), isolated vertices (kept where they
/// are), non-manifold edges (the Laplacian sums over all incident faces; a warning is logged).
/// Rejects (InvalidInput): duplicate faces, constraints on missing
/// vertices/faces, bad barycentric coordinates, non-finite targets, weights outside (0, 1e100], and
/// constraint sets that leave a component free to translate (the system would be singular).

#include <Eigen/Core>
#include <Eigen/SparseCore>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "tbsp/core/progress.h"
#include "tbsp/mesh/cotan_laplacian.h"
#include "tbsp/mesh/tri_mesh.h"

namespace tbsp {

struct ConstraintGraph;

/// \brief A point on the mesh: a vertex, or a face with barycentric coordinates.
struct SurfacePoint {
  int vertex = -1;                          ///< >= 0: this vertex
  int face = -1;                            ///< >= 0 (and vertex < 0): a point on this face
  Eigen::Vector3d bary = Eigen::Vector3d::Zero();  ///< weights of F(face,0..2), sum 1

  static SurfacePoint atVertex(int v) { SurfacePoint p; p.vertex = v; return p; }
  static SurfacePoint onFace(int f, const Eigen::Vector3d& b) { SurfacePoint p; p.face = f; p.bary = b; return p; }
  bool isVertex() const { return vertex >= 0; }
};

enum class ConstraintType { Position, Line, Plane };

/// \brief One deformation constraint. For Position `target` is the 3D goal; for Line the line
/// passes through `target` with direction `axis`; for Plane the plane passes through `target`
/// with normal `axis`.
struct DeformConstraint {
  SurfacePoint at;
  ConstraintType type = ConstraintType::Position;
  Eigen::Vector3d target = Eigen::Vector3d::Zero();
  Eigen::Vector3d axis = Eigen::Vector3d::UnitZ();
  double weight = 1.0;           ///< w_j of eq. 3.8 (soft constraints only), in (0, 1e100]
  bool hard = false;             ///< exact; only for Position on a vertex
  std::optional<Eigen::Matrix3d> rotation;  ///< user-given local rotation (rotation field node)
  /// Handle group (default −1: none). Position constraints with the same group ≥ 0 form one
  /// handle region that moves as a whole (a `vertices` + `transform` group of the constraints
  /// file): with the rotation field (§3.2.3) the region is *one* node of the constraint graph,
  /// whatever its size, and all its vertices get one rotation — the given one, or else the best
  /// rigid fit (Procrustes) of the region's rest positions to its targets. Ungrouped constraints
  /// are one node per vertex, as before.
  int group = -1;
};

/// \brief Residual of one constraint after a solve (distance to target point / line / plane).
struct ConstraintResidual {
  int id = 0;
  ConstraintType type = ConstraintType::Position;
  bool hard = false;
  double distance = 0;
};

/// \brief What the last deform() did: sizes, timings (seconds) and residuals.
struct DeformReport {
  Eigen::Index vertices = 0, free_vertices = 0, fixed_isolated = 0;
  int position_constraints = 0, line_constraints = 0, plane_constraints = 0, hard_constraints = 0;
  bool coupled_xyz = false;      ///< line/plane constraints forced one 3n system
  bool refactorized = false;     ///< this solve had to factorize (false: back-substitution only)
  bool rotation_field = false;
  int rotation_nodes = 0;
  double scale = 1.0;
  std::string backend;
  double t_laplacian = 0, t_graph = 0, t_factorize = 0, t_rotations = 0, t_solve = 0;
  double max_residual = 0, rms_residual = 0;
  std::vector<ConstraintResidual> residuals;
};

/// Options of LaplacianDeformer (docs/conventions.md). Each also has its own setter below.
struct LaplacianDeformerOptions {
  /// Edge weights of L̂ (eq. 3.2). Default cotangent. Changing them recomputes L̂.
  LaplacianWeights weights = LaplacianWeights::Cotangent;
  /// The automatic rotation field of §3.2.3 (eq. 3.12). Default off.
  bool rotation_field = false;
  /// Global scale λ of the differential coordinates (§5.2); > 0, finite. Default 1.
  double scale = 1.0;
  /// Anchor ε ≥ 0 towards the rest positions (see setAnchor). Default 0 = off.
  double anchor = 0.0;
  /// Sliver guard ≥ 0 of the cotangent Laplacian (see setSliverGuard). Default 0 = off.
  double sliver_guard = 0.0;
  /// True when every field is in range; else false and, if given, `why` says which and why.
  bool isValid(std::string* why = nullptr) const;
};

class LaplacianDeformer {
public:
  using Ptr = std::shared_ptr<LaplacianDeformer>;
  using ConstPtr = std::shared_ptr<const LaplacianDeformer>;
  using Options = LaplacianDeformerOptions;

  LaplacianDeformer();
  ~LaplacianDeformer();
  LaplacianDeformer(const LaplacianDeformer&) = delete;
  LaplacianDeformer& operator=(const LaplacianDeformer&) = delete;

  /// \brief Sets the rest mesh (computes L̂ and δ). Clears nothing else, but every cached
  /// factorization is dropped. \throws InvalidInput (see class doc for what is rejected).
  void setMesh(const TriMesh& mesh);
  const TriMesh& mesh() const;

  /// \brief All options at once. \throws InvalidInput when !o.isValid() (nothing clamped).
  void setOptions(const LaplacianDeformerOptions& o);
  LaplacianDeformerOptions options() const;

  /// Laplacian weights (default cotangent). Changing them refactorizes.
  void setLaplacianWeights(LaplacianWeights w);
  LaplacianWeights laplacianWeights() const { return weights_; }

  /// \brief Adds a soft position constraint (eq. 3.9). \returns its id.
  int addPositionConstraint(const SurfacePoint& at, const Eigen::Vector3d& target, double weight = 1.0);
  /// \brief Adds a hard constraint: vertex `v` ends exactly at `target`. \returns its id.
  int addHardConstraint(int v, const Eigen::Vector3d& target);
  /// \brief Soft line constraint through `point` along `direction` (eq. 3.10). \returns its id.
  int addLineConstraint(const SurfacePoint& at, const Eigen::Vector3d& point, const Eigen::Vector3d& direction,
                        double weight = 1.0);
  /// \brief Soft plane constraint through `point` with `normal`. \returns its id.
  int addPlaneConstraint(const SurfacePoint& at, const Eigen::Vector3d& point, const Eigen::Vector3d& normal,
                         double weight = 1.0);
  /// \brief Adds any constraint (validated as the specific adders do). \returns its id.
  int addConstraint(const DeformConstraint& c);
  /// Removes all constraints.
  void clearConstraints();
  const std::vector<DeformConstraint>& constraints() const { return constraints_; }

  /// \brief Moves a position constraint's target (soft or hard). Cheap: no refactorization.
  void setPositionTarget(int id, const Eigen::Vector3d& target);
  /// \brief Moves a line (point, direction) or plane (point, normal). Cheap if `axis` is
  /// parallel to the current one; otherwise the matrix changes and is refactorized.
  void setLineOrPlane(int id, const Eigen::Vector3d& point, const Eigen::Vector3d& axis);
  /// \brief Changes a soft constraint's weight (refactorizes on the next solve).
  void setWeight(int id, double weight);
  /// \brief Sets or clears the user rotation of a constraint (used by the rotation field).
  void setConstraintRotation(int id, const std::optional<Eigen::Matrix3d>& R);

  /// \brief Enables the automatic rotation field of §3.2.3 (default off): at each deform() the
  /// constraint skeleton is built from the position constraints (cached while the constraint
  /// set is unchanged), node rotations are estimated from their targets (user rotations take
  /// precedence) and interpolated, and δ is rotated (eq. 3.12). Needs at least 3 position
  /// constraints not all on a line, or user rotations.
  void setUseRotationField(bool on);
  bool useRotationField() const { return use_rotation_field_; }
  /// \brief Explicit dense rotations, one per vertex (disables the automatic field); pass an
  /// empty vector to clear.
  void setRotations(const std::vector<Eigen::Matrix3d>& R);
  /// The per-vertex rotations used by the last deform() (empty if none).
  const std::vector<Eigen::Matrix3d>& lastRotations() const { return last_rotations_; }
  /// \brief The constraint skeleton of the automatic rotation field (nodes in ascending vertex
  /// order, their Dijkstra distance matrix on the rest mesh), or nullptr before the first
  /// deform() with the field on / after the constraint set changed. Lets callers reuse the
  /// geodesics (e.g. the §5.2 scale estimate) instead of computing them again.
  const ConstraintGraph* rotationGraph() const;

  /// \brief Global scale λ applied to the differential coordinates (§5.2). Default 1.
  void setScale(double lambda);
  double scale() const { return scale_; }

  /// \brief Adds ε·median(diag)·‖x − V_rest‖² to the energy (default ε = 0: off). A tiny ε
  /// (1e-9) keeps the system positive definite on folded/degenerate meshes whose Laplacian has
  /// extra near-null vectors, at the cost of a small bias towards the rest positions. With ε > 0
  /// a component the constraints leave free to translate keeps its rest position along the free
  /// directions (no "free to translate" error).
  void setAnchor(double epsilon);

  /// \brief Sliver guard of the cotangent Laplacian (laplacian(): vertex areas floored at
  /// guard · (mean edge length)²; default 0 = off). Takes effect at the next setMesh().
  /// \throws InvalidInput when negative or not finite.
  void setSliverGuard(double guard);

  /// \brief Takes over the symbolic analysis of `other`'s last factorization (see
  /// SparseCholesky::copyAnalysis): when this deformer's next system has the same sparsity
  /// pattern — the same mesh connectivity and the same hard-constrained vertices, e.g. a second
  /// deformer of one template with another rest shape — only its numeric factorization runs.
  /// The result is identical to analysing anew; any other pattern is analysed as usual.
  /// Keeps this deformer's mesh, constraints and options; its cached factorization is dropped.
  void copySolverAnalysis(const LaplacianDeformer& other);

  /// Progress callback (stages: laplacian, geodesics, factorize, rotations, solve).
  void setProgressCallback(ProgressCallback cb) { progress_ = std::move(cb); }

  /// \brief Solves and returns the deformed #V by 3 positions. Factorizes only if needed.
  /// \throws InvalidInput when no mesh is set or the constraints leave a component
  /// under-determined (the message names the component and a vertex in it);
  /// NumericalFailure if the solver fails.
  Eigen::MatrixX3d deform();

  const DeformReport& report() const { return report_; }

  /// Rest differential coordinates δ = L̂ V (#V by 3), for inspection.
  const Eigen::MatrixX3d& differentialCoordinates() const { return delta_; }
  /// The scaled Laplacian L̂ (#V by #V).
  const Eigen::SparseMatrix<double>& laplacianMatrix() const { return L_; }

private:
  struct Cache;
  void requireMesh(const char* who) const;
  void checkConstraint(const DeformConstraint& c, const char* who) const;
  void invalidateMatrix();
  void buildSystem();
  /// Builds the rotation field's skeleton and interpolation system if the field is in use and
  /// not built yet (nothing else). Independent of buildSystem(): deform() runs the two
  /// concurrently when both are needed.
  void buildRotationGraph(bool with_progress);
  void checkRank() const;
  Eigen::MatrixX3d rotatedDelta();
  Eigen::Vector3d evaluate(const SurfacePoint& p, const Eigen::MatrixX3d& X) const;

  TriMesh mesh_;
  bool has_mesh_ = false;
  LaplacianWeights weights_ = LaplacianWeights::Cotangent;
  Eigen::SparseMatrix<double> L_;
  Eigen::MatrixX3d delta_;
  std::vector<DeformConstraint> constraints_;
  std::vector<char> hard_at_;  ///< per vertex: it has a hard constraint (grown on demand)
  bool use_rotation_field_ = false;
  std::vector<Eigen::Matrix3d> user_rotations_, last_rotations_;
  double scale_ = 1.0;
  double anchor_ = 0.0;
  double sliver_guard_ = 0.0;
  ProgressCallback progress_;
  DeformReport report_;
  std::unique_ptr<Cache> cache_;
};

}  // namespace tbsp
