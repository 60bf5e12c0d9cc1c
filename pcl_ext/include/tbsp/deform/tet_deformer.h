#pragma once
/// \file tet_deformer.h
/// \brief Iterative as-rigid-as-possible deformation of tetrahedral meshes, thesis ch. 7
/// (§7.1–7.2.3).
///
/// Differential representation (§7.1): per tetrahedron j the 3×4 gradient operator G_j of its
/// linear shape functions, L = Gᵀ D S G (eq. 7.3 / 7.9; D = tet volumes, S = per-tet stiffness)
/// and δ = Gᵀ D S g (eq. 7.4 / 7.10) with g_j = G_j V_j the rest gradients. Rotating the
/// gradients, g_j ↦ g_j R_jᵀ, changes δ but not L, so L is factorized once and every
/// iteration is a back-substitution plus local work:
///
///   (I)   linear solve L_ff x_f = δ_f − L_fc x_c (constrained vertices eliminated);
///   (II)  rotation extraction: T_j = G_j x_j (eq. 7.6), polar decomposition T = R S (eq. 7.7,
///         Newton iteration eq. 7.8 warm-started from the previous R_j; a reflection or a
///         collapsed tet falls back to the SVD's closest proper rotation, so det R_j = +1);
///   (III) rotation interpolation (optional): when region handles turn, their rotation
///         increments since the previous iteration (relative rotations, at most
///         max_handle_step) are interpolated harmonically as unit quaternions over the
///         vertices — with L and the eliminated vertices of step (I), so the same factorization
///         serves; the interpolation is linear in the handles' quaternions, so one harmonic
///         weight per region handle is precomputed and an iteration only blends — other handles'
///         vertices carry no increment — and each tet's R_j is turned by the normalized mean of
///         its vertices' increments.
///         Being relative and incremental, handles that turn by more than 180° in total are
///         fine. Done before the solve so that it already sees the handles' new orientation;
///   (IV)  rigid regions: every tet of a region gets the volume-weighted mean rotation;
///   (V)   differential-coordinate update δ = Gᵀ D S (g Rᵀ).
/// E_nonrigid = Σ_j ‖S_j − I‖_F (eq. 7.5) is measured in step (II) of every iteration.
///
/// Handles: single vertices (position), vertex regions (a rigid motion: position and
/// orientation), and points that are not vertices (§7.2.3): a point inside the mesh splits its
/// enclosing tetrahedron into four; a point outside is tied to the nearest boundary triangles by
/// "virtual" tetrahedra. Handle targets are reached progressively: a region rotating by θ in
/// total is applied over ⌈θ / max_handle_step⌉ iterations (default 45° per iteration), the way a
/// user drags a handle interactively — this is what lets a 360° twist come out as a twist.
///
/// Cost: setup O(#T), one sparse Cholesky of the #free × #free matrix; per iteration one
/// back-substitution with 3 right-hand sides and O(#T) local work (OpenMP over tets).
///
/// \code
/// tbsp::TetDeformer d;
/// d.setMesh(tets);
/// d.addRegionHandle(fixed_vertices, {});                                  // stays put
/// d.addRegionHandle(moving_vertices, tbsp::RigidMotion::rotation({0,0,1}, M_PI/2, c));
/// Eigen::MatrixX3d X = d.deform(50);      // iterates until converged or 50 iterations
/// \endcode
///
/// Rejects (InvalidInput): invalid tet meshes (see require_valid_tet_mesh), no handles, handles
/// on missing vertices, a vertex in two handles, stiffness ≤ 0 or of the wrong size, point
/// handles that cannot be attached, and handle sets that leave a connected component free.

#include <Eigen/Core>
#include <memory>
#include <string>
#include <vector>

#include "tbsp/core/progress.h"
#include "tbsp/mesh/tet_mesh.h"

namespace tbsp {

/// \brief x ↦ center + Rot(axis, angle)·(x − center) + translation. The angle (radians) may
/// exceed π: a 2π twist is a full turn, reached progressively (see TetDeformer).
struct RigidMotion {
  Eigen::Vector3d axis = Eigen::Vector3d::UnitZ();
  double angle = 0.0;
  Eigen::Vector3d center = Eigen::Vector3d::Zero();
  Eigen::Vector3d translation = Eigen::Vector3d::Zero();

