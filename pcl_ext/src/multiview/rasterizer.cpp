#include "tbsp/multiview/rasterizer.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "tbsp/core/error.h"

namespace tbsp {

namespace {

struct Projected {
  std::vector<double> x, y, iz;  // screen position and 1/z per vertex
  std::vector<char> ok;          // z > near
};

Projected project_vertices(const TriMesh& mesh, const Camera& cam, double near_plane) {
  const Eigen::Index n = mesh.V.rows();
  Projected p;
  p.x.resize(n);
  p.y.resize(n);
  p.iz.resize(n);
  p.ok.resize(n);
  for (Eigen::Index i = 0; i < n; ++i) {
    const Eigen::Vector3d X = mesh.V.row(i).transpose();
    const double z = cam.depth(X);
    p.ok[i] = z > near_plane;
    if (!p.ok[i]) {
      p.x[i] = p.y[i] = p.iz[i] = 0;
      continue;
    }
    const Eigen::Vector2d s = cam.project(X);
    p.x[i] = s.x();
    p.y[i] = s.y();
    p.iz[i] = 1.0 / z;
  }
  return p;
}

inline double edge(double ax, double ay, double bx, double by, double px, double py) {
  return (bx - ax) * (py - ay) - (by - ay) * (px - ax);
}
// Perspective-correct barycentrics (b1, b2) at pixel (x, y) of a triangle projected to
// (px, py) with inverse depths iz: the barycentric pass of renderChecked and pixel_barycentrics.
inline void perspective_barycentrics(const double px[3], const double py[3], const double iz[3], double x, double y, double& b1,
                                     double& b2) {
  const double area = edge(px[0], py[0], px[1], py[1], px[2], py[2]);
  const double l0 = edge(px[1], py[1], px[2], py[2], x, y) / area;
  const double l1 = edge(px[2], py[2], px[0], py[0], x, y) / area;
  const double l2 = 1.0 - l0 - l1;
  const double q0 = l0 * iz[0], q1 = l1 * iz[1], q2 = l2 * iz[2];
  const double s = q0 + q1 + q2;
  b1 = q1 / s;
  b2 = q2 / s;
}
inline bool top_left(double ax, double ay, double bx, double by) {
  return (ay == by && bx > ax) || (by < ay);
}

void check_mesh(const TriMesh& mesh, const char* who) {
  if (mesh.V.rows() == 0 || mesh.F.rows() == 0)
    throw InvalidInput(std::string("[tbsp::") + who + "] the mesh is empty (" + std::to_string(mesh.V.rows()) +
                       " vertices, " + std::to_string(mesh.F.rows()) + " faces)");
  const int n = static_cast<int>(mesh.V.rows());
  for (Eigen::Index f = 0; f < mesh.F.rows(); ++f)
    for (int k = 0; k < 3; ++k)
      if (mesh.F(f, k) < 0 || mesh.F(f, k) >= n)
        throw InvalidInput(std::string("[tbsp::") + who + "] face " + std::to_string(f) + " references vertex " +
                           std::to_string(mesh.F(f, k)) + " but the mesh has " + std::to_string(n) +
                           " vertices; run `tbsp validate` on the mesh");
  if (!mesh.V.allFinite()) throw InvalidInput(std::string("[tbsp::") + who + "] the mesh has NaN/Inf vertex coordinates");
}

// Empties `out` for a W x H render: buffers of another size (or fresh ones) are filled whole;
// buffers of this size are reset only inside the box the previous render covered (the render
// then sets the box anew).
void reset_buffers(RenderBuffers& out, int W, int H, bool bary) {
  const std::size_t npix = static_cast<std::size_t>(W) * H;
  const float inf = std::numeric_limits<float>::infinity();
  const bool reuse = out.width == W && out.height == H && out.depth.size() == npix && out.face.size() == npix &&
                     out.mask.size() == npix && (!bary || out.bary.size() == 2 * npix);
  if (!bary) out.bary.clear();
  out.width = W;
  out.height = H;
  out.skipped_near = 0;
  if (!reuse) {
    out.depth.assign(npix, inf);
    out.face.assign(npix, -1);
    out.mask.assign(npix, 0);
    if (bary) out.bary.assign(2 * npix, 0.0f);
  } else {
    const int x0 = std::max(0, out.box_x0), x1 = std::min(W - 1, out.box_x1);
    const int y0 = std::max(0, out.box_y0), y1 = std::min(H - 1, out.box_y1);
    if (x0 <= x1) {
      const std::size_t len = static_cast<std::size_t>(x1 - x0 + 1);
      for (int y = y0; y <= y1; ++y) {
        const std::size_t i = static_cast<std::size_t>(y) * W + x0;
        std::fill_n(out.depth.begin() + std::ptrdiff_t(i), len, inf);
        std::fill_n(out.face.begin() + std::ptrdiff_t(i), len, -1);
        std::fill_n(out.mask.begin() + std::ptrdiff_t(i), len, std::uint8_t(0));
        if (bary) std::fill_n(out.bary.begin() + std::ptrdiff_t(2 * i), 2 * len, 0.0f);
      }
    }
  }
}
}  // namespace

void Rasterizer::render(const TriMesh& mesh, const Camera& cam, RenderBuffers& out) const {
  check_mesh(mesh, "Rasterizer::render");
  renderChecked(mesh, cam, out);
}

void Rasterizer::renderChecked(const TriMesh& mesh, const Camera& cam, RenderBuffers& out) const {
  const int W = cam.width(), H = cam.height();
  reset_buffers(out, W, H, options_.barycentrics);
  const Projected p = project_vertices(mesh, cam, options_.near_plane);
  const Eigen::Vector3d c = cam.center();
  int cover_x0 = W, cover_x1 = -1, cover_y0 = H, cover_y1 = -1;

  for (Eigen::Index f = 0; f < mesh.F.rows(); ++f) {
    int i0 = mesh.F(f, 0), i1 = mesh.F(f, 1), i2 = mesh.F(f, 2);
    if (!p.ok[i0] || !p.ok[i1] || !p.ok[i2]) {
      ++out.skipped_near;
      continue;
    }
    if (options_.cull_backfaces) {
      const Eigen::Vector3d a = mesh.V.row(i0), b = mesh.V.row(i1), d = mesh.V.row(i2);
      if ((b - a).cross(d - a).dot(c - a) <= 0) continue;
    }
    double area = edge(p.x[i0], p.y[i0], p.x[i1], p.y[i1], p.x[i2], p.y[i2]);
    if (area == 0 || !std::isfinite(area)) continue;
    if (area < 0) {
      std::swap(i1, i2);
      area = -area;
    }
    const double x0 = p.x[i0], y0 = p.y[i0], x1 = p.x[i1], y1 = p.y[i1], x2 = p.x[i2], y2 = p.y[i2];
    const int xmin = std::max(0, static_cast<int>(std::ceil(std::min({x0, x1, x2}))));
    const int xmax = std::min(W - 1, static_cast<int>(std::floor(std::max({x0, x1, x2}))));
    const int ymin = std::max(0, static_cast<int>(std::ceil(std::min({y0, y1, y2}))));
    const int ymax = std::min(H - 1, static_cast<int>(std::floor(std::max({y0, y1, y2}))));
    if (xmin > xmax || ymin > ymax) continue;
    const bool tl0 = top_left(x1, y1, x2, y2), tl1 = top_left(x2, y2, x0, y0), tl2 = top_left(x0, y0, x1, y1);
    const double inv_area = 1.0 / area;
    const double iz0 = p.iz[i0] * inv_area, iz1 = p.iz[i1] * inv_area, iz2 = p.iz[i2] * inv_area;
    // Edge-function steps per pixel in x.
    const double a0 = -(y2 - y1), a1 = -(y0 - y2), a2 = -(y1 - y0);
    const std::int32_t fid = static_cast<std::int32_t>(f);
    for (int y = ymin; y <= ymax; ++y) {
      const double e0 = edge(x1, y1, x2, y2, xmin, y);
      const double e1 = edge(x2, y2, x0, y0, xmin, y);
      const double e2 = edge(x0, y0, x1, y1, xmin, y);
      // Span of x where all three edge functions are >= 0 (one pixel of slack each side; the
      // exact test with the fill rule decides inside the span).
      double lo = xmin, hi = xmax;
      auto clip = [&](double e, double a) {
        if (a > 0) lo = std::max(lo, xmin + std::floor(-e / a) - 1);
        else if (a < 0) hi = std::min(hi, xmin + std::ceil(e / -a) + 1);
        else if (e < 0) hi = lo - 1;
      };
      clip(e0, a0);
      clip(e1, a1);
      clip(e2, a2);
      if (lo > hi) continue;
      const int xs = static_cast<int>(lo), xe = static_cast<int>(hi);
      double w0 = e0 + a0 * (xs - xmin), w1 = e1 + a1 * (xs - xmin), w2 = e2 + a2 * (xs - xmin);
      const std::size_t row = static_cast<std::size_t>(y) * W;
      float* drow = out.depth.data() + row;
      std::int32_t* frow = out.face.data() + row;
      std::uint8_t* mrow = out.mask.data() + row;
      for (int x = xs; x <= xe; ++x, w0 += a0, w1 += a1, w2 += a2) {
        const bool in0 = w0 > 0 || (w0 == 0 && tl0);
        const bool in1 = w1 > 0 || (w1 == 0 && tl1);
        const bool in2 = w2 > 0 || (w2 == 0 && tl2);
        if (!(in0 && in1 && in2)) continue;
        const double iz = w0 * iz0 + w1 * iz1 + w2 * iz2;  // 1/z, perspective-correct
        if (iz * drow[x] > 1.0) {                          // z < stored depth (inf passes)
          drow[x] = static_cast<float>(1.0 / iz);
          frow[x] = fid;
          mrow[x] = 255;
          cover_x0 = std::min(cover_x0, x);
          cover_x1 = std::max(cover_x1, x);
          cover_y0 = std::min(cover_y0, y);
          cover_y1 = std::max(cover_y1, y);
        }
      }
    }
  }

  out.box_x0 = cover_x0;
  out.box_x1 = cover_x1;
  out.box_y0 = cover_y0;
  out.box_y1 = cover_y1;
  // Barycentrics of the visible triangle at each covered pixel centre.
  if (!options_.barycentrics) return;
  for (int y = cover_y0; y <= cover_y1; ++y) {
    for (int x = cover_x0; x <= cover_x1; ++x) {
      const std::size_t idx = static_cast<std::size_t>(y) * W + x;
      const std::int32_t f = out.face[idx];
      if (f < 0) continue;
      const int i0 = mesh.F(f, 0), i1 = mesh.F(f, 1), i2 = mesh.F(f, 2);
      const double px[3] = {p.x[i0], p.x[i1], p.x[i2]}, py[3] = {p.y[i0], p.y[i1], p.y[i2]}, iz[3] = {p.iz[i0], p.iz[i1], p.iz[i2]};
      double b1 = 0, b2 = 0;
      perspective_barycentrics(px, py, iz, x, y, b1, b2);
      out.bary[2 * idx] = static_cast<float>(b1);
      out.bary[2 * idx + 1] = static_cast<float>(b2);
    }
  }
}

namespace {
// The projected corners (px, py) and inverse depths of `face` in `cam`; throws what
// pixel_barycentrics documents.
void project_face(const TriMesh& mesh, const Camera& cam, int face, const char* who, double px[3], double py[3], double iz[3]) {
  if (face < 0 || face >= mesh.F.rows())
    throw InvalidInput(std::string("[tbsp::") + who + "] face " + std::to_string(face) + " is outside the mesh's " +
                       std::to_string(mesh.F.rows()) + " faces");
  for (int k = 0; k < 3; ++k) {
    const int v = mesh.F(face, k);
    if (v < 0 || v >= mesh.V.rows())
      throw InvalidInput(std::string("[tbsp::") + who + "] face " + std::to_string(face) + " references vertex " + std::to_string(v) +
                         " of " + std::to_string(mesh.V.rows()));
    const Eigen::Vector3d X = mesh.V.row(v).transpose();
    const double z = cam.depth(X);
    if (!(z > 0))
      throw InvalidInput(std::string("[tbsp::") + who + "] vertex " + std::to_string(v) + " of face " + std::to_string(face) +
                         " is not in front of the camera: the face is never rendered");
    const Eigen::Vector2d s = cam.project(X);  // as project_vertices
    px[k] = s.x();
    py[k] = s.y();
    iz[k] = 1.0 / z;
  }
}
}  // namespace

Eigen::Vector3d pixel_barycentrics(const TriMesh& mesh, const Camera& cam, int face, int x, int y) {
  double px[3], py[3], iz[3];
  project_face(mesh, cam, face, "pixel_barycentrics", px, py, iz);
  double b1 = 0, b2 = 0;
  perspective_barycentrics(px, py, iz, x, y, b1, b2);
  const float f1 = static_cast<float>(b1), f2 = static_cast<float>(b2);  // as the buffer stores them
  return Eigen::Vector3d(1.0 - f1 - f2, f1, f2);
}

Eigen::Vector3d point_barycentrics(const TriMesh& mesh, const Camera& cam, int face, const Eigen::Vector2d& p) {
  double px[3], py[3], iz[3];
  project_face(mesh, cam, face, "point_barycentrics", px, py, iz);
  double b1 = 0, b2 = 0;
  perspective_barycentrics(px, py, iz, p.x(), p.y(), b1, b2);
  return Eigen::Vector3d(1.0 - b1 - b2, b1, b2);
}

void Rasterizer::renderViews(const TriMesh& mesh, const std::vector<Camera>& cameras, std::vector<RenderBuffers>& out) const {
  check_mesh(mesh, "Rasterizer::renderViews");
  out.resize(cameras.size());
#pragma omp parallel for schedule(dynamic, 1)
  for (int i = 0; i < static_cast<int>(cameras.size()); ++i) renderChecked(mesh, cameras[i], out[i]);
}

std::vector<RenderBuffers> Rasterizer::renderViews(const TriMesh& mesh, const std::vector<Camera>& cameras) const {
  std::vector<RenderBuffers> out;
  renderViews(mesh, cameras, out);
  return out;
}

std::vector<int> rim_vertices(const TriMesh& mesh, const Camera& cam, const RenderBuffers& b, double tol) {
  check_mesh(mesh, "rim_vertices");
  if (b.width != cam.width() || b.height != cam.height() || b.face.size() != static_cast<std::size_t>(b.width) * b.height)
    throw InvalidInput("[tbsp::rim_vertices] the buffers do not match the camera size; render this camera first");
  const Eigen::Index n = mesh.V.rows();
  const Eigen::Vector3d c = cam.center();
  std::vector<char> front(n, 0), back(n, 0);
  for (Eigen::Index f = 0; f < mesh.F.rows(); ++f) {
    const Eigen::Vector3d a = mesh.V.row(mesh.F(f, 0)), bb = mesh.V.row(mesh.F(f, 1)), d = mesh.V.row(mesh.F(f, 2));
    const double s = (bb - a).cross(d - a).dot(c - a);
    auto& flag = s > 0 ? front : back;
    for (int k = 0; k < 3; ++k) flag[mesh.F(f, k)] = 1;
  }
  const int W = b.width, H = b.height;
  auto border = [&](int x, int y) {
    if (b.face[static_cast<std::size_t>(y) * W + x] < 0) return false;
    if (x == 0 || y == 0 || x == W - 1 || y == H - 1) return true;
    const std::size_t i = static_cast<std::size_t>(y) * W + x;
    return b.face[i - 1] < 0 || b.face[i + 1] < 0 || b.face[i - W] < 0 || b.face[i + W] < 0;
  };
  const double slack = 0.05 * bbox_diagonal(mesh.V);
  const int r = static_cast<int>(std::ceil(tol));
  std::vector<int> rim;
  for (Eigen::Index v = 0; v < n; ++v) {
    if (!front[v] || !back[v]) continue;
    const Eigen::Vector3d X = mesh.V.row(v).transpose();
    const double z = cam.depth(X);
    if (!(z > 0)) continue;
    const Eigen::Vector2d px = cam.project(X);
    const int cx = static_cast<int>(std::lround(px.x())), cy = static_cast<int>(std::lround(px.y()));
    bool found = false;
    for (int y = std::max(0, cy - r); y <= std::min(H - 1, cy + r) && !found; ++y)
      for (int x = std::max(0, cx - r); x <= std::min(W - 1, cx + r) && !found; ++x) {
        if ((Eigen::Vector2d(x, y) - px).norm() > tol + 0.5) continue;
        if (!border(x, y)) continue;
        if (b.depth[static_cast<std::size_t>(y) * W + x] + slack < z) continue;  // hidden behind nearer surface
        found = true;
      }
    if (found) rim.push_back(static_cast<int>(v));
  }
  return rim;
}

}  // namespace tbsp
