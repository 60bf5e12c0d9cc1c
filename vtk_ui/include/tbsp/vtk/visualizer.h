#pragma once
/// \file visualizer.h
/// \brief tbsp::Visualizer: a small VTK 9 scene for tbsp's shapes, usable from any PCL program the
/// way `pcl::visualization::PCLVisualizer` is: triangle meshes, tetrahedral meshes, point clouds
/// (`pcl::PointCloud<PointT>`, any point type with x, y, z; RGB used when the type has it),
/// calibrated cameras (frustum + image plane), per-vertex scalars with a colour bar (fit error
/// heatmaps, clothness, confidence), handles and constraints; offscreen screenshots.
///
/// \code
/// tbsp::Visualizer viz({/*width*/ 800, /*height*/ 600, /*offscreen*/ true});
/// viz.addPointCloud("scan", *cloud);                 // pcl::PointCloud<pcl::PointXYZ>
/// viz.addMesh("fit", fitted);                        // tbsp::TriMesh
/// viz.setScalars("fit", error_mm, {"error (mm)"});   // one value per vertex, with a colour bar
/// viz.resetCamera();
/// viz.saveScreenshot("fit.png");                     // or viz.spin() for a window
/// \endcode
///
/// Every object has a string id (like PCLVisualizer): adding an id that exists replaces it.
/// Rendering needs an X display (VTK 9 on Debian renders with OpenGL through X): offscreen
/// screenshots on a machine without a screen run under `xvfb-run`. Without a display the
/// constructor throws tbsp::InvalidInput saying so (instead of VTK aborting the process).
/// Not thread-safe: call it from one thread (the GUI thread in an app).

#include <cmath>
#include <memory>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <pcl/point_cloud.h>
#include <pcl/point_types.h>

#include "tbsp/mesh/tet_mesh.h"
#include "tbsp/mesh/tri_mesh.h"
#include "tbsp/multiview/camera.h"

class vtkRenderWindow;
class vtkRenderer;

namespace tbsp {

/// Options of Visualizer.
struct VisualizerOptions {
  int width = 800;        ///< window / screenshot width, pixels; range [16, 8192]. Default 800.
  int height = 600;       ///< window / screenshot height, pixels; range [16, 8192]. Default 600.
  bool offscreen = false; ///< render without showing a window (screenshots, tests). Default false.
  Eigen::Vector3d background{1.0, 1.0, 1.0};  ///< RGB in [0, 1]. Default white.
  std::string title = "tbsp";                  ///< window title
  /// True when every field is in range; else false and, if given, `why` says which and why.
  bool isValid(std::string* why = nullptr) const;
};

/// Colour maps of setScalars.
enum class ColorMap {
  Viridis,   ///< perceptually uniform dark blue → yellow (default; errors, confidence)
  BlueRed,   ///< diverging blue → white → red (signed values, clothness)
  Rainbow    ///< blue → red through green (what MeshLab's quality colouring looks like)
};

/// How setScalars colours values and labels its colour bar.
struct ScalarBarOptions {
  std::string title;              ///< colour-bar title (with the unit, e.g. "error (mm)")
  ColorMap colormap = ColorMap::Viridis;
  /// Value range mapped to the colour map ends; values outside are clamped to the end colours.
  /// min ≥ max (the default) = the finite data range.
  double min = 0.0, max = 0.0;
  bool show_bar = true;           ///< draw the colour bar (one per visualizer: the last shown wins)
};

/// The colour of `value` in [min, max] under `map`, RGB in [0, 1] (the table setScalars uses;
/// exposed so tests and reports can look colours up). Values outside are clamped.
Eigen::Vector3d colormap_color(ColorMap map, double value, double min, double max);

/// \brief A VTK scene of tbsp objects. See the file comment.
class Visualizer {
public:
  /// Own window (on screen, or offscreen when `o.offscreen`).
  /// \throws InvalidInput when `o` is invalid or there is no X display (DISPLAY unset).
  explicit Visualizer(const VisualizerOptions& o = {});
  /// Draws into an existing render window (e.g. a Qt widget's); adds its own renderer to it.
  explicit Visualizer(vtkRenderWindow* window, const Eigen::Vector3d& background = {1, 1, 1});
  ~Visualizer();
  Visualizer(const Visualizer&) = delete;
  Visualizer& operator=(const Visualizer&) = delete;

