#include "tbsp/plugins/texture_preview.h"

#include <Eigen/Geometry>

#include <algorithm>
#include <cmath>
#include <opencv2/imgcodecs.hpp>

#include "tbsp/core/error.h"
#include "tbsp/plugins/preview_render.h"

namespace tbsp {

namespace {
/// A rotation that looks at the textured part head-on with the image's "up" pointing up: the
/// view direction is the area-weighted mean normal of the faces with texture coordinates, up is
/// the mean 3D direction of decreasing pixel y on the deformed image surface.
Eigen::Matrix3d preview_rotation(const TriMesh& m, const Eigen::MatrixX2d& uv, const TextureMappingResult& r) {
  Eigen::Vector3d view = Eigen::Vector3d::Zero(), up = Eigen::Vector3d::Zero();
  for (Eigen::Index f = 0; f < m.F.rows(); ++f) {
    const int a = m.F(f, 0), b = m.F(f, 1), c = m.F(f, 2);
    if (!(uv.row(a).allFinite() && uv.row(b).allFinite() && uv.row(c).allFinite())) continue;
    view += (m.V.row(b) - m.V.row(a)).cross(m.V.row(c) - m.V.row(a)).transpose();
  }
  for (int j = 1; j < r.grid_height; ++j)
    for (int i = 0; i < r.grid_width; ++i) {
      const int p = r.node_index[static_cast<std::size_t>(j) * r.grid_width + i], q = r.node_index[static_cast<std::size_t>(j - 1) * r.grid_width + i];
      if (p >= 0 && q >= 0) up += (r.surface.row(q) - r.surface.row(p)).transpose();
    }
  if (!(view.norm() > 0)) view = Eigen::Vector3d::UnitZ();
  view.normalize();
  up -= up.dot(view) * view;
  if (!(up.norm() > 1e-12 * (1 + up.norm()))) up = view.unitOrthogonal();
  up.normalize();
  Eigen::Matrix3d R;
  R.row(0) = up.cross(view).transpose();
  R.row(1) = up.transpose();
  R.row(2) = view.transpose();
  return R;
}

}  // namespace

Eigen::RowVector3d RgbImage::at(double x, double y) const {
  if (width <= 0 || height <= 0) return Eigen::RowVector3d(0.5, 0.5, 0.5);
  x = std::clamp(x, 0.0, width - 1.0);
  y = std::clamp(y, 0.0, height - 1.0);
  const int x0 = std::min(static_cast<int>(x), std::max(0, width - 2)), y0 = std::min(static_cast<int>(y), std::max(0, height - 2));
  const int x1 = std::min(x0 + 1, width - 1), y1 = std::min(y0 + 1, height - 1);
  const double fx = x - x0, fy = y - y0;
  Eigen::RowVector3d c = Eigen::RowVector3d::Zero();
  const int xs[2] = {x0, x1}, ys[2] = {y0, y1};
  const double wx[2] = {1 - fx, fx}, wy[2] = {1 - fy, fy};
  for (int a = 0; a < 2; ++a)
    for (int b = 0; b < 2; ++b) {
      const std::uint8_t* p = &rgb[(static_cast<std::size_t>(ys[b]) * width + xs[a]) * 3];
      c += wx[a] * wy[b] * Eigen::RowVector3d(p[0], p[1], p[2]) / 255.0;
    }
  return c;
}

RgbImage read_rgb_image(const std::string& path) {
  cv::Mat img;
  try {
    img = cv::imread(path, cv::IMREAD_COLOR);
  } catch (const cv::Exception& e) {
    throw FileError("'" + path + "': cannot read the image: " + e.what());
  }
  if (img.empty()) throw FileError("'" + path + "': cannot read the image (not an image OpenCV can decode: use PNG or JPEG)");
  RgbImage out;
  out.width = img.cols;
  out.height = img.rows;
  out.rgb.resize(static_cast<std::size_t>(img.cols) * img.rows * 3);
  for (int y = 0; y < img.rows; ++y)
    for (int x = 0; x < img.cols; ++x) {
      const cv::Vec3b p = img.at<cv::Vec3b>(y, x);
      std::uint8_t* q = &out.rgb[(static_cast<std::size_t>(y) * img.cols + x) * 3];
      q[0] = p[2];
      q[1] = p[1];
      q[2] = p[0];
    }
  return out;
}

RgbImage checkerboard_image(int width, int height, int cell) {
  if (width < 1 || height < 1 || cell < 1) throw InvalidInput("[tbsp::checkerboard_image] width, height and cell must be >= 1");
  RgbImage out;
  out.width = width;
  out.height = height;
  out.rgb.resize(static_cast<std::size_t>(width) * height * 3);
  for (int y = 0; y < height; ++y)
    for (int x = 0; x < width; ++x) {
      const bool dark = ((x / cell) + (y / cell)) % 2 == 1;
      const double f = dark ? 0.55 : 1.0;
      std::uint8_t* q = &out.rgb[(static_cast<std::size_t>(y) * width + x) * 3];
      q[0] = static_cast<std::uint8_t>(std::lround(f * (40 + 215.0 * x / std::max(1, width - 1))));
      q[1] = static_cast<std::uint8_t>(std::lround(f * 200));
      q[2] = static_cast<std::uint8_t>(std::lround(f * (40 + 215.0 * y / std::max(1, height - 1))));
    }
  return out;
}

TriMesh textured_preview_mesh(const TriMesh& m, const Eigen::MatrixX2d& uv, const RgbImage& img, long max_faces) {
  long textured = 0;
  for (Eigen::Index f = 0; f < m.F.rows(); ++f)
    if (uv.row(m.F(f, 0)).allFinite() && uv.row(m.F(f, 1)).allFinite() && uv.row(m.F(f, 2)).allFinite()) ++textured;
  const int n = std::max(1, static_cast<int>(std::sqrt(static_cast<double>(max_faces) / std::max(1L, textured))));
  std::vector<Eigen::RowVector3d> V, C;
  std::vector<Eigen::RowVector3i> F;
  for (Eigen::Index f = 0; f < m.F.rows(); ++f) {
    const int a = m.F(f, 0), b = m.F(f, 1), c = m.F(f, 2);
    const bool has_uv = uv.row(a).allFinite() && uv.row(b).allFinite() && uv.row(c).allFinite();
    const int nn = has_uv ? n : 1;
    // Lattice points (i, j), i + j <= nn, barycentric (1 - (i+j)/nn, i/nn, j/nn).
    auto id = [nn](int i, int j) { return j * (nn + 1) - j * (j - 1) / 2 + i; };
    const int base = static_cast<int>(V.size());
    for (int j = 0; j <= nn; ++j)
      for (int i = 0; i + j <= nn; ++i) {
        const double wb = static_cast<double>(i) / nn, wc = static_cast<double>(j) / nn, wa = 1 - wb - wc;
        V.push_back(wa * m.V.row(a) + wb * m.V.row(b) + wc * m.V.row(c));
        if (has_uv) {
          const Eigen::RowVector2d t = wa * uv.row(a) + wb * uv.row(b) + wc * uv.row(c);
          C.push_back(img.at(t.x(), t.y()));
        } else {
          C.emplace_back(0.5, 0.5, 0.5);
        }
      }
    for (int j = 0; j < nn; ++j)
      for (int i = 0; i + j < nn; ++i) {
        F.emplace_back(base + id(i, j), base + id(i + 1, j), base + id(i, j + 1));
        if (i + j + 1 < nn) F.emplace_back(base + id(i + 1, j), base + id(i + 1, j + 1), base + id(i, j + 1));
      }
  }
  TriMesh out;
  out.V.resize(static_cast<Eigen::Index>(V.size()), 3);
  out.C.resize(static_cast<Eigen::Index>(C.size()), 3);
  out.F.resize(static_cast<Eigen::Index>(F.size()), 3);
  for (std::size_t i = 0; i < V.size(); ++i) {
    out.V.row(static_cast<Eigen::Index>(i)) = V[i];
    out.C.row(static_cast<Eigen::Index>(i)) = C[i];
  }
  for (std::size_t i = 0; i < F.size(); ++i) out.F.row(static_cast<Eigen::Index>(i)) = F[i];
  return out;
}


void render_texture_result_png(const std::string& path, const TriMesh& mesh, const TextureMappingResult& r, const RgbImage& img, int panel_size) {
  const Eigen::Matrix3d R = preview_rotation(mesh, r.uv, r);
  RenderPanel p1, p2;
  p1.mesh = textured_preview_mesh(mesh, r.uv, img, 400000);
  p1.mesh.V = p1.mesh.V * R.transpose();
  p1.title = "textured mesh (" + std::to_string(static_cast<int>(100 * r.report.matched_fraction + 0.5)) + "% of vertices matched, grey: none)";
  p2.mesh.V = r.surface * R.transpose();
  p2.mesh.F = r.surface_faces;
  p2.mesh.C.resize(r.surface.rows(), 3);
  for (Eigen::Index a = 0; a < r.surface.rows(); ++a) p2.mesh.C.row(a) = img.at(r.node_pixel(a, 0), r.node_pixel(a, 1));
  p2.title = "deformed image surface";
  RenderOptions ro;
  ro.azimuth_deg = 0;
  ro.elevation_deg = 0;
  ro.panel_width = ro.panel_height = panel_size;
  render_panels_png(path, {p1, p2}, ro);
}

}  // namespace tbsp
