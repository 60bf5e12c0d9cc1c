#pragma once
/// \file studio_window.h
/// \brief The main window of tbsp-studio: a VTK view (QVTKOpenGLNativeWidget) with a camera
/// image beside it and a timeline below; viewer for everything scene.h opens; ch. 8 editing
/// through an EditSession (rubber-band selection → handles / rigid regions / stiffness, a box
/// gizmo to drag a handle, the TetDeformer iterating in a worker thread and the view updated
/// after each iteration), undo/redo, save. Every action is also reachable from a script
/// (script_runner.h), so all of it can be replayed without a person.

#include <QElapsedTimer>
#include <QMainWindow>
#include <QTimer>
#include <memory>
#include <mutex>
#include <optional>
#include <vector>

#include <vtkNew.h>

#include "edit_session.h"
#include "scene.h"
#include "tbsp/vtk/visualizer.h"

class QLabel;
class QSlider;
class QRubberBand;
class QVTKOpenGLNativeWidget;
class vtkGenericOpenGLRenderWindow;
class vtkBoxWidget2;

namespace tbsp::studio {

/// Event-loop responsiveness while the solver runs: how late a 10 ms UI timer fired.
struct LatencyStats {
  int samples = 0;
  double median_ms = 0, p95_ms = 0, max_ms = 0;
};

class StudioWindow : public QMainWindow {
  Q_OBJECT
public:
  /// `scripted`: errors go to stderr (no dialogs) and are counted (errors()).
  StudioWindow(int view_width, int view_height, bool scripted);
  ~StudioWindow() override;

  // --- viewer --------------------------------------------------------------------------
  /// Opens a file into the view, replacing what was there, or with `add` beside it (a studio
  /// and the mesh sequence tracked from it play on one timeline). On failure shows the message,
  /// removes what the file had added, keeps the rest and returns false.
  bool openFile(const QString& path, bool add = false);
  /// Timeline position (0-based frame index of a sequence or studio).
  void setFrame(int index);
  int numFrames() const;
  Visualizer& viz() { return *viz_; }

  // --- editing (ch. 8) -------------------------------------------------------------------
  /// Opens a closed surface (or .mesh) for volumetric editing with about `tets` tets (0: full).
  bool openForEditing(const QString& path, long tets, EditSolver solver = EditSolver::Tet);
  /// Surface solver: the rotation field on / off (undoable).
  bool setRotationField(bool on);
  EditSession& session() { return session_; }
  /// Rubber-band selection of the edited surface's visible vertices in a rectangle of the 3D
  /// view (pixels, origin top-left). \returns how many were selected.
  int selectRect(int x0, int y0, int x1, int y1);
  const std::vector<int>& selection() const { return selection_; }
  /// The current selection as a region of the handles format ({"vertices": [...]}).
  nlohmann::json selectionRegion() const;
  /// Adds a handle / rigid region / stiffness for `region`; on failure shows the message and
  /// returns false (the edit is unchanged).
  bool addHandle(const nlohmann::json& region);
  /// Loads a `tbsp tetdeform` handles file (+ optional rigid / stiffness files) into the edit.
  bool loadHandles(const QString& handles, const QString& rigid = QString(), const QString& stiffness = QString());
  bool addRigid(const nlohmann::json& region);
  bool addStiffness(const nlohmann::json& region, double stiffness);
  /// Moves handle `i` (motion relative to the rest shape) and lets the solver iterate.
  bool dragHandle(int i, const Eigen::Vector3d& t, const Eigen::Vector3d& axis, double degrees, const Eigen::Vector3d& c,
                  bool undoable = true);
  void undo();
  void redo();
  /// Iterations the solver runs after each change (default 200; it stops early when converged).
  void setIterationsPerChange(int n) { iterations_per_change_ = n; }
  /// Writes the replayed edit (see EditSession::save); false + message on failure.
  bool save(const QString& mesh, const QString& handles, const QString& rigid, const QString& stiffness, int iterations,
            const QString& constraints = QString());

  // --- measurements ----------------------------------------------------------------------
  LatencyStats latency() const;
  int framesShown() const { return frames_shown_; }
  std::vector<double> renderMs() const { return render_ms_; }
  void resetMeasurements();
  int errors() const { return errors_; }
  /// Shows an error (dialog, or stderr when scripted) and counts it.
  void showError(const QString& message);
  /// The 3D view only (Visualizer::saveScreenshot) or, when `whole_window`, the whole app.
  bool screenshot(const QString& png, bool whole_window);

protected:
  bool eventFilter(QObject* obj, QEvent* ev) override;

private slots:
  void applyLatestFrame();
  void onLatencyTick();
  void onOpen();
  void onOpenForEditing();
  void onSave();
  void onPlay();

private:
  void buildMenus();
  void showEditedMesh();
  void updateHandleGlyphs();
  void placeGizmo(int handle, bool render = true);
  void onGizmoMoved(bool first_move);
  void requestSolve();
  void updateImagePanel();
  void status(const QString& s);
  const Scene* studioScene() const;    // the first studio among the open scenes
  void removeScene(const Scene& sc);

  QVTKOpenGLNativeWidget* vtk_ = nullptr;
  vtkNew<vtkGenericOpenGLRenderWindow> window_;
  std::unique_ptr<Visualizer> viz_;
  QLabel* image_ = nullptr;
  QSlider* timeline_ = nullptr;
  QTimer play_timer_;
  QRubberBand* band_ = nullptr;
  QPoint band_origin_;
  bool select_mode_ = false;
  std::vector<Scene> scenes_;          // what is open (each with its id prefix)
  int next_scene_ = 0;
  int frame_ = 0;
  int image_camera_ = 0;

  EditSession session_;
  bool editing_ = false;
  std::vector<int> selection_;
  int iterations_per_change_ = 200;
  std::mutex frame_m_;
  std::optional<EditFrame> latest_;
  bool frame_queued_ = false;
  vtkNew<vtkBoxWidget2> gizmo_;
  int gizmo_handle_ = -1;
  RigidMotion drag_start_;
  Eigen::Matrix4d gizmo_origin_ = Eigen::Matrix4d::Identity();  // inverse of the gizmo's transform at drag start
  bool drag_started_ = false;
  bool mouse_dragging_ = false;                    // between the gizmo's start and end interaction
  std::vector<int> handle_vertices_;               // surface vertices of all handles ...
  long handle_vertices_version_ = -1;              // ... for this version of the documents

  QTimer latency_timer_;
  QElapsedTimer latency_clock_;
  qint64 last_tick_ns_ = 0;
  std::vector<double> latency_ms_, render_ms_;
  int frames_shown_ = 0;
  int errors_ = 0;
  bool scripted_ = false;
};

}  // namespace tbsp::studio
