// tbsp-studio: the VTK visualizer and interactive shape editor (docs/studio.md).
#include <QApplication>
#include <QSurfaceFormat>
#include <QTimer>
#include <QVTKOpenGLNativeWidget.h>
#include <vtkOpenGLRenderWindow.h>
#include <CLI/CLI.hpp>
#include <cstdlib>
#include <iostream>

#include "script_runner.h"
#include "studio_window.h"

int main(int argc, char** argv) {
  CLI::App cli{"tbsp-studio: view meshes, clouds, tet meshes, fit reports (error heatmaps), studios and mesh sequences; "
               "edit shapes with the tetrahedral solver (thesis ch. 8). Docs: docs/studio.md"};
  std::vector<std::string> files;
  std::string screenshot, script, edit, size = "800x600";
  long tets = 5000;
  bool whole = false;
  cli.add_option("files", files, "files to open, shown together: .ply .obj .off .vtk .stl .pcd .mesh, a fit / tetdeform / texture "
                                 "report .json, studio.yaml, a folder of meshes (a sequence)");
  cli.add_option("--edit", edit, "open this closed surface (or .mesh) for editing");
  cli.add_option("--tets", tets, "target tet count of --edit (0: tetrahedralize at full resolution; default 5000)")
      ->check(CLI::NonNegativeNumber);
  cli.add_option("--screenshot", screenshot, "render the opened files, write this PNG and exit");
  cli.add_flag("--whole-window", whole, "--screenshot grabs the whole app window, not only the 3D view");
  cli.add_option("--script", script, "replay the actions of this JSON file, then exit (docs/studio.md)");
  cli.add_option("--size", size, "size of the 3D view in scripted / screenshot runs, WxH (default 800x600)");
  try {
    cli.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return cli.exit(e) == 0 ? 0 : 2;
  }
  int W = 800, H = 600;
  if (std::sscanf(size.c_str(), "%dx%d", &W, &H) != 2 || W < 64 || H < 64 || W > 8192 || H > 8192) {
    std::cerr << "tbsp-studio: error: --size " << size << ": expected WxH, e.g. 800x600 (64 to 8192 pixels)\n";
    return 2;
  }
  // check the script before anything opens: a malformed file is an error of its own
  nlohmann::json checked;
  if (!script.empty()) {
    try {
      checked = tbsp::studio::load_script(script);
    } catch (const std::exception& e) {
      std::cerr << "tbsp-studio: error: " << e.what() << "\n";
      return 2;
    }
  }
  // No multisampling: VTK's default asks for 8 samples, which costs a software-OpenGL view (Xvfb,
  // virtual machines) 2-3x its frame time and makes screenshots differ between drivers.
  vtkOpenGLRenderWindow::SetGlobalMaximumNumberOfMultiSamples(0);
  const char* display = std::getenv("DISPLAY");
  if (display == nullptr || *display == 0) {
    std::cerr << "tbsp-studio: error: no X display (DISPLAY is not set). tbsp-studio draws with OpenGL through X: run it "
                 "on a desktop, or headless as `xvfb-run -a tbsp-studio ...` (Debian: apt-get install xvfb)\n";
    return 2;
  }
  QSurfaceFormat::setDefaultFormat(QVTKOpenGLNativeWidget::defaultFormat());
  QApplication app(argc, argv);
  const bool scripted = !screenshot.empty() || !script.empty();
  tbsp::studio::StudioWindow w(W, H, scripted);
  w.show();
  for (std::size_t i = 0; i < files.size(); ++i) w.openFile(QString::fromStdString(files[i]), /*add=*/i > 0);
  if (!edit.empty()) w.openForEditing(QString::fromStdString(edit), tets);
  std::unique_ptr<tbsp::studio::ScriptRunner> runner;
  if (!script.empty()) {
    runner = std::make_unique<tbsp::studio::ScriptRunner>(w, script);
    runner->start();
  } else if (!screenshot.empty()) {
    QTimer::singleShot(0, &w, [&] {
      QApplication::processEvents();
      const bool ok = w.screenshot(QString::fromStdString(screenshot), whole);
      QApplication::exit(ok && w.errors() == 0 ? 0 : 2);
    });
  }
  return app.exec();
}
