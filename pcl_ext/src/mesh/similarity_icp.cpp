#include "tbsp/mesh/similarity_icp.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <limits>
#include <string>
#include <vector>

#include "tbsp/core/error.h"
#include "tbsp/mesh/point_search.h"

namespace tbsp {

bool SimilarityIcpOptions::isValid(const char** why) const {
  auto fail = [&](const char* m) {
    if (why) *why = m;
    return false;
  };
  if (!(trim >= 0 && trim <= 0.9)) return fail("trim must be in [0, 0.9]");
  if (max_iterations < 1 || max_iterations > 10000) return fail("max_iterations must be in 1..10000");
  if (!(tolerance >= 0) || !std::isfinite(tolerance)) return fail("tolerance must be >= 0 and finite");
  if (max_points < 10) return fail("max_points must be >= 10");
  if (stall_iterations < 0 || stall_iterations > 1000) return fail("stall_iterations must be in 0..1000");
  return true;
}

Eigen::MatrixX3d transform_points(const Eigen::Matrix4d& T, const Eigen::MatrixX3d& V) {
  return (V * T.topLeftCorner<3, 3>().transpose()).rowwise() + T.topRightCorner<3, 1>().transpose();
}

namespace {

std::vector<Eigen::Index> strided(Eigen::Index n, int max_points) {
  const Eigen::Index stride = std::max<Eigen::Index>(1, n / max_points);
  std::vector<Eigen::Index> s;
  for (Eigen::Index i = 0; i < n; i += stride) s.push_back(i);
  return s;
}

// Indices k of the pairs to keep: the (1 - trim) fraction with the smallest distances (at least 3).
void keep_nearest(const std::vector<double>& dist, const std::vector<char>& ok, double trim, std::vector<std::size_t>& use) {
  use.clear();
  const std::size_t m = dist.size();
  if (m == 0) return;
  std::vector<double> sorted = dist;
  const std::size_t keep = std::min(m, std::max<std::size_t>(3, std::size_t((1.0 - trim) * double(m))));
  std::nth_element(sorted.begin(), sorted.begin() + long(keep - 1), sorted.end());
  const double cut = sorted[keep - 1];
  for (std::size_t k = 0; k < m; ++k)
    if (ok[k] && dist[k] <= cut) use.push_back(k);
}

}  // namespace

namespace {

// One linearised point-to-plane step (Chen & Medioni 1992, with a scale about the centroid c of
// the source points): minimises sum (n·(c + (1+σ) R(ω)(x − c) + τ − y))² over ω, τ, σ to first
// order; returns the 4x4 step (exact rotation of ω). Empty (non-finite) when degenerate.
Eigen::Matrix4d point_to_plane_step(const Eigen::Matrix3Xd& src, const Eigen::Matrix3Xd& dst, const Eigen::Matrix3Xd& nrm, bool scale) {
  const Eigen::Index m = src.cols();
  const Eigen::Vector3d c = src.rowwise().mean();
  const int k = scale ? 7 : 6;
  Eigen::MatrixXd A = Eigen::MatrixXd::Zero(k, k);
  Eigen::VectorXd b = Eigen::VectorXd::Zero(k);
  Eigen::VectorXd J(k);
  for (Eigen::Index i = 0; i < m; ++i) {
    const Eigen::Vector3d x = src.col(i) - c, n = nrm.col(i);
    J.head<3>() = x.cross(n);
    J.segment<3>(3) = n;
    if (scale) J(6) = n.dot(x);
    const double r = n.dot(src.col(i) - dst.col(i));
    A.noalias() += J * J.transpose();
    b.noalias() -= r * J;
  }
  A.diagonal().array() += 1e-12 * (A.trace() + 1e-300);
  const Eigen::VectorXd u = A.ldlt().solve(b);
  Eigen::Matrix4d step = Eigen::Matrix4d::Identity();
  if (!u.allFinite()) return step * std::numeric_limits<double>::quiet_NaN();
  const Eigen::Vector3d w = u.head<3>();
  const Eigen::Matrix3d R = w.norm() > 0 ? Eigen::AngleAxisd(w.norm(), w.normalized()).toRotationMatrix() : Eigen::Matrix3d::Identity();
  const double s = scale ? 1.0 + u(6) : 1.0;
  step.topLeftCorner<3, 3>() = s * R;
  step.topRightCorner<3, 1>() = c + u.segment<3>(3) - s * R * c;
  return step;
}

}  // namespace

SimilarityIcpResult similarity_icp(const Eigen::MatrixX3d& source, const Eigen::MatrixX3d& target, const SimilarityIcpOptions& o,
                                   const Eigen::MatrixX3d* target_normals) {
  const std::string who = "[tbsp::similarity_icp] ";
  const char* why = nullptr;
  if (!o.isValid(&why)) throw InvalidInput(who + why);
  if (source.rows() < 3) throw InvalidInput(who + "the source has " + std::to_string(source.rows()) + " points; at least 3 are needed");
  if (target.rows() < 3) throw InvalidInput(who + "the target has " + std::to_string(target.rows()) + " points; at least 3 are needed");
  if (!source.allFinite()) throw InvalidInput(who + "the source has non-finite coordinates");
  if (!target.allFinite()) throw InvalidInput(who + "the target has non-finite coordinates");
  if (target_normals && (target_normals->rows() != target.rows() || !target_normals->allFinite()))
    throw InvalidInput(who + "target_normals must have one finite normal per target point (" + std::to_string(target.rows()) + " rows)");
  const double diag = (target.colwise().maxCoeff() - target.colwise().minCoeff()).norm();
  const double tol = o.tolerance > 0 ? o.tolerance : 1e-6 * diag;

  const std::vector<Eigen::Index> ts = strided(target.rows(), o.max_points);
  const std::vector<Eigen::Index> ss = o.symmetric ? strided(source.rows(), o.max_points) : std::vector<Eigen::Index>{};
  const std::size_t mt = ts.size(), ms = ss.size();
  // One tree over the untransformed source: the nearest point of T·source to p is the nearest
  // point of source to T⁻¹p (a similarity keeps the order of distances).
  const PointSearch source_tree(source);
  PointSearch target_tree;
  if (o.symmetric) target_tree.build(target);

  SimilarityIcpResult r;
  Eigen::Matrix4d T = Eigen::Matrix4d::Identity();
  Eigen::MatrixX3d X = source;
  std::vector<Eigen::Index> nt(mt), ns(ms);
  std::vector<double> dt(mt), ds(ms);
  std::vector<char> okt(mt), oks(ms);
  std::vector<std::size_t> use_t, use_s;
  int it = 0, since_best = 0;
  double best_rms = std::numeric_limits<double>::infinity();
  Eigen::Matrix4d best_T = T;
  for (; it < o.max_iterations; ++it) {
    const Eigen::Matrix3d A = T.topLeftCorner<3, 3>().inverse();
    const Eigen::Vector3d t = T.topRightCorner<3, 1>();
#pragma omp parallel for schedule(static)
    for (long k = 0; k < long(mt); ++k) {
      const Eigen::Vector3d p = target.row(ts[std::size_t(k)]).transpose();
      const Eigen::Index v = source_tree.nearest(A * (p - t));
      nt[std::size_t(k)] = v;
      okt[std::size_t(k)] = v >= 0;
      dt[std::size_t(k)] = v >= 0 ? (p - X.row(v).transpose()).norm() : 0.0;
    }
#pragma omp parallel for schedule(static)
    for (long k = 0; k < long(ms); ++k) {
      const Eigen::Vector3d x = X.row(ss[std::size_t(k)]).transpose();
      double d2 = 0;
      const Eigen::Index q = target_tree.nearest(x, &d2);
      ns[std::size_t(k)] = q;
      oks[std::size_t(k)] = q >= 0;
      ds[std::size_t(k)] = q >= 0 ? std::sqrt(d2) : 0.0;
    }
    keep_nearest(dt, okt, o.trim, use_t);
    keep_nearest(ds, oks, o.trim, use_s);
    const std::size_t nuse = use_t.size() + use_s.size();
    if (nuse < 3) break;
    Eigen::Matrix3Xd src(3, Eigen::Index(nuse)), dst(3, Eigen::Index(nuse)), nrm;
    if (target_normals) nrm.resize(3, Eigen::Index(nuse));
    double sq = 0;
    Eigen::Index c = 0;
    for (std::size_t k : use_t) {
      if (target_normals) nrm.col(c) = target_normals->row(ts[k]).transpose();
      src.col(c) = X.row(nt[k]).transpose();
      dst.col(c++) = target.row(ts[k]).transpose();
      sq += dt[k] * dt[k];
    }
    for (std::size_t k : use_s) {
      if (target_normals) nrm.col(c) = target_normals->row(ns[k]).transpose();
      src.col(c) = X.row(ss[k]).transpose();
      dst.col(c++) = target.row(ns[k]).transpose();
      sq += ds[k] * ds[k];
    }
    r.rms = std::sqrt(sq / double(nuse));
    if (o.stall_iterations > 0) {
      if (r.rms < best_rms * (1 - 1e-4)) {
        best_rms = r.rms;
        best_T = T;
        since_best = 0;
      } else if (++since_best >= o.stall_iterations) {
        r.converged = r.stalled = true;
        if (r.rms > best_rms) {  // return the best transform seen, not the last of the cycle
          T = best_T;
          r.rms = best_rms;
        }
        break;
      }
    }
    const Eigen::Matrix4d step =
        target_normals ? point_to_plane_step(src, dst, nrm, o.estimate_scale) : Eigen::Matrix4d(Eigen::umeyama(src, dst, o.estimate_scale));
    if (!step.allFinite()) break;
    T = step * T;
    const Eigen::MatrixX3d Xn = transform_points(T, source);
    const double change = (Xn - X).rowwise().norm().maxCoeff();
    X = Xn;
    if (change < tol) {
      ++it;
      r.converged = true;
      break;
    }
  }
  const Eigen::Matrix3d sR = T.topLeftCorner<3, 3>();
  r.transform = T;
  r.scale = std::cbrt(sR.determinant());
  r.rotation_deg = Eigen::AngleAxisd(Eigen::Matrix3d(sR / r.scale)).angle() * 180.0 / M_PI;
  r.translation = T.topRightCorner<3, 1>();
  r.iterations = it;
  return r;
}

}  // namespace tbsp
