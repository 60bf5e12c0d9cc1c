#include "tbsp/vtk/visualizer.h"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <map>

#include <vtkActor.h>
#include <vtkActor2D.h>
#include <vtkAutoInit.h>
#include <vtkCamera.h>
#include <vtkCellArray.h>
#include <vtkDoubleArray.h>
#include <vtkGlyph3DMapper.h>
#include <vtkImageData.h>
#include <vtkInteractorStyleTrackballCamera.h>
#include <vtkLookupTable.h>
#include <vtkPNGWriter.h>
#include <vtkPlaneSource.h>
#include <vtkPointData.h>
#include <vtkPoints.h>
#include <vtkPolyData.h>
#include <vtkPolyDataMapper.h>
#include <vtkProperty.h>
#include <vtkRenderWindow.h>
#include <vtkRenderWindowInteractor.h>
#include <vtkRenderer.h>
#include <vtkScalarBarActor.h>
#include <vtkSmartPointer.h>
#include <vtkSphereSource.h>
#include <vtkTextActor.h>
#include <vtkTextProperty.h>
#include <vtkTexture.h>
#include <vtkUnsignedCharArray.h>
#include <vtkWindowToImageFilter.h>

#include "tbsp/core/error.h"
#include "tbsp/io/atomic_file.h"

// The object factories of the rendering back-end (explicit, so that programs linking tbsp_vtk
// need no VTK autoinit definitions of their own).
VTK_MODULE_INIT(vtkRenderingOpenGL2);
VTK_MODULE_INIT(vtkInteractionStyle);
VTK_MODULE_INIT(vtkRenderingFreeType);

