// StudioWindow: the ch. 8 editing half (selection, handles, gizmo, solver frames, measurements).
#include <QApplication>
#include <QMouseEvent>
#include <QRubberBand>
#include <QSlider>
#include <QVTKOpenGLNativeWidget.h>
#include <algorithm>
#include <chrono>

#include <Eigen/Geometry>
#include <vtkBoxRepresentation.h>
#include <vtkBoxWidget2.h>
#include <vtkMatrix4x4.h>
#include <vtkRenderWindowInteractor.h>
#include <vtkTransform.h>

#include "studio_window.h"
#include "tbsp/core/error.h"

namespace tbsp::studio {

bool StudioWindow::openForEditing(const QString& path, long tets, EditSolver solver) {
  try {
    status((solver == EditSolver::Tet ? "tetrahedralizing " : "opening ") + path + " ...");
    QApplication::processEvents();
    session_.open(path.toStdString(), tets, solver);
    editing_ = true;
    scenes_.clear();
    selection_.clear();
    gizmo_->SetEnabled(0);
    timeline_->setRange(0, 0);
    showEditedMesh();
    viz_->resetCamera();
    viz_->render();
    const auto& s = session_.setup();
    if (solver == EditSolver::Tet)
      status(QString("editing %1: %2 vertices, %3 tets. S: select, H: handle, G: drag, R: rigid, K: stiffness")
                 .arg(path).arg(s.surface.V.rows()).arg(s.tets.T.rows()));
    else
      status(QString("surface editing %1: %2 vertices (Laplacian). S: select, H: handle, G: drag, T: rotation field")
                 .arg(path).arg(s.surface.V.rows()));
    return true;
  } catch (const std::exception& e) {
    showError(QString::fromStdString(e.what()));
    return false;
  }
}

void StudioWindow::showEditedMesh() {
  for (const auto& id : viz_->ids()) viz_->remove(id);
  TriMesh m = session_.setup().surface;
  m.V = session_.currentSurface();
  viz_->addMesh("edit", m);
  viz_->setText("");
  updateHandleGlyphs();
}

int StudioWindow::selectRect(int x0, int y0, int x1, int y1) {
  if (!editing_) {
    showError("nothing to select: open a mesh for editing first (File > Open for editing)");
    return 0;
  }
  selection_ = viz_->selectVisiblePoints("edit", x0, y0, x1, y1);
  const Eigen::MatrixX3d X = session_.currentSurface();
  Eigen::MatrixX3d P(Eigen::Index(selection_.size()), 3);
  for (std::size_t k = 0; k < selection_.size(); ++k) P.row(Eigen::Index(k)) = X.row(selection_[k]);
  if (P.rows() > 0) viz_->addPoints("selection", P, {}, 7.0, {0.95, 0.75, 0.1});
  else viz_->remove("selection");
  viz_->render();
  status(QString("%1 vertices selected").arg(selection_.size()));
  return int(selection_.size());
}

nlohmann::json StudioWindow::selectionRegion() const { return {{"vertices", selection_}}; }

bool StudioWindow::addHandle(const nlohmann::json& region) {
  try {
    session_.addHandle(region);
    selection_.clear();
    viz_->remove("selection");
    updateHandleGlyphs();
    placeGizmo(session_.numHandles() - 1);
    requestSolve();
    status(QString("handle %1 added: drag the box (G picks another handle)").arg(session_.numHandles() - 1));
    return true;
  } catch (const std::exception& e) {
    showError(QString::fromStdString(e.what()));
    return false;
  }
}

bool StudioWindow::loadHandles(const QString& handles, const QString& rigid, const QString& stiffness) {
  try {
    session_.loadHandles(handles.toStdString(), rigid.toStdString(), stiffness.toStdString());
    updateHandleGlyphs();
    if (session_.numHandles() > 0) placeGizmo(session_.numHandles() - 1);
    requestSolve();
    status("loaded " + handles);
    return true;
  } catch (const std::exception& e) {
    showError(QString::fromStdString(e.what()));
    return false;
  }
}

bool StudioWindow::addRigid(const nlohmann::json& region) {
  try {
    session_.addRigid(region);
    requestSolve();
    return true;
  } catch (const std::exception& e) {
    showError(QString::fromStdString(e.what()));
    return false;
  }
}

bool StudioWindow::addStiffness(const nlohmann::json& region, double stiffness) {
  try {
    session_.addStiffness(region, stiffness);
    requestSolve();
    return true;
  } catch (const std::exception& e) {
    showError(QString::fromStdString(e.what()));
    return false;
  }
}

bool StudioWindow::setRotationField(bool on) {
  try {
    if (session_.solver() != EditSolver::Surface)
      throw InvalidInput("the rotation field belongs to the surface solver (File > Open for surface editing)");
    session_.setRotationField(on);
    requestSolve();
    return true;
  } catch (const std::exception& e) {
    showError(QString::fromStdString(e.what()));
    return false;
  }
}

bool StudioWindow::dragHandle(int i, const Eigen::Vector3d& t, const Eigen::Vector3d& axis, double degrees,
                              const Eigen::Vector3d& c, bool undoable) {
  try {
    session_.setHandleMotion(i, t, axis, degrees, c, undoable);
    requestSolve();
    return true;
  } catch (const std::exception& e) {
    showError(QString::fromStdString(e.what()));
    return false;
  }
}

void StudioWindow::undo() {
  if (!session_.undo()) return status("nothing to undo");
  updateHandleGlyphs();
  requestSolve();
}

void StudioWindow::redo() {
  if (!session_.redo()) return status("nothing to redo");
  updateHandleGlyphs();
  requestSolve();
}

bool StudioWindow::save(const QString& mesh, const QString& handles, const QString& rigid, const QString& stiffness,
                        int iterations, const QString& constraints) {
  try {
    status("saving: replaying the edit from the rest shape ...");
    QApplication::processEvents();
    session_.save(mesh.toStdString(), handles.toStdString(), rigid.toStdString(), stiffness.toStdString(), iterations,
                  constraints.toStdString());
    status("saved " + mesh + " and " + handles + " (replay: tbsp tetdeform --mesh " +
           QString::fromStdString(session_.path()) + " --tets " + QString::number(session_.targetTets()) + " --handles " +
           handles + ")");
    return true;
  } catch (const std::exception& e) {
    showError(QString::fromStdString(e.what()));
    return false;
  }
}

void StudioWindow::requestSolve() {
  if (session_.numHandles() == 0) {
    session_.requestIterations(1);  // back to rest
    return;
  }
  session_.requestIterations(iterations_per_change_);
}

void StudioWindow::updateHandleGlyphs() {
  if (!editing_) return;
  const Eigen::MatrixX3d X = session_.currentSurface();
  auto& vs = handle_vertices_;
  if (handle_vertices_version_ != session_.version()) {  // resolve the regions once per edit
    vs.clear();
    for (int h = 0; h < session_.numHandles(); ++h)
      for (int v : session_.handleSurfaceVertices(h)) vs.push_back(v);
    handle_vertices_version_ = session_.version();
    viz_->remove("handles");
  }
  if (vs.empty()) return;
  Eigen::MatrixX3d P(Eigen::Index(vs.size()), 3);
  for (std::size_t k = 0; k < vs.size(); ++k) P.row(Eigen::Index(k)) = X.row(vs[k]);
  if (viz_->contains("handles")) viz_->updatePositions("handles", P);
  else viz_->addPoints("handles", P, {}, 7.0, {0.85, 0.1, 0.1});
}

void StudioWindow::applyLatestFrame() {
  std::optional<EditFrame> f;
  {
    std::lock_guard<std::mutex> lk(frame_m_);
    f.swap(latest_);
    frame_queued_ = false;
  }
  if (!f || !editing_) return session_.frameShown();
  if (!f->error.empty()) {
    session_.frameShown();
    return showError(QString::fromStdString(f->error));
  }
  const auto t0 = std::chrono::steady_clock::now();
  viz_->updatePositions("edit", f->surface);
  updateHandleGlyphs();
  if (gizmo_->GetEnabled() && !mouse_dragging_) placeGizmo(gizmo_handle_, false);  // the box follows its handle
  viz_->render();
  render_ms_.push_back(std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
  ++frames_shown_;
  session_.frameShown();
  status(QString("iteration %1, E_nonrigid %2, %3 ms per iteration")
             .arg(f->iteration).arg(f->e_nonrigid, 0, 'g', 4).arg(f->seconds * 1e3, 0, 'f', 1));
}

void StudioWindow::placeGizmo(int handle, bool render) {
  if (handle < 0 || handle >= session_.numHandles()) return;
  const Eigen::MatrixX3d X = session_.currentSurface();
  const auto vs = session_.handleSurfaceVertices(handle);
  if (vs.empty()) return;
  Eigen::Vector3d lo = X.row(vs[0]).transpose(), hi = lo;
  for (int v : vs) {
    lo = lo.cwiseMin(X.row(v).transpose());
    hi = hi.cwiseMax(X.row(v).transpose());
  }
  const double pad = 0.01 * bbox_diagonal(X);
  double b[6] = {lo.x() - pad, hi.x() + pad, lo.y() - pad, hi.y() + pad, lo.z() - pad, hi.z() + pad};
  auto* rep = vtkBoxRepresentation::SafeDownCast(gizmo_->GetRepresentation());
  rep->PlaceWidget(b);
  gizmo_handle_ = handle;
  gizmo_->SetEnabled(1);
  drag_started_ = false;
  if (render) viz_->render();
}

void StudioWindow::onGizmoMoved(bool first_move) {
  if (gizmo_handle_ < 0 || gizmo_handle_ >= session_.numHandles()) return;
  if (first_move) mouse_dragging_ = true;
  if (first_move || !drag_started_) {
    drag_start_ = session_.handleMotion(gizmo_handle_);
    if (drag_start_.angle == 0) {  // rotate about the region's rest centroid
      const auto vs = session_.handleSurfaceVertices(gizmo_handle_);
      Eigen::Vector3d c = Eigen::Vector3d::Zero();
      for (int v : vs) c += session_.setup().surface.V.row(v).transpose();
      drag_start_.center = c / double(std::max<std::size_t>(1, vs.size()));
    }
    auto* rep = vtkBoxRepresentation::SafeDownCast(gizmo_->GetRepresentation());
    vtkNew<vtkTransform> t0;
    rep->GetTransform(t0);
    vtkNew<vtkMatrix4x4> inv;
    vtkMatrix4x4::Invert(t0->GetMatrix(), inv);
    for (int r = 0; r < 4; ++r)
      for (int c = 0; c < 4; ++c) gizmo_origin_(r, c) = inv->GetElement(r, c);
    drag_started_ = true;
    if (first_move) return;
  }
  auto* rep = vtkBoxRepresentation::SafeDownCast(gizmo_->GetRepresentation());
  vtkNew<vtkTransform> t;
  rep->GetTransform(t);
  Eigen::Matrix4d M;
  for (int r = 0; r < 4; ++r)
    for (int c = 0; c < 4; ++c) M(r, c) = t->GetMatrix()->GetElement(r, c);
  M = M * gizmo_origin_;  // the gizmo's motion since the drag started
  const Eigen::Matrix3d RM = M.topLeftCorner<3, 3>();
  const Eigen::Vector3d bM = M.topRightCorner<3, 1>();
  // compose with the handle's motion at drag start: x ↦ M(c + R0(x − c) + t0)
  const Eigen::Vector3d& c = drag_start_.center;
  const Eigen::Matrix3d R = RM * drag_start_.R();
  const Eigen::Vector3d tr = RM * (c + drag_start_.translation) + bM - c;
  const Eigen::AngleAxisd aa(R);
  dragHandle(gizmo_handle_, tr, aa.axis(), aa.angle() * 180.0 / M_PI, c, /*undoable=*/false);
}

bool StudioWindow::eventFilter(QObject* obj, QEvent* ev) {
  if (obj != vtk_ || !select_mode_) return QMainWindow::eventFilter(obj, ev);
  if (ev->type() == QEvent::MouseButtonPress) {
    band_origin_ = static_cast<QMouseEvent*>(ev)->pos();
    band_->setGeometry(QRect(band_origin_, QSize()));
    band_->show();
    return true;
  }
  if (ev->type() == QEvent::MouseMove && band_->isVisible()) {
    band_->setGeometry(QRect(band_origin_, static_cast<QMouseEvent*>(ev)->pos()).normalized());
    return true;
  }
  if (ev->type() == QEvent::MouseButtonRelease && band_->isVisible()) {
    band_->hide();
    const QRect r = QRect(band_origin_, static_cast<QMouseEvent*>(ev)->pos()).normalized();
    const double s = vtk_->devicePixelRatioF();
    selectRect(int(r.left() * s), int(r.top() * s), int(r.right() * s), int(r.bottom() * s));
    return true;
  }
  return QMainWindow::eventFilter(obj, ev);
}

void StudioWindow::onLatencyTick() {
  const qint64 now = latency_clock_.nsecsElapsed();
  if (last_tick_ns_ > 0 && session_.busy()) latency_ms_.push_back(std::max(0.0, double(now - last_tick_ns_) / 1e6 - 10.0));
  last_tick_ns_ = now;
}

LatencyStats StudioWindow::latency() const {
  LatencyStats s;
  std::vector<double> v = latency_ms_;
  s.samples = int(v.size());
  if (v.empty()) return s;
  std::sort(v.begin(), v.end());
  s.median_ms = v[v.size() / 2];
  s.p95_ms = v[std::min(v.size() - 1, std::size_t(0.95 * double(v.size())))];
  s.max_ms = v.back();
  return s;
}

void StudioWindow::resetMeasurements() {
  latency_ms_.clear();
  render_ms_.clear();
  frames_shown_ = 0;
}

bool StudioWindow::screenshot(const QString& png, bool whole_window) {
  try {
    if (whole_window) {
      const QImage img = grab().toImage();
      const std::string tmp = png.toStdString() + ".tmp.png";
      if (!img.save(QString::fromStdString(tmp), "PNG") || std::rename(tmp.c_str(), png.toStdString().c_str()) != 0) {
        std::remove(tmp.c_str());
        throw FileError(png.toStdString() + ": cannot write the screenshot (folder missing or not writable)");
      }
    } else {
      viz_->saveScreenshot(png.toStdString());
    }
    return true;
  } catch (const std::exception& e) {
    showError(QString::fromStdString(e.what()));
    return false;
  }
}

}  // namespace tbsp::studio
