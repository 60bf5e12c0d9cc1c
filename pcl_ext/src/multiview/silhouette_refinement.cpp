#include "tbsp/multiview/silhouette_refinement.h"

#include <algorithm>
#include <cmath>

#include <opencv2/imgproc.hpp>

#include "tbsp/core/error.h"
#include "tbsp/core/timer.h"
#include "tbsp/deform/laplacian_deformer.h"
#include "tbsp/multiview/rasterizer.h"

namespace tbsp {

bool SilhouetteRefinementOptions::isValid(std::string* why) const {
  auto fail = [&](const std::string& m) {
    if (why) *why = m;
    return false;
  };
  if (!(weight > 0) || weight > 10) return fail("weight must be in (0, 10]");
  if (!(search_px > 0) || !std::isfinite(search_px)) return fail("search_px must be > 0");
  if (!(max_distance_px > 0) || !std::isfinite(max_distance_px)) return fail("max_distance_px must be > 0");
  if (!(max_gradient_angle_deg > 0) || max_gradient_angle_deg > 180) return fail("max_gradient_angle_deg must be in (0, 180]");
  if (max_iterations < 1 || max_iterations > 100) return fail("max_iterations must be in 1..100");
  if (!(anchor >= 0) || !std::isfinite(anchor)) return fail("anchor must be >= 0");
  return true;
}

void SilhouetteRefinement::setOptions(const SilhouetteRefinementOptions& o) {
  std::string why;
  if (!o.isValid(&why)) throw InvalidInput("[tbsp::SilhouetteRefinement::setOptions] " + why);
  options_ = o;
}

void SilhouetteRefinement::setInputFrame(std::vector<Camera> cameras, std::vector<cv::Mat> silhouettes, int frame) {
  cameras_ = std::move(cameras);
  silhouettes_ = std::move(silhouettes);
  frame_ = frame;
}

namespace {

// Smoothed mask gradient (points from background into the foreground).
void mask_gradient(const cv::Mat& mask, cv::Mat& gx, cv::Mat& gy) {
  cv::Mat f, b;
  mask.convertTo(f, CV_32F, 1.0 / 255.0);
  cv::GaussianBlur(f, b, cv::Size(5, 5), 1.2);
  cv::Sobel(b, gx, CV_32F, 1, 0, 3);
  cv::Sobel(b, gy, CV_32F, 0, 1, 3);
}

inline bool inside(const cv::Mat& m, double x, double y) {
  const int xi = static_cast<int>(std::lround(x)), yi = static_cast<int>(std::lround(y));
  if (xi < 0 || yi < 0 || xi >= m.cols || yi >= m.rows) return false;
  return m.at<std::uint8_t>(yi, xi) >= 128;
}

struct Overlap {
  long xor_px = 0;
  double iou = 0;
};
Overlap overlap(const std::vector<std::uint8_t>& rendered, const cv::Mat& input) {
  long inter = 0, uni = 0, x = 0;
  for (int y = 0; y < input.rows; ++y)
    for (int c = 0; c < input.cols; ++c) {
      const bool a = rendered[static_cast<std::size_t>(y) * input.cols + c] != 0, b = input.at<std::uint8_t>(y, c) >= 128;
      inter += a && b;
      uni += a || b;
      x += a != b;
    }
  return {x, uni ? static_cast<double>(inter) / static_cast<double>(uni) : 1.0};
}

}  // namespace

void SilhouetteRefinement::refine(TriMesh& refined) {
  const auto t0 = Clock::now();
  const SilhouetteRefinementOptions& o = options_;
  const std::string where = "[tbsp::SilhouetteRefinement] frame " + std::to_string(frame_) + ": ";
  const int n = static_cast<int>(cameras_.size());
  if (n < 1) throw InvalidInput(where + "no camera: give the calibrated views");
  if (static_cast<int>(silhouettes_.size()) != n) throw InvalidInput(where + "one silhouette per camera is needed");
  if (mesh_.V.rows() == 0 || mesh_.F.rows() == 0) throw InvalidInput(where + "the mesh is empty: set a posed mesh with setInputMesh");
  for (int k = 0; k < n; ++k) {
    const cv::Mat& s = silhouettes_[k];
    if (s.empty() || s.type() != CV_8U || s.cols != cameras_[k].width() || s.rows != cameras_[k].height())
      throw InvalidInput(where + "camera '" + cameras_[k].name() + "': the silhouette must be 8-bit and " + std::to_string(cameras_[k].width()) +
                         "x" + std::to_string(cameras_[k].height()) + " (the calibrated size)");
    if (cv::countNonZero(s >= 128) == 0)
      throw InvalidInput(where + "camera '" + cameras_[k].name() +
                         "': the silhouette is empty (no foreground pixel): it would pull the whole mesh away; fix the segmentation or leave the camera out");
  }
  std::vector<cv::Mat> igx(n), igy(n);
  for (int k = 0; k < n; ++k) mask_gradient(silhouettes_[k] >= 128, igx[k], igy[k]);
  const double cos_max = std::cos(o.max_gradient_angle_deg * M_PI / 180.0);
  RasterOptions ro;
  ro.barycentrics = false;
  const Rasterizer rast(ro);

  SilhouetteRefinementReport rep;
  rep.views.resize(n);
  TriMesh current = mesh_, best = mesh_;
  long best_xor = -1;
  std::vector<RenderBuffers> buf(n);
  auto measure = [&](const TriMesh& m, std::vector<Overlap>& ov) {
    rast.renderViews(m, cameras_, buf);
    ov.resize(n);
    long total = 0;
    for (int k = 0; k < n; ++k) {
      ov[k] = overlap(buf[k].mask, silhouettes_[k]);
      total += ov[k].xor_px;
    }
    return total;
  };
  std::vector<Overlap> ov;
  best_xor = measure(current, ov);
  bool covered = false;
  for (int k = 0; k < n && !covered; ++k) covered = std::any_of(buf[k].face.begin(), buf[k].face.end(), [](std::int32_t f) { return f >= 0; });
  if (!covered) throw InvalidInput(where + "the mesh is outside every view (no pixel covered): pose the mesh in the studio's frame first");
  rep.xor_before = best_xor;
  for (int k = 0; k < n; ++k) {
    rep.views[k].camera = cameras_[k].name();
    rep.views[k].iou_before = ov[k].iou;
    rep.views[k].xor_before = ov[k].xor_px;
  }
  std::vector<Overlap> best_ov = ov;
  int stale = 0;
  for (int it = 1; it <= o.max_iterations; ++it) {
    report_progress(progress_, (it - 1.0) / o.max_iterations, "iteration " + std::to_string(it));
    LaplacianDeformer D;
    D.setMesh(current);  // L and δ of the current mesh (§6.3.1)
    D.setAnchor(o.anchor);
    std::vector<int> per_view(n, 0);
    for (int k = 0; k < n; ++k) {
      const Camera& cam = cameras_[k];
      const RenderBuffers& b = buf[k];
      cv::Mat rmask(b.height, b.width, CV_8U, const_cast<std::uint8_t*>(b.mask.data()));
      cv::Mat rgx, rgy;
      mask_gradient(rmask, rgx, rgy);
      for (int v : rim_vertices(current, cam, b)) {
        const Eigen::Vector3d X = current.V.row(v).transpose();
        const Eigen::Vector2d p = cam.project(X);
        const int px = std::clamp(static_cast<int>(std::lround(p.x())), 0, b.width - 1), py = std::clamp(static_cast<int>(std::lround(p.y())), 0, b.height - 1);
        Eigen::Vector2d g(rgx.at<float>(py, px), rgy.at<float>(py, px));
        if (!(g.norm() > 1e-3)) continue;
        const Eigen::Vector2d nrm = -g.normalized();  // outward normal of the rendered contour
        // Nearest inside->outside crossing of the input silhouette along the normal.
        const double step = 0.5;
        double best_t = 1e9;
        for (int dir : {1, -1})
          for (double t = 0; t <= o.search_px; t += step) {
            const double a = dir * t, c = a + dir * step;
            const double lo = std::min(a, c), hi = std::max(a, c);
            const Eigen::Vector2d qa = p + lo * nrm, qb = p + hi * nrm;
            if (inside(silhouettes_[k], qa.x(), qa.y()) && !inside(silhouettes_[k], qb.x(), qb.y())) {
              const double tc = 0.5 * (lo + hi);
              if (std::abs(tc) < std::abs(best_t)) best_t = tc;
              break;
            }
          }
        if (std::abs(best_t) > o.max_distance_px) continue;
        const Eigen::Vector2d u = p + best_t * nrm;
        const int ux = std::clamp(static_cast<int>(std::lround(u.x())), 0, b.width - 1), uy = std::clamp(static_cast<int>(std::lround(u.y())), 0, b.height - 1);
        const Eigen::Vector2d gi(igx[k].at<float>(uy, ux), igy[k].at<float>(uy, ux));
        if (!(gi.norm() > 1e-3) || gi.normalized().dot(g.normalized()) < cos_max) continue;  // orientation test
        if (o.line_constraints) {
          const Ray r = cam.ray(u);
          D.addLineConstraint(SurfacePoint::atVertex(v), r.origin, r.direction, o.weight);
        } else {
          D.addPositionConstraint(SurfacePoint::atVertex(v), cam.backProject(u, cam.depth(X)), o.weight);
        }
        ++per_view[k];
      }
    }
    int total = 0;
    for (int c : per_view) total += c;
    rep.iterations = it;
    if (total == 0) break;
    TriMesh next = current;
    next.V = D.deform();
    const long x = measure(next, ov);
    for (int k = 0; k < n; ++k) rep.views[k].constraints = per_view[k];
    current = std::move(next);
    if (x < best_xor) {
      best_xor = x;
      best = current;
      best_ov = ov;
      rep.best_iteration = it;
      stale = 0;
    } else if (++stale >= 2) {
      break;  // the overlap stopped improving (§6.3.1)
    }
  }
  for (int k = 0; k < n; ++k) {
    rep.views[k].iou_after = best_ov[k].iou;
    rep.views[k].xor_after = best_ov[k].xor_px;
  }
  rep.xor_after = best_xor;
  rep.seconds = seconds_since(t0);
  report_progress(progress_, 1.0, "done");
  report_ = rep;
  refined = std::move(best);
}

}  // namespace tbsp