  /// A triangle mesh, flat grey-blue by default (`rgb` in [0, 1]), smooth-shaded.
  /// \throws InvalidInput for a face index out of range.
  void addMesh(const std::string& id, const TriMesh& mesh, const Eigen::Vector3d& rgb = {0.75, 0.78, 0.85});
  /// A triangle mesh with a texture: `uv` one texture coordinate per vertex in [0, 1] (origin
  /// bottom-left, as OBJ), `rgb` the image (row-major 8-bit RGB, top row first, width × height
  /// × 3 bytes). Unlit, so the image's colours are shown as they are.
  /// \throws InvalidInput for a wrong uv row count or image size.
  void addTexturedMesh(const std::string& id, const TriMesh& mesh, const Eigen::MatrixX2d& uv,
                       const std::vector<unsigned char>& rgb, int width, int height);
  /// Moves the vertices of a mesh, cloud or tet mesh added before (same count; normals
  /// recomputed). O(#V). \throws InvalidInput for an unknown id or a different vertex count.
  void updatePositions(const std::string& id, const Eigen::MatrixX3d& V);
  /// A tetrahedral mesh: its boundary surface, with the tet edges as a wireframe when `edges`.
  void addTetMesh(const std::string& id, const TetMesh& tets, bool edges = true,
                  const Eigen::Vector3d& rgb = {0.85, 0.75, 0.6});
  /// Points drawn as round sprites of `point_size` pixels; `rgb` per point (values 0–255, rows =
  /// points) or empty for one colour `color`.
  void addPoints(const std::string& id, const Eigen::MatrixX3d& P,
                 const Eigen::Matrix<unsigned char, Eigen::Dynamic, 3>& rgb = {}, double point_size = 3.0,
                 const Eigen::Vector3d& color = {0.2, 0.2, 0.2});
  /// A PCL cloud: any point type with x, y, z; per-point colour when it has rgb. Non-finite
  /// points are skipped (organized clouds are fine).
  template <typename PointT>
  void addPointCloud(const std::string& id, const pcl::PointCloud<PointT>& cloud, double point_size = 3.0);
  /// A camera: its frustum as lines from the centre to the image corners at `depth` (world
  /// units), and, when `rgb` is given (row-major 8-bit RGB, width × height × 3 bytes, e.g. a
  /// cv::Mat converted with cvtColor(BGR2RGB)), the image textured on the far plane.
  void addCamera(const std::string& id, const Camera& camera, double depth,
                 const std::vector<unsigned char>& rgb = {}, const Eigen::Vector3d& color = {0.1, 0.3, 0.8});
  /// Colours object `id` by one scalar per vertex (mesh, tet mesh) or per point (cloud) through
  /// a colour map, with a colour bar. NaN values are drawn grey.
  /// \throws InvalidInput for an unknown id or a wrong count.
  void setScalars(const std::string& id, const Eigen::VectorXd& values, const ScalarBarOptions& bar = {});
  /// Spheres of `radius` (world units) at the rows of `centers` (handles, markers).
  void addSpheres(const std::string& id, const Eigen::MatrixX3d& centers, double radius,
                  const Eigen::Vector3d& rgb = {0.9, 0.2, 0.2});
  /// Line segments from[i] → to[i] (constraints: a vertex and its target).
  void addLines(const std::string& id, const Eigen::MatrixX3d& from, const Eigen::MatrixX3d& to,
                const Eigen::Vector3d& rgb = {0.9, 0.5, 0.1}, double width = 2.0);
  /// A text label in the top-left corner (one per visualizer).
  void setText(const std::string& text);

  /// \brief The points (vertices) of object `id` that are visible — not hidden behind a
  /// surface — inside the screen rectangle [x0, x1] × [y0, y1] (pixels of the render window,
  /// origin top-left as mouse events give them): a rubber-band selection. Visibility is read from
  /// the depth buffer of the last render; `tolerance` is the allowed depth difference as a
  /// fraction of the scene's bounding-box diagonal. O(#points). \throws InvalidInput for an
  /// unknown id.
  std::vector<int> selectVisiblePoints(const std::string& id, int x0, int y0, int x1, int y1, double tolerance = 0.01);

  bool contains(const std::string& id) const;
  /// Removes an object; unknown ids are ignored.
  void remove(const std::string& id);
  void setVisible(const std::string& id, bool visible);
  /// Opacity in [0, 1].
  void setOpacity(const std::string& id, double opacity);
  /// Ids of the objects in the scene, in the order they were added.
  std::vector<std::string> ids() const;

  /// Fits the view to everything visible (keeps the viewing direction).
  void resetCamera();
  /// Camera position, focal point and up vector (world).
  void setCameraPose(const Eigen::Vector3d& eye, const Eigen::Vector3d& focal, const Eigen::Vector3d& up);
  /// Looks at the scene from a calibrated camera (its pose and field of view).
  void setCameraFrom(const Camera& camera);
  /// Renders one frame.
  void render();
  /// Renders and writes a PNG (written to a temporary file and renamed: an existing file is
  /// never left half-written). \throws FileError when the file cannot be written.
  void saveScreenshot(const std::string& png_path);
  /// Opens the window and runs VTK's interactor until it is closed (not for offscreen).
  void spin();

  vtkRenderer* renderer();
  vtkRenderWindow* renderWindow();

private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// ---- template implementation -------------------------------------------------------------------

template <typename PointT>
void Visualizer::addPointCloud(const std::string& id, const pcl::PointCloud<PointT>& cloud, double point_size) {
  Eigen::MatrixX3d P(Eigen::Index(cloud.size()), 3);
  Eigen::Matrix<unsigned char, Eigen::Dynamic, 3> rgb;
  constexpr bool has_rgb = pcl::traits::has_color<PointT>::value;
  if (has_rgb) rgb.resize(P.rows(), 3);
  Eigen::Index n = 0;
  for (const auto& p : cloud.points) {
    if (!std::isfinite(p.x) || !std::isfinite(p.y) || !std::isfinite(p.z)) continue;
    P.row(n) << p.x, p.y, p.z;
    if constexpr (pcl::traits::has_color<PointT>::value) rgb.row(n) << p.r, p.g, p.b;
    ++n;
  }
  P.conservativeResize(n, 3);
  if (has_rgb) rgb.conservativeResize(n, 3);
  addPoints(id, P, rgb, point_size);
}

}  // namespace tbsp
