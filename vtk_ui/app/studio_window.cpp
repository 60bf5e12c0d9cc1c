#include "studio_window.h"

#include <QAction>
#include <QApplication>
#include <QComboBox>
#include <QFileDialog>
#include <QHBoxLayout>
#include <QInputDialog>
#include <QLabel>
#include <QMenuBar>
#include <QMessageBox>
#include <QMouseEvent>
#include <QPushButton>
#include <QRubberBand>
#include <QSlider>
#include <QSplitter>
#include <QStatusBar>
#include <QToolBar>
#include <QVBoxLayout>
#include <QVTKOpenGLNativeWidget.h>
#include <algorithm>
#include <chrono>
#include <iostream>

#include <Eigen/Geometry>
#include <vtkBoxRepresentation.h>
#include <vtkBoxWidget2.h>
#include <vtkCallbackCommand.h>
#include <vtkGenericOpenGLRenderWindow.h>
#include <vtkInteractorStyleTrackballCamera.h>
#include <vtkMatrix4x4.h>
#include <vtkProperty.h>
#include <vtkRenderWindowInteractor.h>
#include <vtkRenderer.h>
#include <vtkTransform.h>

#include "tbsp/core/error.h"

namespace tbsp::studio {

StudioWindow::StudioWindow(int view_width, int view_height, bool scripted) : scripted_(scripted) {
  setWindowTitle("tbsp-studio");
  vtk_ = new QVTKOpenGLNativeWidget(this);
  vtk_->setRenderWindow(window_.Get());
  viz_ = std::make_unique<Visualizer>(window_.Get(), Eigen::Vector3d(1, 1, 1));
  vtkNew<vtkInteractorStyleTrackballCamera> style;
  vtk_->interactor()->SetInteractorStyle(style);
  if (scripted) vtk_->setFixedSize(view_width, view_height);
  else vtk_->setMinimumSize(320, 240);
  vtk_->installEventFilter(this);
  band_ = new QRubberBand(QRubberBand::Rectangle, vtk_);

  auto* side = new QWidget(this);
  side->setObjectName("side");
  auto* side_layout = new QVBoxLayout(side);
  auto* cameras = new QComboBox(side);
  cameras->setObjectName("cameras");
  image_ = new QLabel(side);
  image_->setMinimumWidth(200);
  image_->setAlignment(Qt::AlignCenter);
  image_->setText("camera images of a studio appear here");
  side_layout->addWidget(cameras);
  side_layout->addWidget(image_, 1);
  connect(cameras, QOverload<int>::of(&QComboBox::currentIndexChanged), this, [this](int i) {
    image_camera_ = std::max(0, i);
    updateImagePanel();
  });

  auto* split = new QSplitter(Qt::Horizontal, this);
  split->addWidget(vtk_);
  split->addWidget(side);
  split->setStretchFactor(0, 4);
  split->setStretchFactor(1, 1);
  side->setVisible(false);  // shown for studios

  auto* bottom = new QWidget(this);
  auto* bl = new QHBoxLayout(bottom);
  auto* play = new QPushButton("Play", bottom);
  timeline_ = new QSlider(Qt::Horizontal, bottom);
  timeline_->setObjectName("timeline");
  timeline_->setRange(0, 0);
  bl->addWidget(play);
  bl->addWidget(timeline_, 1);
  connect(play, &QPushButton::clicked, this, &StudioWindow::onPlay);
  connect(timeline_, &QSlider::valueChanged, this, [this](int v) { setFrame(v); });
  connect(&play_timer_, &QTimer::timeout, this, [this] {
    if (numFrames() <= 1) return play_timer_.stop();
    timeline_->setValue((frame_ + 1) % numFrames());
  });

  auto* central = new QWidget(this);
  auto* cl = new QVBoxLayout(central);
  cl->addWidget(split, 1);
  cl->addWidget(bottom);
  setCentralWidget(central);
  buildMenus();

  // the box gizmo that drags the selected handle (translation + rotation, no scaling)
  auto* rep = vtkBoxRepresentation::New();
  rep->SetPlaceFactor(1.15);
  gizmo_->SetRepresentation(rep);
  rep->Delete();
  gizmo_->SetInteractor(vtk_->interactor());
  gizmo_->SetScalingEnabled(false);
  gizmo_->SetMoveFacesEnabled(false);
  vtkNew<vtkCallbackCommand> cb;
  cb->SetClientData(this);
  cb->SetCallback([](vtkObject*, unsigned long ev, void* client, void*) {
    auto* w = static_cast<StudioWindow*>(client);
    if (ev == vtkCommand::EndInteractionEvent) w->mouse_dragging_ = false;
    else w->onGizmoMoved(ev == vtkCommand::StartInteractionEvent);
  });
  gizmo_->AddObserver(vtkCommand::StartInteractionEvent, cb);
  gizmo_->AddObserver(vtkCommand::InteractionEvent, cb);
  gizmo_->AddObserver(vtkCommand::EndInteractionEvent, cb);
  auto* box = vtkBoxRepresentation::SafeDownCast(gizmo_->GetRepresentation());
  box->GetOutlineProperty()->SetColor(0.15, 0.15, 0.5);
  box->GetOutlineProperty()->SetLineWidth(2);
  box->GetHandleProperty()->SetColor(0.2, 0.4, 0.9);
  box->SetHandleSize(4);

  session_.setFrameCallback([this](const EditFrame& f) {
    std::lock_guard<std::mutex> lk(frame_m_);
    latest_ = f;
    if (!frame_queued_) {
      frame_queued_ = true;
      QMetaObject::invokeMethod(this, "applyLatestFrame", Qt::QueuedConnection);
    }
  });
  latency_timer_.setTimerType(Qt::PreciseTimer);
  latency_timer_.setInterval(10);
  connect(&latency_timer_, &QTimer::timeout, this, &StudioWindow::onLatencyTick);
  latency_clock_.start();
  latency_timer_.start();
  resize(view_width + 260, view_height + 120);
  status("open a mesh, cloud, fit report, tet mesh, studio or mesh folder (File menu)");
}

StudioWindow::~StudioWindow() {
  session_.setFrameCallback(nullptr);
  session_.waitIdle();
  gizmo_->SetEnabled(0);
}

void StudioWindow::buildMenus() {
  auto* file = menuBar()->addMenu("&File");
  file->addAction("&Open...", this, &StudioWindow::onOpen, QKeySequence::Open);
  file->addAction("&Add to the view...", this, [this] {
    const QString p = QFileDialog::getOpenFileName(this, "Add", QString(),
        "tbsp files (*.ply *.obj *.off *.vtk *.stl *.pcd *.mesh *.json *.yaml *.yml);;All files (*)");
    if (!p.isEmpty()) openFile(p, true);
  }, QKeySequence("Ctrl+Shift+O"));
  file->addAction("Open for &editing...", this, &StudioWindow::onOpenForEditing, QKeySequence("Ctrl+E"));
  file->addAction("Open for s&urface editing (Laplacian)...", this, [this] {
    const QString p = QFileDialog::getOpenFileName(this, "Open for surface editing", QString(), "meshes (*.ply *.obj *.off *.vtk *.stl)");
    if (!p.isEmpty()) openForEditing(p, 0, EditSolver::Surface);
  });
  file->addAction("&Load handles...", this, [this] {
    const QString p = QFileDialog::getOpenFileName(this, "Load a tbsp tetdeform handles file", QString(), "JSON (*.json)");
    if (!p.isEmpty()) loadHandles(p);
  });
  file->addAction("&Save edit...", this, &StudioWindow::onSave, QKeySequence::Save);
  file->addAction("Screens&hot...", this, [this] {
    const QString p = QFileDialog::getSaveFileName(this, "Screenshot", "screenshot.png", "PNG (*.png)");
    if (!p.isEmpty()) screenshot(p, false);
  });
  file->addSeparator();
  file->addAction("&Quit", qApp, &QApplication::quit, QKeySequence::Quit);
  auto* edit = menuBar()->addMenu("&Edit");
  edit->addAction("&Undo", this, &StudioWindow::undo, QKeySequence::Undo);
  edit->addAction("&Redo", this, &StudioWindow::redo, QKeySequence::Redo);
  edit->addSeparator();
  auto* sel = edit->addAction("&Select (rubber band)");
  sel->setCheckable(true);
  sel->setShortcut(QKeySequence("S"));
  connect(sel, &QAction::toggled, this, [this](bool on) {
    select_mode_ = on;
    status(on ? "select: drag a rectangle over the mesh" : "navigate: rotate / pan / zoom");
  });
  edit->addAction("&Handle from selection", this, [this] { addHandle(selectionRegion()); }, QKeySequence("H"));
  edit->addAction("Rigid region from selection", this, [this] { addRigid(selectionRegion()); }, QKeySequence("R"));
  edit->addAction("Stiffness of selection...", this, [this] {
    bool ok = false;
    const double s = QInputDialog::getDouble(this, "Stiffness", "stiffness (> 0; 1 = default, 0.05 bends easily)", 0.1, 1e-4, 1e4, 4, &ok);
    if (ok) addStiffness(selectionRegion(), s);
  }, QKeySequence("K"));
  edit->addAction("Drag handle...", this, [this] {
    const int n = session_.numHandles();
    if (n == 0) return showError("no handle yet: select vertices (S) and make a handle (H)");
    bool ok = false;
    const int h = QInputDialog::getInt(this, "Drag handle", "handle", n - 1, 0, n - 1, 1, &ok);
    if (ok) placeGizmo(h);
  }, QKeySequence("G"));
  auto* rf = edit->addAction("Rotation field (surface editing)");
  rf->setCheckable(true);
  rf->setShortcut(QKeySequence("T"));
  connect(rf, &QAction::toggled, this, [this](bool on) { setRotationField(on); });
  auto* view = menuBar()->addMenu("&View");
  view->addAction("&Reset camera", this, [this] {
    viz_->resetCamera();
    viz_->render();
  }, QKeySequence("F"));
}

void StudioWindow::status(const QString& s) { statusBar()->showMessage(s); }

void StudioWindow::showError(const QString& message) {
  ++errors_;
  std::cerr << "tbsp-studio: error: " << message.toStdString() << std::endl;
  if (!scripted_) QMessageBox::warning(this, "tbsp-studio", message);
  status("error: " + message);
}

const Scene* StudioWindow::studioScene() const {
  for (const auto& sc : scenes_)
    if (sc.kind == FileKind::Studio) return &sc;
  return nullptr;
}

int StudioWindow::numFrames() const {
  int n = 1;
  for (const auto& sc : scenes_) n = std::max(n, sc.numFrames());
  return n;
}

void StudioWindow::removeScene(const Scene& sc) {
  for (const auto& id : viz_->ids())
    if (id.compare(0, sc.prefix.size(), sc.prefix) == 0) viz_->remove(id);
}

bool StudioWindow::openFile(const QString& path, bool add) {
  session_.waitIdle();
  gizmo_->SetEnabled(0);
  if (!add || editing_) {  // replace everything
    for (const auto& id : viz_->ids()) viz_->remove(id);
    scenes_.clear();
    editing_ = false;
  }
  // each file's objects carry its own prefix, so a failed file is removed without touching the others
  const std::string prefix = "s" + std::to_string(next_scene_++) + ":";
  Scene sc;
  sc.prefix = prefix;
  try {
    sc = load_scene(*viz_, path.toStdString(), prefix);
  } catch (const std::exception& e) {
    removeScene(sc);
    showError(QString::fromStdString(e.what()));
    viz_->render();
    return false;
  }
  scenes_.push_back(std::move(sc));
  const Scene& added = scenes_.back();
  frame_ = 0;
  timeline_->blockSignals(true);
  timeline_->setRange(0, std::max(0, numFrames() - 1));
  timeline_->setValue(0);
  timeline_->blockSignals(false);
  const Scene* st = studioScene();
  auto* cameras = findChild<QComboBox*>("cameras");
  cameras->blockSignals(true);
  cameras->clear();
  if (st)
    for (const auto& c : st->studio.cameras) cameras->addItem(QString::fromStdString(c.camera.name()));
  cameras->blockSignals(false);
  image_camera_ = 0;
  for (const auto& s2 : scenes_)
    if (s2.numFrames() > 1 || s2.kind == FileKind::Studio) {
      try {
        show_frame(*viz_, s2, 0);
      } catch (const std::exception& e) {
        showError(QString::fromStdString(e.what()));
      }
    }
  findChild<QWidget*>("side")->setVisible(st != nullptr);
  updateImagePanel();
  viz_->setText(added.kind == FileKind::FitReport ? "fit error heatmap" : "");
  viz_->resetCamera();
  viz_->render();
  status(QString::fromStdString(added.summary));
  return true;
}

void StudioWindow::setFrame(int index) {
  if (index < 0 || index >= numFrames()) return;
  frame_ = index;
  if (timeline_->value() != index) {
    timeline_->blockSignals(true);
    timeline_->setValue(index);
    timeline_->blockSignals(false);
  }
  for (const auto& sc : scenes_) {
    if (index >= sc.numFrames()) continue;
    try {
      show_frame(*viz_, sc, index);
    } catch (const std::exception& e) {
      showError(QString::fromStdString(e.what()));
    }
  }
  updateImagePanel();
  viz_->render();
  status(QString("frame %1 / %2").arg(index + 1).arg(numFrames()));
}

void StudioWindow::updateImagePanel() {
  const Scene* st = studioScene();
  if (!st || st->studio.cameras.empty() || frame_ >= st->numFrames()) return;
  try {
    int w = 0, h = 0;
    const auto rgb = studio_image_rgb(st->studio, image_camera_, frame_, &w, &h);
    if (rgb.empty()) return image_->setText("this camera has no images");
    QImage img(rgb.data(), w, h, w * 3, QImage::Format_RGB888);
    image_->setPixmap(QPixmap::fromImage(img.copy()).scaled(image_->size(), Qt::KeepAspectRatio, Qt::SmoothTransformation));
  } catch (const std::exception& e) {
    image_->setText(QString::fromStdString(e.what()));
  }
}

void StudioWindow::onPlay() {
  if (play_timer_.isActive()) return play_timer_.stop();
  const double fps = studioScene() ? studioScene()->studio.frame_rate : 25.0;
  play_timer_.start(int(1000.0 / std::max(1.0, fps)));
}

void StudioWindow::onOpen() {
  const QString p = QFileDialog::getOpenFileName(this, "Open", QString(),
      "tbsp files (*.ply *.obj *.off *.vtk *.stl *.pcd *.mesh *.json *.yaml *.yml);;All files (*)");
  if (!p.isEmpty()) openFile(p);
}

void StudioWindow::onOpenForEditing() {
  const QString p = QFileDialog::getOpenFileName(this, "Open for editing", QString(),
                                                 "closed meshes (*.ply *.obj *.off *.vtk *.stl *.mesh)");
  if (p.isEmpty()) return;
  bool ok = false;
  const int tets = QInputDialog::getInt(this, "Tetrahedra", "target tet count (0 = full resolution)", 5000, 0, 10000000, 1000, &ok);
  if (ok) openForEditing(p, tets);
}

void StudioWindow::onSave() {
  const QString mesh = QFileDialog::getSaveFileName(this, "Save deformed mesh", "edited.ply", "meshes (*.ply *.obj *.off *.vtk)");
  if (mesh.isEmpty()) return;
  const QString base = mesh.left(mesh.lastIndexOf('.'));
  save(mesh, base + "_handles.json", base + "_rigid.json", base + "_stiffness.json", std::max(50, session_.iterations()),
       base + "_constraints.json");
}

}  // namespace tbsp::studio
