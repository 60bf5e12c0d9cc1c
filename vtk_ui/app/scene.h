#pragma once
/// \file scene.h
/// \brief What tbsp-studio can open, loaded into a tbsp::Visualizer (no Qt here, so the
/// offscreen paths and tests share it): meshes, point clouds, tet meshes, `tbsp fit` reports
/// (error heatmap), studio datasets (cameras with their images) and mesh sequences (a folder
/// of meshes with one connectivity, played frame by frame: only the current frame is in memory).

#include <string>
#include <vector>

#include <Eigen/Core>

#include "tbsp/io/studio.h"
#include "tbsp/vtk/visualizer.h"

namespace tbsp::studio {

enum class FileKind { Mesh, Cloud, TetMesh, FitReport, TetReport, TextureReport, Studio, MeshSequence };

/// What was opened (and what the timeline plays).
struct Scene {
  FileKind kind = FileKind::Mesh;
  std::string path;
  std::string summary;                  ///< one line for the status bar
  std::string prefix;                   ///< prepended to its object ids (several scenes in one view)
  std::vector<std::string> frames;      ///< MeshSequence: mesh files in frame order
  Studio studio;                        ///< Studio
  int numFrames() const;                ///< 1 for single files
  /// FitReport: scan → fit distance of each scan point, % of the fit's bbox diagonal.
  Eigen::VectorXd heat;
  double heat_max = 0, heat_median = 0;
  double heat_top = 0;                  ///< FitReport: value at the top of the colour bar (3 point spacings)
};

/// The kind of file `path` is (by extension; JSON by content; a folder is a mesh sequence).
/// \throws FileError naming the file when it does not exist or is of no kind we open.
FileKind classify(const std::string& path);

/// \brief Loads `path` into `viz` (objects PREFIX + "mesh", "cloud", "tets", "fit", "scan", "rest",
/// "camera:NAME"), frame 0 for sequences. \throws FileError / InvalidInput naming the file, the
/// item and the fix.
Scene load_scene(Visualizer& viz, const std::string& path, const std::string& prefix = "");

/// Shows frame `index` (0-based) of a sequence or studio: the mesh of that frame, the camera
/// images of that frame on the image planes. \throws FileError naming the frame's file.
void show_frame(Visualizer& viz, const Scene& scene, int index);

/// The 8-bit RGB image of studio camera `camera` at frame index `index` (empty when the
/// studio has no images for it), with its size.
std::vector<unsigned char> studio_image_rgb(const Studio& studio, int camera, int index, int* width, int* height);

}  // namespace tbsp::studio