  static RigidMotion identity() { return {}; }
  static RigidMotion translate(const Eigen::Vector3d& t) { RigidMotion m; m.translation = t; return m; }
  static RigidMotion rotation(const Eigen::Vector3d& axis, double angle, const Eigen::Vector3d& center,
                              const Eigen::Vector3d& t = Eigen::Vector3d::Zero()) {
    RigidMotion m; m.axis = axis; m.angle = angle; m.center = center; m.translation = t; return m;
  }
  Eigen::Matrix3d R() const;
  Eigen::Vector3d apply(const Eigen::Vector3d& x) const { return center + R() * (x - center) + translation; }
};

/// Options of TetDeformer (docs/conventions.md: one options struct per class, validated).
struct TetDeformerOptions {
  /// step (III), incremental rotation interpolation over the tet dual graph (twists > 180°).
  /// Default true.
  bool rotation_interpolation = true;
  /// Largest handle rotation applied per iteration, degrees; range (0, 180). Default 45.
  double max_handle_step_deg = 45.0;
  /// Convergence: stop when no vertex moved more than tolerance × bbox diagonal in an iteration
  /// (and all handles have reached their targets). Range > 0. Default 1e-7.
  double tolerance = 1e-7;
  /// True when every field is in range; else false and, if given, `why` says which and why.
  bool isValid(std::string* why = nullptr) const;
};

/// \brief Sizes, timings (seconds; per-step times are summed over the iterations) and the
/// energy history of the last run.
struct TetDeformReport {
  Eigen::Index vertices = 0, tets = 0;           ///< working mesh (after refinement)
  Eigen::Index added_vertices = 0, virtual_tets = 0, split_tets = 0;
  Eigen::Index constrained_vertices = 0, rotation_handle_tets = 0;
  int vertex_handles = 0, region_handles = 0, point_handles = 0, rigid_regions = 0;
  std::string backend;
  double t_setup = 0, t_factorize = 0, t_factorize_rotint = 0;
  double t_def = 0, t_rotext = 0, t_rotint = 0, t_rigid = 0, t_difupd = 0;
  int iterations = 0;                            ///< iterations since the last reset()
  bool converged = false;
  std::vector<double> e_nonrigid;                ///< eq. 7.5 after each iteration's solve
  /// Σ_j D_j S_j ‖F_j − R_j‖²_F after each solve: the energy the local/global iteration
  /// minimizes, non-increasing once the handles have reached their targets (E_nonrigid is its
  /// unweighted, unsquared relative and decreases with it, but is not strictly monotone).
  std::vector<double> e_arap;
  std::vector<double> max_move;                  ///< largest vertex move per iteration / bbox diagonal
  double volume_ratio = 1.0;                     ///< deformed / rest volume (non-virtual tets)
  double max_handle_residual = 0;                ///< distance of constrained vertices to their final targets
};

class TetDeformer {
public:
  TetDeformer();
  ~TetDeformer();
  TetDeformer(const TetDeformer&) = delete;
  TetDeformer& operator=(const TetDeformer&) = delete;

  /// \brief Sets the rest mesh (validated; negatively oriented tets are re-oriented). Clears
  /// handles, rigid regions and stiffness. \throws InvalidInput.
  void setMesh(const TetMesh& mesh);
  /// The working mesh: the input plus vertices/tets added by point handles.
  const TetMesh& mesh() const { return mesh_; }
  /// Number of vertices of the mesh given to setMesh (added vertices come after them).
  Eigen::Index numInputVertices() const { return n_input_vertices_; }
  /// Number of tets of the mesh given to setMesh.
  Eigen::Index numInputTets() const { return n_input_tets_; }

  using Ptr = std::shared_ptr<TetDeformer>;
  using ConstPtr = std::shared_ptr<const TetDeformer>;
  using Options = TetDeformerOptions;

  /// \throws InvalidInput when !o.isValid() (nothing is clamped silently).
  void setOptions(const TetDeformerOptions& o);
  const TetDeformerOptions& options() const { return options_; }

  /// \brief Per-tet stiffness s_j > 0 (eq. 7.9–7.10), one per input tet; tets created by
  /// refinement inherit their parent's. Refactorizes.
  void setStiffness(const Eigen::VectorXd& s);

  /// \brief Vertex v is moved to `target` (its orientation is free). \returns the handle id.
  int addVertexHandle(int v, const Eigen::Vector3d& target);
  /// \brief The vertices follow `motion` (position + orientation). \returns the handle id.
  int addRegionHandle(const std::vector<int>& vertices, const RigidMotion& motion);
  /// \brief §7.2.3: a handle at a point that is not a vertex. Inside the mesh the enclosing
  /// tetrahedron is split at the point; outside, the point is connected to the nearest boundary
  /// triangles by virtual tetrahedra. Adds a vertex. \returns the handle id.
  int addPointHandle(const Eigen::Vector3d& rest_point, const Eigen::Vector3d& target);
  /// Moves a vertex or point handle (no refactorization; ramps like any target change).
  void setHandleTarget(int id, const Eigen::Vector3d& target);
  /// Changes a region handle's motion (no refactorization).
  void setRegionMotion(int id, const RigidMotion& motion);
  /// \brief Marks input tets as one rigid region (step IV). Refactorizes nothing.
  void addRigidRegion(const std::vector<int>& tets);
  /// Removes all handles and rigid regions (the refined mesh is kept).
  void clearHandles();
  int numHandles() const { return int(handles_.size()); }

