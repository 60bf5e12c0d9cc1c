#include "scene.h"

#include <algorithm>
#include <filesystem>
#include <fstream>

#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "tbsp/core/error.h"
#include "tbsp/io/cloud_io.h"
#include "tbsp/io/mesh_io.h"
#include "tbsp/io/tet_mesh_io.h"
#include "tbsp/mesh/point_mesh_distance.h"

#include <vtkCellArray.h>
#include <vtkCellArrayIterator.h>
#include <vtkDataArray.h>
#include <vtkOBJReader.h>
#include <vtkPointData.h>
#include <vtkPolyData.h>
#include <vtkSmartPointer.h>

namespace fs = std::filesystem;

namespace tbsp::studio {

namespace {

std::string lower_ext(const std::string& p) {
  std::string e = fs::path(p).extension().string();
  std::transform(e.begin(), e.end(), e.begin(), [](unsigned char c) { return char(std::tolower(c)); });
  return e;
}

bool is_mesh_ext(const std::string& e) { return e == ".ply" || e == ".obj" || e == ".off" || e == ".vtk" || e == ".stl"; }

// A path written in a report: as it is, else relative to the report's folder.
std::string resolve_near(const std::string& p, const std::string& report) {
  if (p.empty() || fs::exists(p)) return p;
  const fs::path alt = fs::path(report).parent_path() / fs::path(p).filename();
  return fs::exists(alt) ? alt.string() : p;
}

Eigen::MatrixX3d cloud_points(const std::string& path) {
  const auto c = read_cloud_normals(path);
  Eigen::MatrixX3d P(Eigen::Index(c->size()), 3);
  Eigen::Index n = 0;
  for (const auto& q : *c)
    if (std::isfinite(q.x) && std::isfinite(q.y) && std::isfinite(q.z)) P.row(n++) << q.x, q.y, q.z;
  P.conservativeResize(n, 3);
  return P;
}

// `tbsp texture --report`: the textured OBJ it names, with its texture (OUT.png next to it).
void load_texture_report(Visualizer& viz, Scene& s, const nlohmann::json& j) {
  const std::string obj = resolve_near(j["output"].get<std::string>(), s.path);
  if (!fs::exists(obj)) throw FileError(s.path + ": the textured mesh " + obj + " it names does not exist");
  auto reader = vtkSmartPointer<vtkOBJReader>::New();
  reader->SetFileName(obj.c_str());
  reader->Update();
  vtkPolyData* pd = reader->GetOutput();
  vtkDataArray* tc = pd ? pd->GetPointData()->GetTCoords() : nullptr;
  if (!pd || pd->GetNumberOfPoints() == 0 || !tc)
    throw FileError(obj + ": not an OBJ with texture coordinates (written by tbsp texture)");
  TriMesh m;
  m.V.resize(pd->GetNumberOfPoints(), 3);
  Eigen::MatrixX2d uv(pd->GetNumberOfPoints(), 2);
  for (vtkIdType i = 0; i < pd->GetNumberOfPoints(); ++i) {
    double p[3];
    pd->GetPoint(i, p);
    m.V.row(i) << p[0], p[1], p[2];
    uv.row(i) << tc->GetComponent(i, 0), tc->GetComponent(i, 1);
  }
  std::vector<Eigen::Vector3i> faces;
  auto it = vtkSmartPointer<vtkCellArrayIterator>::Take(pd->GetPolys()->NewIterator());
  for (it->GoToFirstCell(); !it->IsDoneWithTraversal(); it->GoToNextCell()) {
    vtkIdType n;
    const vtkIdType* ids;
    it->GetCurrentCell(n, ids);
    for (vtkIdType k = 1; k + 1 < n; ++k) faces.emplace_back(int(ids[0]), int(ids[k]), int(ids[k + 1]));
  }
  m.F.resize(Eigen::Index(faces.size()), 3);
  for (std::size_t f = 0; f < faces.size(); ++f) m.F.row(Eigen::Index(f)) = faces[f].transpose();
  const std::string png = fs::path(obj).replace_extension(".png").string();
  cv::Mat img = cv::imread(png, cv::IMREAD_COLOR);
  if (img.empty()) throw FileError(png + ": the texture image of " + obj + " cannot be read");
  cv::cvtColor(img, img, cv::COLOR_BGR2RGB);
  if (!img.isContinuous()) img = img.clone();
  viz.addTexturedMesh(s.prefix + "mesh", m, uv, std::vector<unsigned char>(img.data, img.data + img.total() * 3), img.cols, img.rows);
  char buf[256];
  std::snprintf(buf, sizeof buf, "texture report: %lld vertices, %dx%d texture, constraint residual max %.2f px, matched %.1f %%",
                static_cast<long long>(m.V.rows()), img.cols, img.rows, j.value("max_constraint_residual_px", 0.0),
                100.0 * j.value("matched_fraction", 0.0));
  s.summary = buf;
}

// `tbsp tetdeform --report`: the deformed output coloured by how far each vertex moved.
void load_tet_report(Visualizer& viz, Scene& s, const nlohmann::json& j) {
  const std::string in = resolve_near(j["input"]["mesh"].get<std::string>(), s.path);
  const std::string out = resolve_near(j["output"].get<std::string>(), s.path);
  auto surface = [&](const std::string& p) {
    return p.size() > 5 && p.compare(p.size() - 5, 5, ".mesh") == 0 ? tet_boundary_mesh(read_tet_mesh(p)) : read_mesh(p);
  };
  TriMesh rest, def;
  try {
    rest = surface(in);
    def = surface(out);
  } catch (const std::exception& e) {
    throw FileError(s.path + ": " + e.what() + " (the report names it; keep the meshes next to the report)");
  }
  viz.addMesh(s.prefix + "mesh", def);
  if (rest.V.rows() == def.V.rows()) {
    viz.addMesh(s.prefix + "rest", rest, {0.7, 0.7, 0.7});
    viz.setOpacity(s.prefix + "rest", 0.2);
    const Eigen::VectorXd d = (def.V - rest.V).rowwise().norm() * (100.0 / bbox_diagonal(rest.V));
    viz.setScalars(s.prefix + "mesh", d, {"moved, % diag", ColorMap::Viridis, 0.0, std::max(d.maxCoeff(), 1e-9)});
  }
  char buf[256];
  std::snprintf(buf, sizeof buf, "tetdeform report: %lld tets, %d iterations%s, volume ratio %.4f",
                static_cast<long long>(j.value("tet_mesh", nlohmann::json::object()).value("tets", 0LL)),
                j.value("iterations", 0), j.value("converged", false) ? " (converged)" : "", j.value("volume_ratio", 1.0));
  s.summary = buf;
}

void load_fit_report(Visualizer& viz, Scene& s, const nlohmann::json& j) {
  const std::string mesh_path = resolve_near(j["output"].get<std::string>(), s.path);
  const std::string cloud_path = resolve_near(j["input"]["cloud"].get<std::string>(), s.path);
  TriMesh fit;
  Eigen::MatrixX3d P;
  try {
    fit = read_mesh(mesh_path);
    P = cloud_points(cloud_path);
  } catch (const std::exception& e) {
    throw FileError(s.path + ": " + e.what() + " (the report names it; keep the fit and scan next to the report)");
  }
  const double diag = bbox_diagonal(fit.V);
  s.heat = point_mesh_distances(fit.V, fit.F, P) * (100.0 / diag);
  std::vector<double> v(s.heat.data(), s.heat.data() + s.heat.size());
  std::sort(v.begin(), v.end());
  s.heat_max = v.empty() ? 0 : v.back();
  s.heat_median = v.empty() ? 0 : v[v.size() / 2];
  // The bar spans 0 to three point spacings of the scan (the report's point_spacing): the noise
  // level of a good fit sits low on it, misfits and outliers saturate at the top colour. Without
  // a spacing in the report: 0 to the 90th percentile.
  double top = v.empty() ? 1 : v[std::min(v.size() - 1, size_t(0.9 * double(v.size())))];
  if (j.contains("metrics") && j["metrics"].contains("point_spacing") && j["metrics"]["point_spacing"].is_number() &&
      j["metrics"]["point_spacing"].get<double>() > 0)
    top = 3.0 * j["metrics"]["point_spacing"].get<double>() * 100.0 / diag;
  const double p99 = v.empty() ? 0 : v[std::min(v.size() - 1, size_t(0.99 * double(v.size())))];
  viz.addMesh(s.prefix + "fit", fit, {0.8, 0.8, 0.8});
  viz.setOpacity(s.prefix + "fit", 0.55);
  viz.addPoints(s.prefix + "scan", P, {}, 4.0);
  viz.setScalars(s.prefix + "scan", s.heat, {"scan->fit, % diag", ColorMap::Viridis, 0.0, std::max(top, 1e-9), true});
  s.heat_top = top;
  char buf[256];
  std::snprintf(buf, sizeof buf, "fit report: %lld scan points, scan -> fit median %.3f %%, p99 %.3f %%, max %.3f %% of the diagonal",
                static_cast<long long>(P.rows()), s.heat_median, p99, s.heat_max);
  s.summary = buf;
}

// How far from its centre a camera's image plane is drawn: a quarter of the rig's radius.
double image_plane_depth(const Studio& studio) {
  const auto& cams = studio.cameras;
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (const auto& c : cams) mean += c.camera.center();
  mean /= double(std::max<size_t>(1, cams.size()));
  double spread = 0;
  for (const auto& c : cams) spread = std::max(spread, (c.camera.center() - mean).norm());
  return std::max(1e-3, 0.25 * spread);
}

void load_studio(Visualizer& viz, Scene& s) {
  s.studio = read_studio(s.path);
  const auto& cams = s.studio.cameras;
  const double depth = image_plane_depth(s.studio);
  for (std::size_t k = 0; k < cams.size(); ++k) viz.addCamera(s.prefix + "camera:" + cams[k].camera.name(), cams[k].camera, depth);
  if (!s.studio.template_mesh.empty()) viz.addMesh(s.prefix + "mesh", read_mesh(s.studio.resolve(s.studio.template_mesh)));
  s.summary = "studio " + s.studio.name + ": " + std::to_string(cams.size()) + " cameras, frames " +
              std::to_string(s.studio.first_frame) + "-" + std::to_string(s.studio.last_frame);
}

}  // namespace

int Scene::numFrames() const {
  if (kind == FileKind::MeshSequence) return int(frames.size());
  if (kind == FileKind::Studio) return studio.numFrames();
  return 1;
}

FileKind classify(const std::string& path) {
  std::error_code ec;
  if (!fs::exists(path, ec)) throw FileError(path + ": no such file or folder");
  if (fs::is_directory(path, ec)) return FileKind::MeshSequence;
  const std::string e = lower_ext(path);
  if (is_mesh_ext(e)) return FileKind::Mesh;  // a PLY without faces is shown as a cloud
  if (e == ".pcd") return FileKind::Cloud;
  if (e == ".mesh") return FileKind::TetMesh;
  if (e == ".yaml" || e == ".yml") return FileKind::Studio;
  if (e == ".json") return FileKind::FitReport;
  throw FileError(path + ": tbsp-studio opens meshes (.ply .obj .off .vtk .stl), clouds (.pcd, .ply), tet meshes "
                  "(.mesh), fit reports (.json from tbsp fit --report), studios (studio.yaml) and folders of meshes");
}

Scene load_scene(Visualizer& viz, const std::string& path, const std::string& prefix) {
  Scene s;
  s.path = path;
  s.prefix = prefix;
  s.kind = classify(path);
  switch (s.kind) {
    case FileKind::Mesh: {
      TriMesh m = read_mesh(path);
      if (m.F.rows() == 0) {
        s.kind = FileKind::Cloud;
        viz.addPoints(s.prefix + "cloud", m.V, {}, 3.0);
        s.summary = path + ": " + std::to_string(m.V.rows()) + " points";
      } else {
        viz.addMesh(s.prefix + "mesh", m);
        s.summary = path + ": " + std::to_string(m.V.rows()) + " vertices, " + std::to_string(m.F.rows()) + " faces";
      }
      break;
    }
    case FileKind::Cloud: {
      const Eigen::MatrixX3d P = cloud_points(path);
      viz.addPoints(s.prefix + "cloud", P, {}, 3.0);
      s.summary = path + ": " + std::to_string(P.rows()) + " points";
      break;
    }
    case FileKind::TetMesh: {
      const TetMesh t = read_tet_mesh(path);
      viz.addTetMesh(s.prefix + "tets", t);
      s.summary = path + ": " + std::to_string(t.V.rows()) + " vertices, " + std::to_string(t.T.rows()) + " tets";
      break;
    }
    case FileKind::TetReport:      // classify() returns FitReport for every .json: the keys decide below
    case FileKind::TextureReport:
    case FileKind::FitReport: {  // any report: which one is read from its keys
      nlohmann::json j;
      try {
        std::ifstream in(path);
        j = nlohmann::json::parse(in);
      } catch (const std::exception& e) {
        throw FileError(path + ": not valid JSON (" + e.what() + ")");
      }
      const bool has_out = j.is_object() && j.contains("output") && j["output"].is_string();
      if (has_out && j.contains("input") && j["input"].is_object() && j["input"].contains("cloud")) {
        load_fit_report(viz, s, j);
      } else if (has_out && j.contains("input") && j["input"].is_object() && j["input"].contains("mesh") &&
                 j.contains("e_nonrigid")) {
        s.kind = FileKind::TetReport;
        load_tet_report(viz, s, j);
      } else if (has_out && j.contains("image") && j.contains("constraints")) {
        s.kind = FileKind::TextureReport;
        load_texture_report(viz, s, j);
      } else {
        throw FileError(path + ": not a report tbsp-studio shows (tbsp fit / tetdeform / texture --report); a handles "
                        "file is loaded into an edit (File > Open for editing, then File > Load handles)");
      }
      break;
    }
    case FileKind::Studio: load_studio(viz, s); break;
    case FileKind::MeshSequence: {
      for (const auto& e : fs::directory_iterator(path))
        if (e.is_regular_file() && is_mesh_ext(lower_ext(e.path().string()))) s.frames.push_back(e.path().string());
      std::sort(s.frames.begin(), s.frames.end());
      if (s.frames.empty())
        throw FileError(path + ": the folder holds no mesh (.ply .obj .off .vtk .stl); a sequence is one mesh per frame");
      viz.addMesh(s.prefix + "mesh", read_mesh(s.frames[0]));
      s.summary = path + ": " + std::to_string(s.frames.size()) + " frames";
      break;
    }
  }
  viz.resetCamera();
  return s;
}

std::vector<unsigned char> studio_image_rgb(const Studio& studio, int camera, int index, int* width, int* height) {
  if (camera < 0 || camera >= int(studio.cameras.size()) || studio.cameras[std::size_t(camera)].images.empty()) return {};
  const std::string p = studio.imagePath(camera, studio.first_frame + index);
  cv::Mat img = cv::imread(p, cv::IMREAD_COLOR);
  if (img.empty()) throw FileError(p + ": cannot read the image (missing or not an image) of camera " +
                                   studio.cameras[std::size_t(camera)].camera.name());
  cv::cvtColor(img, img, cv::COLOR_BGR2RGB);
  if (!img.isContinuous()) img = img.clone();
  *width = img.cols;
  *height = img.rows;
  return std::vector<unsigned char>(img.data, img.data + img.total() * 3);
}

void show_frame(Visualizer& viz, const Scene& s, int index) {
  if (index < 0 || index >= s.numFrames()) return;
  if (s.kind == FileKind::MeshSequence) {
    const TriMesh m = read_mesh(s.frames[std::size_t(index)]);
    try {
      viz.updatePositions(s.prefix + "mesh", m.V);
    } catch (const InvalidInput&) {
      viz.addMesh(s.prefix + "mesh", m);  // another connectivity: replace
    }
  } else if (s.kind == FileKind::Studio) {
    const auto& cams = s.studio.cameras;
    const double depth = image_plane_depth(s.studio);
    for (std::size_t k = 0; k < cams.size(); ++k) {
      int w = 0, h = 0;
      auto rgb = studio_image_rgb(s.studio, int(k), index, &w, &h);
      if (!rgb.empty() && w == cams[k].camera.width() && h == cams[k].camera.height())
        viz.addCamera(s.prefix + "camera:" + cams[k].camera.name(), cams[k].camera, depth, rgb);
    }
    if (!s.studio.ground_truth.empty()) {
      const std::string p = s.studio.groundTruthPath(s.studio.first_frame + index);
      if (fs::exists(p)) {
        const TriMesh m = read_mesh(p);
        if (viz.contains(s.prefix + "mesh")) {
          try { viz.updatePositions(s.prefix + "mesh", m.V); } catch (const InvalidInput&) { viz.addMesh(s.prefix + "mesh", m); }
        } else {
          viz.addMesh(s.prefix + "mesh", m);
        }
      }
    }
  }
}

}  // namespace tbsp::studio
