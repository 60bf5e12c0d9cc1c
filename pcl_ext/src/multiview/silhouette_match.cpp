#include "silhouette_match.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "tbsp/core/error.h"

namespace tbsp::detail {

void check_silhouettes(const std::vector<Camera>& cameras, const std::vector<cv::Mat>& silhouettes, const std::string& where) {
  const std::size_t n = cameras.size();
  if (n < 1) throw InvalidInput(where + "no camera: give the calibrated views");
  if (silhouettes.size() != n)
    throw InvalidInput(where + "one silhouette per camera is needed (" + std::to_string(n) + " cameras, " + std::to_string(silhouettes.size()) +
                       " silhouettes)");
  for (std::size_t k = 0; k < n; ++k) {
    const cv::Mat& s = silhouettes[k];
    if (s.empty() || s.type() != CV_8U || s.cols != cameras[k].width() || s.rows != cameras[k].height())
      throw InvalidInput(where + "camera '" + cameras[k].name() + "': the silhouette must be 8-bit and " + std::to_string(cameras[k].width()) + "x" +
                         std::to_string(cameras[k].height()) + " (the calibrated size)");
    if (cv::countNonZero(s >= 128) == 0)
      throw InvalidInput(where + "camera '" + cameras[k].name() +
                         "': the silhouette is empty (no foreground pixel): it would pull the whole mesh away; fix the segmentation or leave the camera out");
  }
}

namespace {
// OpenCV's default border, reflect-101: -1 -> 1, n -> n - 2.
inline int reflect101(int i, int n) {
  if (n == 1) return 0;
  while (i < 0 || i >= n) i = i < 0 ? -i : 2 * (n - 1) - i;
  return i;
}
// The 5-tap Gaussian of σ 1.2 (cv::getGaussianKernel's weights).
struct Gauss5 {
  double w[5];
  Gauss5() {
    double s = 0;
    for (int i = 0; i < 5; ++i) s += w[i] = std::exp(-(i - 2) * (i - 2) / (2 * 1.2 * 1.2));
    for (double& v : w) v /= s;
  }
};
}  // namespace

Eigen::Vector2d mask_gradient_at(const cv::Mat& mask, int x, int y) {
  const int W = mask.cols, H = mask.rows;
  if (x < 0 || y < 0 || x >= W || y >= H) return Eigen::Vector2d::Zero();
  static const Gauss5 g;
  // the blurred mask (0..1) on the 3x3 neighbourhood the Sobel reads, each from its 5x5
  // neighbourhood; indices reflected at each stage as the whole-image filters do
  double b[3][3];
  for (int dy = -1; dy <= 1; ++dy)
    for (int dx = -1; dx <= 1; ++dx) {
      const int cx = reflect101(x + dx, W), cy = reflect101(y + dy, H);
      double v = 0;
      for (int i = 0; i < 5; ++i) {
        const std::uint8_t* row = mask.ptr<std::uint8_t>(reflect101(cy + i - 2, H));
        double r = 0;
        for (int j = 0; j < 5; ++j) r += g.w[j] * row[reflect101(cx + j - 2, W)];
        v += g.w[i] * r;
      }
      b[dy + 1][dx + 1] = v / 255.0;
    }
  const double gx = (b[0][2] - b[0][0]) + 2 * (b[1][2] - b[1][0]) + (b[2][2] - b[2][0]);
  const double gy = (b[2][0] - b[0][0]) + 2 * (b[2][1] - b[0][1]) + (b[2][2] - b[0][2]);
  return {gx, gy};
}

SilhouetteOverlap silhouette_overlap(const std::vector<std::uint8_t>& rendered, const cv::Mat& input) {
  long inter = 0, uni = 0, x = 0;
  for (int y = 0; y < input.rows; ++y) {
    const std::uint8_t* in = input.ptr<std::uint8_t>(y);
    const std::uint8_t* r = rendered.data() + static_cast<std::size_t>(y) * input.cols;
    for (int c = 0; c < input.cols; ++c) {
      const bool a = r[c] != 0, b = in[c] >= 128;
      inter += a && b;
      uni += a || b;
      x += a != b;
    }
  }
  return {x, uni ? static_cast<double>(inter) / static_cast<double>(uni) : 1.0};
}

SilhouetteOverlap silhouette_overlap(const RenderBuffers& r, const SilhouetteView& input) {
  // inside the box: the rendered pixels and their intersection with the input; every input
  // pixel outside the box is in the union and the XOR
  long rendered = 0, inter = 0;
  for (int y = std::max(0, r.box_y0); y <= std::min(r.height - 1, r.box_y1); ++y) {
    const std::uint8_t* in = input.mask.ptr<std::uint8_t>(y);
    const std::uint8_t* m = r.mask.data() + static_cast<std::size_t>(y) * r.width;
    for (int c = std::max(0, r.box_x0); c <= std::min(r.width - 1, r.box_x1); ++c) {
      const bool a = m[c] != 0;
      rendered += a;
      inter += a && in[c] != 0;
    }
  }
  const long uni = rendered + input.foreground - inter;
  return {uni - inter, uni ? static_cast<double>(inter) / static_cast<double>(uni) : 1.0};
}

void SilhouetteView::set(const cv::Mat& silhouette) {
  mask = silhouette >= 128;
  foreground = cv::countNonZero(mask);
}

namespace {
inline bool inside(const cv::Mat& m, double x, double y) {
  const int xi = static_cast<int>(std::lround(x)), yi = static_cast<int>(std::lround(y));
  if (xi < 0 || yi < 0 || xi >= m.cols || yi >= m.rows) return false;
  return m.at<std::uint8_t>(yi, xi) >= 128;
}
// Signed distance along `nrm` from `p` to the nearest inside -> outside crossing of `mask`
// (searched both ways in half-pixel steps up to `search_px`; the crossing is the middle of the
// step); NaN if none.
double nearest_crossing(const cv::Mat& mask, const Eigen::Vector2d& p, const Eigen::Vector2d& nrm, double search_px) {
  const double step = 0.5;
  double best = std::numeric_limits<double>::quiet_NaN();
  for (int dir : {1, -1})
    for (double t = 0; t <= search_px; t += step) {
      const double a = dir * t, c = a + dir * step;
      const double lo = std::min(a, c), hi = std::max(a, c);
      const Eigen::Vector2d qa = p + lo * nrm, qb = p + hi * nrm;
      if (inside(mask, qa.x(), qa.y()) && !inside(mask, qb.x(), qb.y())) {
        const double tc = 0.5 * (lo + hi);
        if (!(std::abs(tc) >= std::abs(best))) best = tc;
        break;
      }
    }
  return best;
}
}  // namespace

std::vector<RimMatch> match_rims(const TriMesh& mesh, const Camera& cam, const RenderBuffers& b, const SilhouetteView& input,
                                 const RimMatchOptions& o) {
  std::vector<RimMatch> out;
  const cv::Mat rmask(b.height, b.width, CV_8U, const_cast<std::uint8_t*>(b.mask.data()));
  for (int v : rim_vertices(mesh, cam, b)) {
    const Eigen::Vector3d X = mesh.V.row(v).transpose();
    const Eigen::Vector2d p = cam.project(X);
    const int px = std::clamp(static_cast<int>(std::lround(p.x())), 0, b.width - 1), py = std::clamp(static_cast<int>(std::lround(p.y())), 0, b.height - 1);
    const Eigen::Vector2d g = mask_gradient_at(rmask, px, py);
    if (!(g.norm() > 1e-3)) continue;
    const Eigen::Vector2d nrm = -g.normalized();  // outward normal of the rendered contour
    // Nearest inside->outside crossing of the input silhouette along the normal, measured against
    // the same crossing of the rendered silhouette: both masks are sampled at pixel centres, so
    // their difference is the contour's displacement, while the vertex itself can project up
    // to a pixel inside its own rendered contour (a polyhedral contour generator zigzags); the
    // vertex alone against the input contour pushed an exact template outwards by 0.3 px.
    const double t_in = nearest_crossing(input.mask, p, nrm, o.search_px);
    if (!std::isfinite(t_in)) continue;
    const double t_r = nearest_crossing(rmask, p, nrm, 2.0);
    if (!std::isfinite(t_r)) continue;  // not on the rendered contour: a hidden turn of the contour generator
    const double shift = t_in - t_r;
    if (std::abs(shift) > o.max_distance_px) continue;
    const Eigen::Vector2d c = p + t_in * nrm;  // the input contour point, for the orientation test
    const int ux = std::clamp(static_cast<int>(std::lround(c.x())), 0, b.width - 1), uy = std::clamp(static_cast<int>(std::lround(c.y())), 0, b.height - 1);
    const Eigen::Vector2d gi = mask_gradient_at(input.mask, ux, uy);
    if (!(gi.norm() > 1e-3) || gi.normalized().dot(g.normalized()) < o.cos_max) continue;  // orientation test
    const Eigen::Vector2d u = p + shift * nrm;
    out.push_back({v, u, std::abs(shift), gi.normalized()});
  }
  return out;
}

}  // namespace tbsp::detail