  /// \brief Back to the rest state: positions = rest, rotations = identity, handles at their
  /// starting point of the ramp, history cleared.
  void reset();
  /// \brief Overrides the current per-tet rotations (size #tets of the working mesh); the next
  /// iteration starts from δ built with them. Used to test robustness (§8.3).
  void setRotations(const std::vector<Eigen::Matrix3d>& R);
  const std::vector<Eigen::Matrix3d>& rotations() const { return R_; }

  /// \brief One iteration (I)–(V). \returns E_nonrigid of this iteration's solve.
  double iterate();
  /// \brief Iterates until converged (see TetDeformerOptions::tolerance) or max_iterations.
  /// \returns the positions of the input vertices.
  /// \throws NumericalFailure when the result overflowed (non-finite positions, E_nonrigid or
  /// volume: handle targets far beyond the mesh's size).
  Eigen::MatrixX3d deform(int max_iterations = 100);

  /// Current positions of all working-mesh vertices.
  const Eigen::MatrixX3d& positions() const { return X_; }
  /// \brief Linear response of working-mesh `vertices` to the vertex and point handles, with the
  /// rotations held fixed: entry (i, h) is how far vertex i moves (the same along x, y and z) when
  /// handle h's target moves by one unit. Exact for the linear solve of the next iterate(), so a
  /// tracker can fit handle targets to constraints on any vertex by linear least squares
  /// (performance capture, §9.2). Region-handle columns are zero. Factorizes if needed; one solve
  /// with #handles right-hand sides. \throws InvalidInput for a vertex out of range.
  Eigen::MatrixXd handleResponse(const std::vector<int>& vertices);
  /// Current positions of the input vertices only.
  Eigen::MatrixX3d inputPositions() const { return X_.topRows(n_input_vertices_); }
  /// E_nonrigid (eq. 7.5) of arbitrary positions of the working mesh.
  double nonrigidEnergy(const Eigen::MatrixX3d& X) const;

  void setProgressCallback(ProgressCallback cb) { progress_ = std::move(cb); }
  const TetDeformReport& report() const { return report_; }

private:
  struct Handle {
    enum Kind { Vertex, Region, Point } kind = Vertex;
    std::vector<int> vertices;
    Eigen::Vector3d target = Eigen::Vector3d::Zero(), from_target = Eigen::Vector3d::Zero();
    RigidMotion motion, from_motion;
  };
  struct Solver;
  void requireMesh(const char* who) const;
  void checkVertex(int v, const char* who) const;
  void prepare();
  void buildOperators();
  void buildRotationInterpolation();
  void updateConstrained();
  int rampSteps() const;
  void freezeRamp();  // every handle restarts its ramp from where it is now
  Eigen::Matrix3d handleRotation(const Handle& h, double s) const;
  Eigen::Vector3d handlePosition(const Handle& h, int vertex_slot, double s) const;
  void splitTet(int t, const Eigen::Vector3d& p, int new_vertex);

  TetMesh mesh_;
  Eigen::MatrixX3d rest_;  // == mesh_.V
  Eigen::Index n_input_vertices_ = 0, n_input_tets_ = 0;
  std::vector<int> parent_;   // working tet -> input tet (-1 virtual)
  std::vector<char> virtual_;
  Eigen::VectorXd stiffness_input_;
  TetDeformerOptions options_;
  std::vector<Handle> handles_;
  std::vector<std::vector<int>> rigid_regions_;  // input tet ids
  double diag_ = 1.0;

  // operators
  bool operators_dirty_ = true, constrained_dirty_ = true;
  Eigen::Matrix<double, Eigen::Dynamic, 12, Eigen::RowMajor> G_;   // per tet 3x4 row-major
  Eigen::Matrix<double, Eigen::Dynamic, 9, Eigen::RowMajor> g_;    // rest gradients per tet (row-major 3x3)
  Eigen::VectorXd weight_;                         // vol * stiffness
  Eigen::VectorXd rest_volume_;
  std::vector<int> free_index_, constrained_index_;  // per vertex: position in free / constrained lists or -1
  std::vector<int> free_vertices_, constrained_vertices_;
  std::vector<int> constraint_handle_, constraint_slot_;  // per constrained vertex
  std::unique_ptr<Solver> solver_;
  Eigen::MatrixX3d rhs_c_;   // L_fc X_c
  Eigen::MatrixX3d Xc_;
  // rotation interpolation
  bool rotint_active_ = false;
  std::vector<int> rot_groups_;               // region handles, in weight-column order
  Eigen::MatrixXd rot_tet_weights_;           // #tets x (#regions + 1): harmonic weights (last: identity)

  // state
  Eigen::MatrixX3d X_;
  Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor> Xrow_;
  Eigen::VectorXd tet_e2_;  // per-tet squared ARAP residual of the last rotation extraction
  std::vector<Eigen::Matrix3d> R_;
  int ramp_iteration_ = 0, ramp_steps_ = 1;
  TetDeformReport report_;
  ProgressCallback progress_;
};

}  // namespace tbsp
