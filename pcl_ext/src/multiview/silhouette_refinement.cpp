#include "tbsp/multiview/silhouette_refinement.h"

#include <algorithm>
#include <cmath>


#include "tbsp/core/error.h"
#include "tbsp/core/timer.h"
#include "tbsp/deform/laplacian_deformer.h"
#include "tbsp/multiview/rasterizer.h"
#include "silhouette_match.h"

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

void SilhouetteRefinement::refine(TriMesh& refined) {
  const auto t0 = Clock::now();
  const SilhouetteRefinementOptions& o = options_;
  const std::string where = "[tbsp::SilhouetteRefinement] frame " + std::to_string(frame_) + ": ";
  const int n = static_cast<int>(cameras_.size());
  if (mesh_.V.rows() == 0 || mesh_.F.rows() == 0) throw InvalidInput(where + "the mesh is empty: set a posed mesh with setInputMesh");
  detail::check_silhouettes(cameras_, silhouettes_, where);
  std::vector<detail::SilhouetteView> input(static_cast<std::size_t>(n));
  for (int k = 0; k < n; ++k) input[k].set(silhouettes_[k]);
  detail::RimMatchOptions rmo;
  rmo.search_px = o.search_px;
  rmo.max_distance_px = o.max_distance_px;
  rmo.cos_max = std::cos(o.max_gradient_angle_deg * M_PI / 180.0);
  RasterOptions ro;
  ro.barycentrics = false;
  const Rasterizer rast(ro);

  SilhouetteRefinementReport rep;
  rep.views.resize(n);
  TriMesh current = mesh_, best = mesh_;
  long best_xor = -1;
  std::vector<RenderBuffers>& buf = buffers_;
  auto measure = [&](const TriMesh& m, std::vector<detail::SilhouetteOverlap>& ov) {
    rast.renderViews(m, cameras_, buf);
    ov.resize(n);
    long total = 0;
    for (int k = 0; k < n; ++k) {
      ov[k] = detail::silhouette_overlap(buf[k], input[k]);
      total += ov[k].xor_px;
    }
    return total;
  };
  std::vector<detail::SilhouetteOverlap> ov;
  best_xor = measure(current, ov);
  bool covered = false;
  for (int k = 0; k < n && !covered; ++k) covered = buf[k].box_x0 <= buf[k].box_x1;
  if (!covered) throw InvalidInput(where + "the mesh is outside every view (no pixel covered): pose the mesh in the studio's frame first");
  rep.xor_before = best_xor;
  for (int k = 0; k < n; ++k) {
    rep.views[k].camera = cameras_[k].name();
    rep.views[k].iou_before = ov[k].iou;
    rep.views[k].xor_before = ov[k].xor_px;
  }
  std::vector<detail::SilhouetteOverlap> best_ov = ov;
  int stale = 0;
  LaplacianDeformer D;
  for (int it = 1; it <= o.max_iterations; ++it) {
    report_progress(progress_, (it - 1.0) / o.max_iterations, "iteration " + std::to_string(it));
    D.clearConstraints();
    D.setMesh(current);  // L and δ of the current mesh (§6.3.1); the connectivity, so the
                         // factorization's symbolic analysis, stays: it is reused
    D.setAnchor(o.anchor);
    std::vector<int> per_view(n, 0);
    for (int k = 0; k < n; ++k) {
      const Camera& cam = cameras_[k];
      for (const detail::RimMatch& m : detail::match_rims(current, cam, buf[k], input[k], rmo)) {
        if (o.line_constraints) {
          const Ray r = cam.ray(m.pixel);
          D.addLineConstraint(SurfacePoint::atVertex(m.vertex), r.origin, r.direction, o.weight);
        } else {
          D.addPositionConstraint(SurfacePoint::atVertex(m.vertex), cam.backProject(m.pixel, cam.depth(current.V.row(m.vertex).transpose())), o.weight);
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
