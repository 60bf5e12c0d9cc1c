#pragma once
/// \file edit_session.h
/// \brief The interactive shape-editing session of tbsp-studio (thesis ch. 8), without any UI:
/// a surface (or tet mesh) is tetrahedralized once, the user's edit is kept as the very
/// documents `tbsp tetdeform` reads (handles, rigid regions, stiffness: docs/tetdeform_json.md),
/// and a worker thread iterates the TetDeformer in the background, handing every iteration's
/// surface to a callback.
///
/// - Dragging a handle (setHandleMotion) only changes its rigid motion: the deformer keeps
///   iterating from where it is (warm start, no refactorization).
/// - Adding or removing a handle, a rigid region or stiffness changes the linear system: the
///   deformer is rebuilt and iterates from the rest shape again, so the view converges to the
///   same answer `tbsp tetdeform` gives for the current documents.
/// - A handle added to an already deformed shape gets the rigid motion that best maps its rest
///   vertices onto where they are now (least squares), so it holds them in place.
/// - save() replays the documents from the rest shape on a fresh deformer — exactly the
///   steps of `tbsp tetdeform --mesh IN --tets N --handles H.json [--rigid R.json]
///   [--stiffness S.json] --iterations K` — so a saved edit is reproducible bit for bit.
/// - Every edit is undoable (documents are snapshotted; undo/redo restore them).
///
/// Thread safety: all public functions are for one (UI) thread; the callback runs on the
/// worker thread and must hand the frame over (e.g. a queued Qt call).

#include <atomic>
#include <condition_variable>
#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include <nlohmann/json.hpp>

#include "tbsp/deform/laplacian_deformer.h"
#include "tbsp/deform/tet_deformer.h"
#include "tbsp/plugins/tet_job_run.h"

namespace tbsp::studio {

/// One iteration's result, produced on the worker thread.
struct EditFrame {
  Eigen::MatrixX3d surface;   ///< positions of the input surface's vertices
  int iteration = 0;          ///< iterations since the last rebuild
  double e_nonrigid = 0;      ///< eq. 7.5 of this iteration
  double seconds = 0;         ///< time of this iteration (rebuild included when there was one)
  bool rebuilt = false;       ///< the system was rebuilt (handles / rigid / stiffness changed)
  std::string error;          ///< non-empty: the deformer refused the documents (e.g. a free component)
};

/// Which deformer the session drives.
enum class EditSolver {
  Tet,      ///< TetDeformer (ch. 7): volumetric, iterative; rigid regions and stiffness
  Surface   ///< LaplacianDeformer (ch. 3): the surface alone, one solve per change; rotation field on/off
};

class EditSession {
public:
  using FrameCallback = std::function<void(const EditFrame&)>;
  EditSession();
  ~EditSession();  ///< stops and joins the worker
  EditSession(const EditSession&) = delete;
  EditSession& operator=(const EditSession&) = delete;

  /// \brief Opens a closed triangle mesh (tetrahedralized, QEM-decimated to about
  /// `target_tets` tets; 0 = full resolution) or a `.mesh` tet mesh. Clears the documents and
  /// the undo history. Blocking. \throws InvalidInput / FileError naming the file and the reason
  /// (open, non-manifold or self-intersecting surfaces cannot be edited volumetrically).
  void open(const std::string& path, long target_tets, EditSolver solver = EditSolver::Tet);
  EditSolver solver() const { return solver_; }
  bool isOpen() const { return bool(setup_); }
  const std::string& path() const { return path_; }
  long targetTets() const { return target_tets_; }
  /// The surface (rest positions) and its tet mesh.
  const TetJobSetup& setup() const;

  /// \brief Adds a region handle: `region` is {"vertices": [...]}, {"sphere": {...}} or
  /// {"box": {...}} (docs/tetdeform_json.md). Validated by the same parser as the CLI's; a
  /// region that selects no tet vertex is refused. \returns the handle's index.
  /// \throws InvalidInput naming the item.
  int addHandle(const nlohmann::json& region);
  /// Sets handle `i`'s rigid motion relative to the rest shape: x ↦ c + R(axis, degrees)(x − c) + t.
  /// `undoable` false replaces the motion without a new undo step (the moves of one mouse drag).
  void setHandleMotion(int i, const Eigen::Vector3d& translate, const Eigen::Vector3d& axis = Eigen::Vector3d::UnitZ(),
                       double degrees = 0, const Eigen::Vector3d& center = Eigen::Vector3d::Zero(), bool undoable = true);
  /// Handle `i`'s current motion.
  RigidMotion handleMotion(int i) const;
  void removeHandle(int i);
  int numHandles() const;
  /// The input-surface vertices of handle `i` (for drawing it).
  std::vector<int> handleSurfaceVertices(int i) const;
  /// Adds a rigid region (tets that share one rotation). \throws InvalidInput when it holds no tet.
  void addRigid(const nlohmann::json& region);
  /// Stiffness `s` > 0 for the tets of `region` (later regions override earlier ones).
  void addStiffness(const nlohmann::json& region, double s);
  void setRotationInterpolation(bool on);
  /// Surface solver: the rotation field of §3.2.3 (handle rotations interpolated over the
  /// surface) on or off. Default off. Undoable.
  void setRotationField(bool on);
  bool rotationField() const { return docs_.rotation_field; }
  /// Surface solver: the documents as a `tbsp deform --constraints` file (each handle a hard
  /// vertex group with its 4x4 transform; docs/constraints_json.md).
  nlohmann::json constraintsDoc() const;

