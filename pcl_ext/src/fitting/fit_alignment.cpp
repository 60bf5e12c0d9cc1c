// Fitting without markers: a similarity alignment (rotation, uniform scale, translation) of the
// template to the cloud by trimmed ICP before the coarse-to-fine fit.
#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <vector>

#include "fit_state.h"
#include "tbsp/core/error.h"
#include "tbsp/core/logging.h"
#include "tbsp/core/timer.h"

namespace tbsp {
namespace fit_impl {

// Trimmed ICP with scale (Chetverikov et al. 2002's trimming; Umeyama 1991's closed-form
// similarity, Eigen::umeyama). Correspondences go from the cloud to the template: every scan
// point has a counterpart on a complete template, while template vertices over the scan's holes
// have none, so this direction is not biased by holes. The farthest 10 % of the pairs (outliers,
// parts of the scene the template does not model) are dropped each iteration. At most 20k cloud
// points (a fixed stride: deterministic) and 60 iterations; stops when the transform changes
// the template by less than 1e-6 of the cloud diagonal.
// Written here rather than with PCL's IterativeClosestPoint: it runs on the Eigen matrices the
// fitter already has, with our kd-tree, and needs no point-type conversions; PCL offers the same
// pieces (TransformationEstimationSVDScale, CorrespondenceRejectorTrimmed).
void align_without_markers(FitState& s, TriMesh& aligned) {
  const auto t0 = Clock::now();
  FitReport& rep = s.rep;
  const TriMesh& rest = s.templ();
  std::vector<Eigen::Index> sample;
  Eigen::Index n_roi = 0;
  for (Eigen::Index i = 0; i < s.np; ++i) n_roi += s.roi_ok[std::size_t(i)];
  const Eigen::Index stride = std::max<Eigen::Index>(1, n_roi / 20000);
  for (Eigen::Index i = 0, k = 0; i < s.np; ++i)
    if (s.roi_ok[std::size_t(i)] && k++ % stride == 0) sample.push_back(i);
  const Eigen::Index m = Eigen::Index(sample.size());
  Eigen::Matrix4d T = Eigen::Matrix4d::Identity();
  Eigen::MatrixX3d X = rest.V;
  std::vector<Eigen::Index> nearest(static_cast<std::size_t>(m));
  std::vector<double> dist(static_cast<std::size_t>(m));
  int it = 0;
  double rms = 0;
  // one tree over the rest template: the nearest vertex of T·rest to p is the nearest vertex of
  // rest to T⁻¹p (a similarity keeps the order of distances)
  const PointSearch rest_search(rest.V);
  for (; it < 60; ++it) {
    const Eigen::Matrix3d A = T.topLeftCorner<3, 3>().inverse();
    const Eigen::Vector3d t = T.topRightCorner<3, 1>();
#pragma omp parallel for schedule(static)
    for (Eigen::Index k = 0; k < m; ++k) {
      const Eigen::Vector3d p = s.P.row(sample[std::size_t(k)]).transpose();
      const Eigen::Index v = rest_search.nearest(A * (p - t));
      nearest[std::size_t(k)] = v;
      dist[std::size_t(k)] = v >= 0 ? (p - X.row(v).transpose()).norm() : 0.0;
    }
    std::vector<double> sorted = dist;
    const std::size_t keep = std::max<std::size_t>(3, std::size_t(0.9 * double(m)));
    std::nth_element(sorted.begin(), sorted.begin() + long(std::min(keep, sorted.size()) - 1), sorted.end());
    const double cut = sorted[std::min(keep, sorted.size()) - 1];
    std::vector<Eigen::Index> use;
    for (Eigen::Index k = 0; k < m; ++k)
      if (nearest[std::size_t(k)] >= 0 && dist[std::size_t(k)] <= cut) use.push_back(k);
    if (use.size() < 3) break;
    Eigen::Matrix3Xd src(3, Eigen::Index(use.size())), dst(3, Eigen::Index(use.size()));
    double sq = 0;
    for (std::size_t q = 0; q < use.size(); ++q) {
      const Eigen::Index k = use[q];
      src.col(Eigen::Index(q)) = X.row(nearest[std::size_t(k)]).transpose();
      dst.col(Eigen::Index(q)) = s.P.row(sample[std::size_t(k)]).transpose();
      sq += dist[std::size_t(k)] * dist[std::size_t(k)];
    }
    rms = std::sqrt(sq / double(use.size()));
    const Eigen::Matrix4d step = Eigen::umeyama(src, dst, true);
    if (!step.allFinite()) break;
    T = step * T;
    const Eigen::MatrixX3d Xn = ((rest.V * T.topLeftCorner<3, 3>().transpose()).rowwise() + T.topRightCorner<3, 1>().transpose());
    const double change = (Xn - X).rowwise().norm().maxCoeff();
    X = Xn;
    if (change < 1e-6 * s.diag) { ++it; break; }
  }
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
  logger()->debug("[TemplateFitting] alignment without markers: {} iterations, rotation {:.2f} deg, scale {:.4f}, rms {:.3g}",
                  it, rep.alignment_rotation_deg, scale, rms);
  aligned.V = X;
  aligned.F = rest.F;
}

}  // namespace fit_impl
}  // namespace tbsp
