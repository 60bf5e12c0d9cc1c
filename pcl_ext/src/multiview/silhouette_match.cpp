#include "silhouette_match.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include <opencv2/imgproc.hpp>

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

void mask_gradient(const cv::Mat& mask, cv::Mat& gx, cv::Mat& gy) {
  cv::Mat f, b;
  mask.convertTo(f, CV_32F, 1.0 / 255.0);
  cv::GaussianBlur(f, b, cv::Size(5, 5), 1.2);
  cv::Sobel(b, gx, CV_32F, 1, 0, 3);
  cv::Sobel(b, gy, CV_32F, 0, 1, 3);
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

void SilhouetteView::set(const cv::Mat& silhouette) {
  mask = silhouette >= 128;
  mask_gradient(mask, gx, gy);
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
  cv::Mat rmask(b.height, b.width, CV_8U, const_cast<std::uint8_t*>(b.mask.data()));
  cv::Mat rgx, rgy;
  mask_gradient(rmask, rgx, rgy);
  for (int v : rim_vertices(mesh, cam, b)) {
    const Eigen::Vector3d X = mesh.V.row(v).transpose();
    const Eigen::Vector2d p = cam.project(X);
    const int px = std::clamp(static_cast<int>(std::lround(p.x())), 0, b.width - 1), py = std::clamp(static_cast<int>(std::lround(p.y())), 0, b.height - 1);
    Eigen::Vector2d g(rgx.at<float>(py, px), rgy.at<float>(py, px));
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
    const Eigen::Vector2d gi(input.gx.at<float>(uy, ux), input.gy.at<float>(uy, ux));
    if (!(gi.norm() > 1e-3) || gi.normalized().dot(g.normalized()) < o.cos_max) continue;  // orientation test
    const Eigen::Vector2d u = p + shift * nrm;
    out.push_back({v, u, std::abs(shift), gi.normalized()});
  }
  return out;
}

}  // namespace tbsp::detail