namespace tbsp {

namespace {

template <typename T>
using SP = vtkSmartPointer<T>;

// Viridis at 9 stops (matplotlib's table, sampled), interpolated linearly.
const double kViridis[9][3] = {{0.267, 0.005, 0.329}, {0.279, 0.175, 0.483}, {0.230, 0.322, 0.546},
                               {0.173, 0.449, 0.558}, {0.128, 0.567, 0.551}, {0.153, 0.683, 0.502},
                               {0.369, 0.789, 0.383}, {0.678, 0.864, 0.190}, {0.993, 0.906, 0.144}};
const double kBlueRed[3][3] = {{0.23, 0.30, 0.75}, {0.87, 0.87, 0.87}, {0.71, 0.02, 0.15}};
const double kRainbow[5][3] = {{0, 0, 1}, {0, 1, 1}, {0, 1, 0}, {1, 1, 0}, {1, 0, 0}};

Eigen::Vector3d lerp_table(const double (*table)[3], int n, double t) {
  t = std::clamp(t, 0.0, 1.0) * (n - 1);
  const int i = std::min(int(t), n - 2);
  const double f = t - i;
  return {table[i][0] * (1 - f) + table[i + 1][0] * f, table[i][1] * (1 - f) + table[i + 1][1] * f,
          table[i][2] * (1 - f) + table[i + 1][2] * f};
}

SP<vtkPoints> to_points(const Eigen::MatrixX3d& V) {
  auto pts = SP<vtkPoints>::New();
  pts->SetDataTypeToDouble();
  pts->SetNumberOfPoints(V.rows());
  for (Eigen::Index i = 0; i < V.rows(); ++i) pts->SetPoint(i, V(i, 0), V(i, 1), V(i, 2));
  return pts;
}

SP<vtkCellArray> to_triangles(const Eigen::MatrixX3i& F, Eigen::Index n_vertices, const std::string& id) {
  auto cells = SP<vtkCellArray>::New();
  cells->AllocateExact(F.rows(), 3 * F.rows());
  for (Eigen::Index f = 0; f < F.rows(); ++f) {
    vtkIdType ids[3];
    for (int k = 0; k < 3; ++k) {
      if (F(f, k) < 0 || F(f, k) >= n_vertices)
        throw InvalidInput("Visualizer: object \"" + id + "\": face " + std::to_string(f) + " uses vertex " +
                           std::to_string(F(f, k)) + " of " + std::to_string(n_vertices));
      ids[k] = F(f, k);
    }
    cells->InsertNextCell(3, ids);
  }
  return cells;
}

SP<vtkDoubleArray> vertex_normal_array(const Eigen::MatrixX3d& V, const Eigen::MatrixX3i& F) {
  const Eigen::MatrixX3d N = vertex_normals(V, F);
  auto arr = SP<vtkDoubleArray>::New();
  arr->SetNumberOfComponents(3);
  arr->SetNumberOfTuples(N.rows());
  for (Eigen::Index i = 0; i < N.rows(); ++i) arr->SetTuple3(i, N(i, 0), N(i, 1), N(i, 2));
  return arr;
}

}  // namespace

Eigen::Vector3d colormap_color(ColorMap map, double value, double min, double max) {
  const double t = max > min ? (value - min) / (max - min) : 0.5;
  switch (map) {
    case ColorMap::BlueRed: return lerp_table(kBlueRed, 3, t);
    case ColorMap::Rainbow: return lerp_table(kRainbow, 5, t);
    case ColorMap::Viridis: break;
  }
  return lerp_table(kViridis, 9, t);
}

bool VisualizerOptions::isValid(std::string* why) const {
  auto fail = [&](const std::string& m) { if (why) *why = m; return false; };
  if (width < 16 || width > 8192) return fail("width " + std::to_string(width) + " is outside [16, 8192]");
  if (height < 16 || height > 8192) return fail("height " + std::to_string(height) + " is outside [16, 8192]");
  for (int k = 0; k < 3; ++k)
    if (!(background[k] >= 0 && background[k] <= 1)) return fail("background must be RGB in [0, 1]");
  return true;
}

struct Visualizer::Impl {
  struct Object {
    SP<vtkPolyData> poly;                  // the data whose points updatePositions moves (and colours)
    SP<vtkPolyData> edges;                 // tet meshes: the wireframe over the same points
    Eigen::MatrixX3i F;                    // meshes: faces for normals
    std::vector<SP<vtkProp>> props;
    SP<vtkPolyDataMapper> mapper;          // mapper of `poly` (scalars)
  };
  SP<vtkRenderWindow> window;
  SP<vtkRenderer> renderer;
  SP<vtkScalarBarActor> bar;
  SP<vtkTextActor> text;
  std::map<std::string, Object> objects;
  std::string bar_owner;                   // the object whose scalars the colour bar shows
  std::vector<std::string> order;