  /// Bumped by every change of the documents (edits, undo, redo, open): lets a view cache what
  /// it derives from them.
  long version() const { return version_; }

  /// \brief Replaces the edit by a handles file of `tbsp tetdeform` (and, when the paths are
  /// non-empty, its rigid-region and stiffness files), validated against the open mesh by the
  /// CLI's parser. Undoable. \throws FileError naming the file and the item
  /// ("H.json: handles[0].vertices[1]: vertex 99999 does not exist ..."); nothing changes then.
  void loadHandles(const std::string& handles_path, const std::string& rigid_path = "", const std::string& stiffness_path = "");

  bool undo();  ///< \returns false when there is nothing to undo
  bool redo();
  const nlohmann::json& handlesDoc() const { return docs_.handles; }
  const nlohmann::json& rigidDoc() const { return docs_.rigid; }
  const nlohmann::json& stiffnessDoc() const { return docs_.stiffness; }

  /// Callback for every iteration's frame (worker thread).
  void setFrameCallback(FrameCallback cb);
  /// \brief Lockstep (default on): after handing a frame to the callback the worker waits
  /// (at most 250 ms) until frameShown() says the view drew it, so the solver never takes the
  /// CPU the view needs to draw (software OpenGL on a 2-core machine) and every iteration is
  /// seen. Off: the worker iterates flat out and views skip frames.
  void setLockstep(bool on) { lockstep_ = on; }
  /// The UI drew the last frame (see setLockstep).
  void frameShown();
  /// The worker runs `n` more iterations (warm) after applying the current documents.
  void requestIterations(int n);
  /// Blocks until the worker has run every requested iteration.
  void waitIdle();
  bool busy() const;
  /// Iterations run since the last rebuild.
  int iterations() const { return iterations_.load(); }
  /// The surface as the worker last left it.
  Eigen::MatrixX3d currentSurface() const;

  /// \brief The documents replayed from the rest shape: fresh TetDeformer, `iterations`
  /// iterations (or until converged) — what `tbsp tetdeform` computes. Blocking.
  TriMesh replay(int iterations) const;
  /// \brief Writes replay(iterations) to `mesh_path` and the documents to the JSON paths
  /// (`rigid_path` / `stiffness_path` only when non-empty; the handles file records
  /// `iterations`). All files are written atomically. \throws FileError.
  /// Surface solver: `constraints_path` (when non-empty) gets constraintsDoc(), and the mesh is
  /// what `tbsp deform --mesh IN --constraints C.json` computes.
  void save(const std::string& mesh_path, const std::string& handles_path, const std::string& rigid_path,
            const std::string& stiffness_path, int iterations, const std::string& constraints_path = "") const;

private:
  struct Docs {
    nlohmann::json handles, rigid, stiffness;
    bool rotation_field = false;  // surface solver
  };
  nlohmann::json constraintsDocOf(const Docs& d) const;
  TetJob parseDocs(const Docs& d) const;  // the CLI's parser, file names "handles" / "rigid" / "stiffness"
  void edit(const std::function<void(Docs&)>& change, bool undoable = true);  // validates, pushes undo
  bool step(std::vector<Docs>& from, std::vector<Docs>& to);  // undo / redo: from's last state becomes current
  void workerLoop();
  void stopWorker();

  std::unique_ptr<TetJobSetup> setup_;
  std::string path_;
  long target_tets_ = 0;
  EditSolver solver_ = EditSolver::Tet;
  long setup_serial_ = 0;            // bumped by open(): the worker never reuses a deformer of another mesh
  Docs docs_;
  std::vector<Docs> undo_, redo_;

  // worker
  mutable std::mutex m_;
  std::condition_variable cv_, idle_cv_;
  std::thread worker_;
  bool stop_ = false, working_ = false;
  int pending_ = 0;
  long version_ = 0;                 // bumped by every edit
  Docs worker_docs_;                 // copy the worker applies
  Eigen::MatrixX3d surface_;         // last surface
  FrameCallback callback_;
  std::mutex callback_m_;            // held while the callback runs: setFrameCallback waits for it
  std::atomic<int> iterations_{0};
  std::atomic<bool> lockstep_{true};
  long frames_out_ = 0, frames_shown_ = 0;
  std::condition_variable shown_cv_;
};

/// Kabsch: the rigid motion (about the centroid of `rest`) that best maps `rest` onto `now`.
RigidMotion best_rigid_motion(const Eigen::MatrixX3d& rest, const Eigen::MatrixX3d& now);

}  // namespace tbsp::studio
