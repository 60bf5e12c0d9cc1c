// Fitting without markers: a similarity alignment (rotation, uniform scale, translation) of the
// template to the cloud by trimmed ICP before the coarse-to-fine fit.
#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <optional>
#include <string>
#include <vector>

#include "fit_state.h"
#include "tbsp/core/error.h"
#include "tbsp/core/logging.h"
#include "tbsp/core/timer.h"
#include "tbsp/mesh/similarity_icp.h"

namespace tbsp {
namespace fit_impl {

// Trimmed ICP with scale (tbsp::similarity_icp). Correspondences go from the cloud to the
// template: every scan point has a counterpart on a complete template, while template vertices
// over the scan's holes have none, so this direction is not biased by holes. The farthest 10 % of
// the pairs (outliers, parts of the scene the template does not model) are dropped each
// iteration. At most 20k cloud points (a fixed stride: deterministic) and 60 iterations; stops
// when the transform changes the template by less than 1e-6 of the cloud diagonal.
SimilarityIcpResult similarity_alignment(const PreparedCloud& c, const Eigen::MatrixX3d& V) {
  Eigen::Index n_roi = 0;
  for (Eigen::Index i = 0; i < c.np; ++i) n_roi += c.roi_ok[std::size_t(i)];
  Eigen::MatrixX3d cloud(n_roi, 3);
  for (Eigen::Index i = 0, k = 0; i < c.np; ++i)
    if (c.roi_ok[std::size_t(i)]) cloud.row(k++) = c.P.row(i);
  SimilarityIcpOptions io;
  io.trim = 0.1;
  io.max_iterations = 60;
  io.tolerance = 1e-6 * c.diag;
  io.max_points = 20000;
  io.stall_iterations = 0;  // as measured in docs/fitting.md
  return similarity_icp(V, cloud, io);
}

std::string alignment_warning(const SimilarityIcpResult& r) {
  if (r.rotation_deg <= 30 && r.scale >= 2.0 / 3.0 && r.scale <= 1.5) return {};
  char buf[400];
  std::snprintf(buf, sizeof buf,
                "the alignment turned the template by %.1f deg and scaled it by %.4g, far more than for a template roughly "
                "in place (within ~10 deg and ~5 %%); the fit may have settled in a wrong pose: check it (e.g. its PNG), check the "
                "units, or give markers. ",
                r.rotation_deg, r.scale);
  return buf;
}

void align_without_markers(FitState& s, TriMesh& aligned) {
  const auto t0 = Clock::now();
  FitReport& rep = s.rep;
  const TriMesh& rest = s.templ();
  // the same template and cloud give the same alignment: computed once per fit_template call
  std::optional<SimilarityIcpResult> local;
  std::optional<SimilarityIcpResult>& cache = s.alignment_cache ? *s.alignment_cache : local;
  if (!cache) {
    cache = similarity_alignment(s.cloud, rest.V);
    const std::string w = alignment_warning(*cache);
    if (!w.empty()) logger()->warn("[TemplateFitting] {}", w);
  }
  const SimilarityIcpResult& r = *cache;
  const Eigen::Matrix4d T = r.transform;
  const int it = r.iterations;
  const double rms = r.rms;
  const Eigen::MatrixX3d X = transform_points(T, rest.V);
  const Eigen::Matrix3d sR = T.topLeftCorner<3, 3>();
  const double scale = std::cbrt(sR.determinant());
  const Eigen::Matrix3d R = sR / scale;
  rep.aligned_without_markers = true;
  rep.alignment = T;
  rep.alignment_scale = scale;
  rep.alignment_rotation_deg = Eigen::AngleAxisd(R).angle() * 180.0 / M_PI;
  rep.alignment_iterations = it;
  rep.alignment_rms = rms;
  rep.t_alignment = seconds_since(t0);
  rep.message += "no markers: the template was aligned to the cloud first (trimmed ICP with scale: " +
                 std::to_string(rep.alignment_rotation_deg) + " deg, scale " + std::to_string(scale) + "). ";
  if (const std::string w = alignment_warning(r); !w.empty()) rep.message += "warning: " + w;
  logger()->debug("[TemplateFitting] alignment without markers: {} iterations, rotation {:.2f} deg, scale {:.4f}, rms {:.3g}",
                  it, rep.alignment_rotation_deg, scale, rms);
  aligned.V = X;
  aligned.F = rest.F;
}

}  // namespace fit_impl
}  // namespace tbsp