  // The mapper of o.poly (no scalars yet) and an actor with one colour.
  static SP<vtkActor> plain_actor(Object& o, const Eigen::Vector3d& rgb) {
    o.mapper = SP<vtkPolyDataMapper>::New();
    o.mapper->SetInputData(o.poly);
    o.mapper->ScalarVisibilityOff();
    auto actor = SP<vtkActor>::New();
    actor->SetMapper(o.mapper);
    actor->GetProperty()->SetColor(rgb.x(), rgb.y(), rgb.z());
    return actor;
  }
  Object& get(const std::string& id, const char* who) {
    auto it = objects.find(id);
    if (it == objects.end()) throw InvalidInput(std::string("Visualizer::") + who + ": no object \"" + id + "\"");
    return it->second;
  }
  void put(const std::string& id, Object o) {
    remove(id);
    for (auto& p : o.props) renderer->AddViewProp(p);
    objects[id] = std::move(o);
    order.push_back(id);
  }
  void remove(const std::string& id) {
    auto it = objects.find(id);
    if (it == objects.end()) return;
    for (auto& p : it->second.props) renderer->RemoveViewProp(p);
    objects.erase(it);
    if (bar_owner == id) {  // its colour bar goes with it
      bar->SetVisibility(false);
      bar_owner.clear();
    }
    order.erase(std::remove(order.begin(), order.end(), id), order.end());
  }
  void init(const Eigen::Vector3d& bg) {
    renderer = SP<vtkRenderer>::New();
    renderer->SetBackground(bg.x(), bg.y(), bg.z());
    window->AddRenderer(renderer);
    bar = SP<vtkScalarBarActor>::New();
    bar->SetVisibility(false);
    bar->SetNumberOfLabels(5);
    bar->SetMaximumWidthInPixels(80);
    bar->SetPosition(0.8, 0.1);
    bar->SetLabelFormat("%-#6.3g");
    bar->SetUnconstrainedFontSize(true);
    bar->SetTextPad(4);
    bar->SetPosition2(0.1, 0.8);
    for (auto* tp : {bar->GetTitleTextProperty(), bar->GetLabelTextProperty()}) {
      tp->SetColor(bg.mean() > 0.5 ? 0.1 : 0.9, bg.mean() > 0.5 ? 0.1 : 0.9, bg.mean() > 0.5 ? 0.1 : 0.9);
      tp->SetShadow(false);
      tp->SetItalic(false);
      tp->SetBold(false);
      tp->SetFontSize(13);
    }
    renderer->AddViewProp(bar);
    text = SP<vtkTextActor>::New();
    text->SetPosition(10, 10);
    text->GetTextProperty()->SetFontSize(16);
    const double c = bg.mean() > 0.5 ? 0.1 : 0.9;
    text->GetTextProperty()->SetColor(c, c, c);
    text->SetVisibility(false);
    renderer->AddViewProp(text);
    auto cam = renderer->GetActiveCamera();
    cam->SetPosition(0, 0, 1);
    cam->SetFocalPoint(0, 0, 0);
    cam->SetViewUp(0, 1, 0);
  }
};

Visualizer::Visualizer(const VisualizerOptions& o) : impl_(new Impl) {
  std::string why;
  if (!o.isValid(&why)) throw InvalidInput("VisualizerOptions: " + why);
  const char* display = std::getenv("DISPLAY");
  if (display == nullptr || *display == 0)
    throw InvalidInput("Visualizer: no X display (DISPLAY is not set): VTK renders through X, also offscreen; "
                       "run the program under xvfb-run (Debian: apt-get install xvfb) or on a desktop");
  impl_->window = SP<vtkRenderWindow>::New();
  impl_->window->SetSize(o.width, o.height);
  impl_->window->SetWindowName(o.title.c_str());
  impl_->window->SetMultiSamples(0);  // identical pixels across drivers for screenshot tests
  if (o.offscreen) impl_->window->SetOffScreenRendering(1);
  impl_->init(o.background);
}

Visualizer::Visualizer(vtkRenderWindow* window, const Eigen::Vector3d& background) : impl_(new Impl) {
  if (window == nullptr) throw InvalidInput("Visualizer: the render window is null");
  impl_->window = window;
  impl_->init(background);
}

Visualizer::~Visualizer() {
  if (impl_ && impl_->window && impl_->renderer) impl_->window->RemoveRenderer(impl_->renderer);
}

vtkRenderer* Visualizer::renderer() { return impl_->renderer; }
vtkRenderWindow* Visualizer::renderWindow() { return impl_->window; }

void Visualizer::addMesh(const std::string& id, const TriMesh& mesh, const Eigen::Vector3d& rgb) {
  Impl::Object o;
  o.poly = SP<vtkPolyData>::New();
  o.poly->SetPoints(to_points(mesh.V));
  o.poly->SetPolys(to_triangles(mesh.F, mesh.V.rows(), id));
  o.poly->GetPointData()->SetNormals(vertex_normal_array(mesh.V, mesh.F));
  o.F = mesh.F;
  auto actor = Impl::plain_actor(o, rgb);
  actor->GetProperty()->SetInterpolationToPhong();
  actor->GetProperty()->SetSpecular(0.15);
  o.props.push_back(actor);
  impl_->put(id, std::move(o));
}

namespace {
SP<vtkTexture> make_texture(const std::vector<unsigned char>& rgb, int w, int h) {
  auto img = SP<vtkImageData>::New();
  img->SetDimensions(w, h, 1);
  img->AllocateScalars(VTK_UNSIGNED_CHAR, 3);
  auto* dst = static_cast<unsigned char*>(img->GetScalarPointer());
  const std::size_t row = std::size_t(w) * 3;
  for (int y = 0; y < h; ++y)  // VTK images start at the bottom row
    std::copy(rgb.begin() + long(y) * long(row), rgb.begin() + long(y + 1) * long(row), dst + std::size_t(h - 1 - y) * row);
  auto tex = SP<vtkTexture>::New();
  tex->SetInputData(img);
  tex->InterpolateOn();
  return tex;
}
}  // namespace

void Visualizer::addTexturedMesh(const std::string& id, const TriMesh& mesh, const Eigen::MatrixX2d& uv,
                                 const std::vector<unsigned char>& rgb, int width, int height) {
  if (uv.rows() != mesh.V.rows())
    throw InvalidInput("Visualizer::addTexturedMesh: \"" + id + "\": " + std::to_string(uv.rows()) + " texture coordinates for " +
                       std::to_string(mesh.V.rows()) + " vertices");
  if (width <= 0 || height <= 0 || rgb.size() != std::size_t(width) * std::size_t(height) * 3)
    throw InvalidInput("Visualizer::addTexturedMesh: \"" + id + "\": the image has " + std::to_string(rgb.size()) +
                       " bytes for " + std::to_string(width) + " x " + std::to_string(height) + " RGB pixels");
  addMesh(id, mesh);
  auto& o = impl_->get(id, "addTexturedMesh");
  auto tc = SP<vtkDoubleArray>::New();
  tc->SetNumberOfComponents(2);
  tc->SetNumberOfTuples(uv.rows());
  for (Eigen::Index i = 0; i < uv.rows(); ++i) tc->SetTuple2(i, uv(i, 0), uv(i, 1));
  o.poly->GetPointData()->SetTCoords(tc);
  auto* actor = vtkActor::SafeDownCast(o.props[0]);
  actor->SetTexture(make_texture(rgb, width, height));
  actor->GetProperty()->SetColor(1, 1, 1);
  actor->GetProperty()->LightingOff();
}

void Visualizer::updatePositions(const std::string& id, const Eigen::MatrixX3d& V) {
  auto& o = impl_->get(id, "updatePositions");
  vtkPoints* pts = o.poly->GetPoints();
  if (pts == nullptr || pts->GetNumberOfPoints() != V.rows())
    throw InvalidInput("Visualizer::updatePositions: object \"" + id + "\" has " +
                       std::to_string(pts ? pts->GetNumberOfPoints() : 0) + " vertices, got " + std::to_string(V.rows()));
  for (Eigen::Index i = 0; i < V.rows(); ++i) pts->SetPoint(i, V(i, 0), V(i, 1), V(i, 2));
  pts->Modified();
  if (o.F.rows() > 0) o.poly->GetPointData()->SetNormals(vertex_normal_array(V, o.F));
  o.poly->Modified();
  if (o.edges) o.edges->Modified();
}

void Visualizer::addTetMesh(const std::string& id, const TetMesh& tets, bool edges, const Eigen::Vector3d& rgb) {
  const Eigen::MatrixX3i F = tet_boundary_faces(tets.T);
  TriMesh surface;
  surface.V = tets.V;
  surface.F = F;
  addMesh(id, surface, rgb);
  auto& o = impl_->get(id, "addTetMesh");
  if (!edges) return;
  std::vector<std::pair<int, int>> e;
  e.reserve(size_t(tets.T.rows()) * 6);
  for (Eigen::Index t = 0; t < tets.T.rows(); ++t)
    for (int a = 0; a < 4; ++a)
      for (int b = a + 1; b < 4; ++b) e.emplace_back(std::min(tets.T(t, a), tets.T(t, b)), std::max(tets.T(t, a), tets.T(t, b)));
  std::sort(e.begin(), e.end());
  e.erase(std::unique(e.begin(), e.end()), e.end());
  auto lines = SP<vtkCellArray>::New();
  for (const auto& [a, b] : e) {
    vtkIdType ids[2] = {a, b};
    lines->InsertNextCell(2, ids);
  }
  o.edges = SP<vtkPolyData>::New();
  o.edges->SetPoints(o.poly->GetPoints());  // shared: updatePositions moves both
  o.edges->SetLines(lines);
  auto mapper = SP<vtkPolyDataMapper>::New();
  mapper->SetInputData(o.edges);
  auto actor = SP<vtkActor>::New();
  actor->SetMapper(mapper);
  actor->GetProperty()->SetColor(0.25, 0.2, 0.15);
  actor->GetProperty()->SetOpacity(0.35);
  actor->GetProperty()->LightingOff();
  o.props.push_back(actor);
  impl_->renderer->AddViewProp(actor);
}

void Visualizer::addPoints(const std::string& id, const Eigen::MatrixX3d& P,
                           const Eigen::Matrix<unsigned char, Eigen::Dynamic, 3>& rgb, double point_size,
                           const Eigen::Vector3d& color) {
  if (rgb.rows() != 0 && rgb.rows() != P.rows())
    throw InvalidInput("Visualizer::addPoints: object \"" + id + "\": " + std::to_string(rgb.rows()) + " colours for " +
                       std::to_string(P.rows()) + " points");
  Impl::Object o;
  o.poly = SP<vtkPolyData>::New();
  o.poly->SetPoints(to_points(P));
  auto verts = SP<vtkCellArray>::New();
  verts->AllocateExact(P.rows(), P.rows());
  for (vtkIdType i = 0; i < P.rows(); ++i) verts->InsertNextCell(1, &i);
  o.poly->SetVerts(verts);
  o.mapper = SP<vtkPolyDataMapper>::New();
  o.mapper->SetInputData(o.poly);
  if (rgb.rows() > 0) {
    auto c = SP<vtkUnsignedCharArray>::New();
    c->SetNumberOfComponents(3);
    c->SetNumberOfTuples(P.rows());
    for (Eigen::Index i = 0; i < P.rows(); ++i) {
      const unsigned char t[3] = {rgb(i, 0), rgb(i, 1), rgb(i, 2)};
      c->SetTypedTuple(i, t);
    }
    o.poly->GetPointData()->SetScalars(c);
    o.mapper->SetColorModeToDirectScalars();
    o.mapper->ScalarVisibilityOn();
  } else {
    o.mapper->ScalarVisibilityOff();
  }
  auto actor = SP<vtkActor>::New();
  actor->SetMapper(o.mapper);
  actor->GetProperty()->SetColor(color.x(), color.y(), color.z());
  actor->GetProperty()->SetPointSize(float(point_size));
  actor->GetProperty()->SetRenderPointsAsSpheres(true);
  actor->GetProperty()->LightingOff();
  o.props.push_back(actor);
  impl_->put(id, std::move(o));
}

void Visualizer::addCamera(const std::string& id, const Camera& cam, double depth, const std::vector<unsigned char>& rgb,
                           const Eigen::Vector3d& color) {
  if (!(depth > 0)) throw InvalidInput("Visualizer::addCamera: \"" + id + "\": depth must be > 0");
  const double w = cam.width(), h = cam.height();
  if (!rgb.empty() && rgb.size() != size_t(w * h * 3))
    throw InvalidInput("Visualizer::addCamera: \"" + id + "\": the image has " + std::to_string(rgb.size()) +
                       " bytes, the camera is " + std::to_string(cam.width()) + " x " + std::to_string(cam.height()) +
                       " (RGB: width × height × 3)");
  // image corners (pixel-area corners) on the plane z_c = depth
  const Eigen::Vector3d c0 = cam.backProject({-0.5, -0.5}, depth), c1 = cam.backProject({w - 0.5, -0.5}, depth),
                        c2 = cam.backProject({w - 0.5, h - 0.5}, depth), c3 = cam.backProject({-0.5, h - 0.5}, depth);
  Eigen::MatrixX3d from(8, 3), to(8, 3);
  const Eigen::Vector3d C = cam.center();
  const Eigen::Vector3d corners[4] = {c0, c1, c2, c3};
  for (int k = 0; k < 4; ++k) {
    from.row(k) = C.transpose();
    to.row(k) = corners[k].transpose();
    from.row(4 + k) = corners[k].transpose();
    to.row(4 + k) = corners[(k + 1) % 4].transpose();
  }
  addLines(id, from, to, color, 1.5);
  if (rgb.empty()) return;
  auto& o = impl_->get(id, "addCamera");
  const auto tex = make_texture(rgb, cam.width(), cam.height());
  auto plane = SP<vtkPlaneSource>::New();
  plane->SetOrigin(c3.x(), c3.y(), c3.z());   // bottom-left of the image
  plane->SetPoint1(c2.x(), c2.y(), c2.z());   // bottom-right
  plane->SetPoint2(c0.x(), c0.y(), c0.z());   // top-left
  auto mapper = SP<vtkPolyDataMapper>::New();
  mapper->SetInputConnection(plane->GetOutputPort());
  auto actor = SP<vtkActor>::New();
  actor->SetMapper(mapper);
  actor->SetTexture(tex);
  actor->GetProperty()->LightingOff();
  o.props.push_back(actor);
  impl_->renderer->AddViewProp(actor);
}

void Visualizer::setScalars(const std::string& id, const Eigen::VectorXd& values, const ScalarBarOptions& bar) {
  auto& o = impl_->get(id, "setScalars");
  if (!o.mapper) throw InvalidInput("Visualizer::setScalars: object \"" + id + "\" (spheres) has no per-point colours");
  if (o.poly->GetNumberOfPoints() != values.size())
    throw InvalidInput("Visualizer::setScalars: object \"" + id + "\" has " + std::to_string(o.poly->GetNumberOfPoints()) +
                       " vertices/points, got " + std::to_string(values.size()) + " values");
  double lo = bar.min, hi = bar.max;
  if (!(lo < hi)) {
    lo = INFINITY;
    hi = -INFINITY;
    for (double v : values)
      if (std::isfinite(v)) { lo = std::min(lo, v); hi = std::max(hi, v); }
    if (!(lo <= hi)) { lo = 0; hi = 1; }
    if (lo == hi) hi = lo + 1e-12 + std::abs(lo) * 1e-9;
  }
  auto lut = SP<vtkLookupTable>::New();
  lut->SetNumberOfTableValues(256);
  lut->SetRange(lo, hi);
  for (int i = 0; i < 256; ++i) {
    const Eigen::Vector3d c = colormap_color(bar.colormap, i / 255.0, 0.0, 1.0);
    lut->SetTableValue(i, c.x(), c.y(), c.z(), 1.0);
  }
  lut->SetNanColor(0.6, 0.6, 0.6, 1.0);
  lut->UseAboveRangeColorOff();
  lut->UseBelowRangeColorOff();
  lut->Build();
  auto arr = SP<vtkDoubleArray>::New();
  arr->SetName("scalars");
  arr->SetNumberOfTuples(values.size());
  for (Eigen::Index i = 0; i < values.size(); ++i) arr->SetValue(i, values[i]);
  o.poly->GetPointData()->SetScalars(arr);
  o.mapper->SetLookupTable(lut);
  o.mapper->SetScalarRange(lo, hi);
  o.mapper->SetColorModeToMapScalars();
  o.mapper->SetScalarModeToUsePointData();
  o.mapper->ScalarVisibilityOn();
  o.mapper->InterpolateScalarsBeforeMappingOn();
  if (bar.show_bar) {
    impl_->bar->SetLookupTable(lut);
    impl_->bar->SetTitle(bar.title.c_str());
    impl_->bar->SetVisibility(true);
    impl_->bar_owner = id;
  }
}

void Visualizer::addSpheres(const std::string& id, const Eigen::MatrixX3d& centers, double radius, const Eigen::Vector3d& rgb) {
  if (!(radius > 0)) throw InvalidInput("Visualizer::addSpheres: \"" + id + "\": radius must be > 0");
  Impl::Object o;
  o.poly = SP<vtkPolyData>::New();
  o.poly->SetPoints(to_points(centers));
  auto sphere = SP<vtkSphereSource>::New();
  sphere->SetRadius(radius);
  sphere->SetThetaResolution(16);
  sphere->SetPhiResolution(12);
  auto mapper = SP<vtkGlyph3DMapper>::New();
  mapper->SetInputData(o.poly);
  mapper->SetSourceConnection(sphere->GetOutputPort());
  mapper->ScalingOff();
  mapper->ScalarVisibilityOff();
  auto actor = SP<vtkActor>::New();
  actor->SetMapper(mapper);
  actor->GetProperty()->SetColor(rgb.x(), rgb.y(), rgb.z());
  o.props.push_back(actor);
  impl_->put(id, std::move(o));
}

void Visualizer::addLines(const std::string& id, const Eigen::MatrixX3d& from, const Eigen::MatrixX3d& to,
                          const Eigen::Vector3d& rgb, double width) {
  if (from.rows() != to.rows())
    throw InvalidInput("Visualizer::addLines: \"" + id + "\": " + std::to_string(from.rows()) + " start and " +
                       std::to_string(to.rows()) + " end points");
  Eigen::MatrixX3d P(2 * from.rows(), 3);
  P << from, to;
  Impl::Object o;
  o.poly = SP<vtkPolyData>::New();
  o.poly->SetPoints(to_points(P));
  auto lines = SP<vtkCellArray>::New();
  for (vtkIdType i = 0; i < from.rows(); ++i) {
    vtkIdType ids[2] = {i, i + from.rows()};
    lines->InsertNextCell(2, ids);
  }
  o.poly->SetLines(lines);
  auto actor = Impl::plain_actor(o, rgb);
  actor->GetProperty()->SetLineWidth(float(width));
  actor->GetProperty()->LightingOff();
  o.props.push_back(actor);
  impl_->put(id, std::move(o));
}

void Visualizer::setText(const std::string& text) {
  impl_->text->SetInput(text.c_str());
  impl_->text->SetVisibility(!text.empty());
}

std::vector<int> Visualizer::selectVisiblePoints(const std::string& id, int x0, int y0, int x1, int y1, double tolerance) {
  auto& o = impl_->get(id, "selectVisiblePoints");
  render();
  const int* size = impl_->window->GetSize();
  const int W = size[0], H = size[1];
  if (x0 > x1) std::swap(x0, x1);
  if (y0 > y1) std::swap(y0, y1);
  std::vector<float> zbuf(std::size_t(W) * std::size_t(H));
  impl_->window->GetZbufferData(0, 0, W - 1, H - 1, zbuf.data());
  vtkCamera* cam = impl_->renderer->GetActiveCamera();
  double range[2];
  cam->GetClippingRange(range);
  const double n = range[0], f = range[1];
  const bool parallel = cam->GetParallelProjection() != 0;
  auto view_depth = [&](double d) { return parallel ? n + d * (f - n) : n * f / (f - d * (f - n)); };
  double b[6];
  impl_->renderer->ComputeVisiblePropBounds(b);
  const double diag = std::sqrt((b[1] - b[0]) * (b[1] - b[0]) + (b[3] - b[2]) * (b[3] - b[2]) + (b[5] - b[4]) * (b[5] - b[4]));
  std::vector<int> out;
  vtkPoints* pts = o.poly->GetPoints();
  for (vtkIdType i = 0; i < pts->GetNumberOfPoints(); ++i) {
    double p[3];
    pts->GetPoint(i, p);
    impl_->renderer->SetWorldPoint(p[0], p[1], p[2], 1.0);
    impl_->renderer->WorldToDisplay();
    double d[3];
    impl_->renderer->GetDisplayPoint(d);
    const int px = int(std::lround(d[0])), py_vtk = int(std::lround(d[1]));
    const int py = H - 1 - py_vtk;  // top-left origin
    if (px < x0 || px > x1 || py < y0 || py > y1 || px < 0 || px >= W || py_vtk < 0 || py_vtk >= H) continue;
    const double zb = zbuf[std::size_t(py_vtk) * std::size_t(W) + std::size_t(px)];
    if (view_depth(d[2]) <= view_depth(zb) + tolerance * diag) out.push_back(int(i));
  }
  return out;
}

bool Visualizer::contains(const std::string& id) const { return impl_->objects.count(id) > 0; }
void Visualizer::remove(const std::string& id) { impl_->remove(id); }
void Visualizer::setVisible(const std::string& id, bool visible) {
  for (auto& p : impl_->get(id, "setVisible").props) p->SetVisibility(visible);
}
void Visualizer::setOpacity(const std::string& id, double opacity) {
  for (auto& p : impl_->get(id, "setOpacity").props)
    if (auto* a = vtkActor::SafeDownCast(p)) a->GetProperty()->SetOpacity(std::clamp(opacity, 0.0, 1.0));
}
std::vector<std::string> Visualizer::ids() const { return impl_->order; }

void Visualizer::resetCamera() {
  impl_->renderer->ResetCamera();
  impl_->renderer->ResetCameraClippingRange();
}

void Visualizer::setCameraPose(const Eigen::Vector3d& eye, const Eigen::Vector3d& focal, const Eigen::Vector3d& up) {
  auto* cam = impl_->renderer->GetActiveCamera();
  cam->SetPosition(eye.data());
  cam->SetFocalPoint(focal.data());
  cam->SetViewUp(up.data());
  impl_->renderer->ResetCameraClippingRange();
}

void Visualizer::setCameraFrom(const Camera& camera) {
  const Eigen::Vector3d C = camera.center();
  setCameraPose(C, C + camera.viewDirection(), -camera.R().row(1).transpose());
  impl_->renderer->GetActiveCamera()->SetViewAngle(2.0 * std::atan(0.5 * camera.height() / camera.K()(1, 1)) * 180.0 / M_PI);
  impl_->renderer->ResetCameraClippingRange();
}

void Visualizer::render() {
  impl_->renderer->ResetCameraClippingRange();
  impl_->window->Render();
}

void Visualizer::saveScreenshot(const std::string& png_path) {
  render();
  auto grab = SP<vtkWindowToImageFilter>::New();
  grab->SetInput(impl_->window);
  grab->SetInputBufferTypeToRGB();
  grab->ReadFrontBufferOff();
  grab->Update();
  atomic_write_with(png_path, [&](const std::string& tmp) {
    auto writer = SP<vtkPNGWriter>::New();
    writer->SetFileName(tmp.c_str());
    writer->SetInputConnection(grab->GetOutputPort());
    writer->Write();
    return writer->GetErrorCode() == 0;
  });
}

void Visualizer::spin() {
  auto iren = SP<vtkRenderWindowInteractor>::New();
  iren->SetRenderWindow(impl_->window);
  auto style = SP<vtkInteractorStyleTrackballCamera>::New();
  iren->SetInteractorStyle(style);
  iren->Initialize();
  impl_->window->Render();
  iren->Start();
}

}  // namespace tbsp
