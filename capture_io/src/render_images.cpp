#include "tbsp/io/render_images.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <string>

#include "tbsp/core/error.h"

namespace tbsp {

cv::Mat mask_image(const RenderBuffers& b) {
  cv::Mat m(b.height, b.width, CV_8UC1);
  std::copy(b.mask.begin(), b.mask.end(), m.ptr<std::uint8_t>());
  return m;
}

cv::Mat depth_image(const RenderBuffers& b) {
  cv::Mat m(b.height, b.width, CV_32FC1);
  std::copy(b.depth.begin(), b.depth.end(), m.ptr<float>());
  return m;
}

namespace {
void require_bary(const RenderBuffers& b, const TriMesh& mesh, const char* who) {
  if (b.bary.size() != 2 * b.face.size())
    throw InvalidInput(std::string("[tbsp::") + who + "] the buffers have no barycentrics; render with RasterOptions::barycentrics = true");
  for (std::int32_t f : b.face)
    if (f >= mesh.F.rows())
      throw InvalidInput(std::string("[tbsp::") + who + "] the buffers were rendered from a different mesh (face id " +
                         std::to_string(f) + " >= " + std::to_string(mesh.F.rows()) + ")");
}
// Calls fn(row, x, face, b0, b1, b2) for every covered pixel; returns the image (background elsewhere).
template <typename Fn>
cv::Mat shade_covered(const RenderBuffers& b, const cv::Vec3b& background, Fn&& fn) {
  cv::Mat img(b.height, b.width, CV_8UC3, background);
  for (int y = 0; y < b.height; ++y) {
    auto* row = img.ptr<cv::Vec3b>(y);
    for (int x = 0; x < b.width; ++x) {
      const std::size_t idx = static_cast<std::size_t>(y) * b.width + x;
      const std::int32_t f = b.face[idx];
      if (f < 0) continue;
      const double b1 = b.bary[2 * idx], b2 = b.bary[2 * idx + 1];
      row[x] = fn(f, 1 - b1 - b2, b1, b2);
    }
  }
  return img;
}
cv::Vec3b to_bgr(const Eigen::Vector3d& rgb) {
  auto c = [](double v) { return static_cast<std::uint8_t>(std::lround(std::clamp(v, 0.0, 1.0) * 255.0)); };
  return {c(rgb.z()), c(rgb.y()), c(rgb.x())};
}
}  // namespace

cv::Mat shade_vertex_colors(const TriMesh& mesh, const RenderBuffers& b, const cv::Vec3b& background) {
  require_bary(b, mesh, "shade_vertex_colors");
  if (mesh.C.rows() != mesh.V.rows() || mesh.C.cols() != 3)
    throw InvalidInput("[tbsp::shade_vertex_colors] the mesh has no per-vertex colours (C is " +
                       std::to_string(mesh.C.rows()) + "x" + std::to_string(mesh.C.cols()) + ")");
  return shade_covered(b, background, [&](int f, double b0, double b1, double b2) {
    return to_bgr(b0 * mesh.C.row(mesh.F(f, 0)).transpose() + b1 * mesh.C.row(mesh.F(f, 1)).transpose() +
                  b2 * mesh.C.row(mesh.F(f, 2)).transpose());
  });
}

cv::Mat shade_texture(const TriMesh& mesh, const Eigen::MatrixX2d& uv, const cv::Mat& tex, const RenderBuffers& b,
                      const cv::Vec3b& background) {
  require_bary(b, mesh, "shade_texture");
  if (uv.rows() != mesh.V.rows())
    throw InvalidInput("[tbsp::shade_texture] " + std::to_string(uv.rows()) + " texture coordinates for " +
                       std::to_string(mesh.V.rows()) + " vertices; give one (u, v) per vertex");
  if (tex.empty() || tex.type() != CV_8UC3)
    throw InvalidInput("[tbsp::shade_texture] the texture must be a non-empty 8-bit 3-channel image");
  const int TW = tex.cols, TH = tex.rows;
  auto at = [&](int xx, int yy) -> const cv::Vec3b& {
    xx = ((xx % TW) + TW) % TW;
    yy = ((yy % TH) + TH) % TH;
    return tex.at<cv::Vec3b>(yy, xx);
  };
  return shade_covered(b, background, [&](int f, double b0, double b1, double b2) {
    const Eigen::Vector2d t = b0 * uv.row(mesh.F(f, 0)).transpose() + b1 * uv.row(mesh.F(f, 1)).transpose() +
                              b2 * uv.row(mesh.F(f, 2)).transpose();
    const double u = t.x() - std::floor(t.x()), v = t.y() - std::floor(t.y());
    const double tx = u * TW - 0.5, ty = (1.0 - v) * TH - 0.5;
    const int x0 = static_cast<int>(std::floor(tx)), y0 = static_cast<int>(std::floor(ty));
    const double fx = tx - x0, fy = ty - y0;
    cv::Vec3b o;
    for (int ch = 0; ch < 3; ++ch) {
      const double val = (1 - fx) * (1 - fy) * at(x0, y0)[ch] + fx * (1 - fy) * at(x0 + 1, y0)[ch] +
                         (1 - fx) * fy * at(x0, y0 + 1)[ch] + fx * fy * at(x0 + 1, y0 + 1)[ch];
      o[ch] = static_cast<std::uint8_t>(std::lround(std::clamp(val, 0.0, 255.0)));
    }
    return o;
  });
}

}  // namespace tbsp
