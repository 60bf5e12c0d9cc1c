// The §5.3 kernel of a fit: every template vertex matched against the cloud (kernel-weighted
// mean or plane of the cloud points around it, projected on its normal).
#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <optional>
#include <unordered_map>

#include "fit_state.h"
#include "tbsp/mesh/cotan_laplacian.h"

namespace tbsp {
namespace fit_impl {
namespace {

// The cloud summarised on a grid for matching at large radii: per (voxel, normal octant) bin
// the point count, the sums of p and p pᵀ and the mean normal. The kernel-weighted mean and
// covariance of §5.3 over a ball of radius r ≥ 4 h are then sums over bins (the kernel taken at
// the bin centroid, exact within O((h/r)²)), at a fraction of the neighbour visits. The octant
// split keeps the two sides of thin parts apart, so the normal test still works per bin.
struct BinnedCloud {
  Eigen::MatrixX3d centroid, normal, sum_p;
  std::vector<Eigen::Matrix3d> sum_pp;
  Eigen::VectorXd count;
  PointSearch search;
};

// nullopt when the cloud needs more than max_bins bins (then matching against it would not pay:
// the count is known before the sums and the search tree are built)
std::optional<BinnedCloud> bin_cloud(const Eigen::MatrixX3d& P, const Eigen::MatrixX3d& N, const std::vector<char>& use, double h,
                                     int max_bins) {
  Eigen::Vector3d lo = Eigen::Vector3d::Constant(1e300);
  for (Eigen::Index i = 0; i < P.rows(); ++i)
    if (use[std::size_t(i)]) lo = lo.cwiseMin(P.row(i).transpose());
  std::unordered_map<std::uint64_t, int> bin_of;
  bin_of.reserve(std::size_t(P.rows()));
  std::vector<int> bin(std::size_t(P.rows()), -1);
  int nb = 0;
  for (Eigen::Index i = 0; i < P.rows(); ++i) {
    if (!use[std::size_t(i)]) continue;
    const Eigen::Vector3d c = ((P.row(i).transpose() - lo) / h).array().floor();
    const std::uint64_t oct = (N(i, 0) < 0 ? 1u : 0u) | (N(i, 1) < 0 ? 2u : 0u) | (N(i, 2) < 0 ? 4u : 0u);
    const std::uint64_t key = (std::uint64_t(c.x()) & 0x1FFFFF) | ((std::uint64_t(c.y()) & 0x1FFFFF) << 21) |
                              ((std::uint64_t(c.z()) & 0x1FFFFF) << 42) | (oct << 61);
    const auto [it, fresh] = bin_of.emplace(key, nb);
    if (fresh && ++nb > max_bins) return std::nullopt;
    bin[std::size_t(i)] = it->second;
  }
  BinnedCloud b;
  b.sum_p = Eigen::MatrixX3d::Zero(nb, 3);
  b.normal = Eigen::MatrixX3d::Zero(nb, 3);
  b.sum_pp.assign(std::size_t(nb), Eigen::Matrix3d::Zero());
  b.count = Eigen::VectorXd::Zero(nb);
  for (Eigen::Index i = 0; i < P.rows(); ++i) {
    const int k = bin[std::size_t(i)];
    if (k < 0) continue;
    const Eigen::Vector3d p = P.row(i).transpose();
    b.sum_p.row(k) += p.transpose();
    b.sum_pp[std::size_t(k)] += p * p.transpose();
    b.normal.row(k) += N.row(i);
    b.count(k) += 1;
  }
  b.centroid = b.sum_p.array().colwise() / b.count.array();
  for (Eigen::Index k = 0; k < nb; ++k) {
    const double len = b.normal.row(k).norm();
    if (len > 0) b.normal.row(k) /= len;
  }
  b.search = PointSearch(b.centroid);
  return b;
}

}  // namespace

/// Target of §5.3 from kernel-weighted sums over a vertex's neighbourhood (Σw, Σw p, Σw ppᵀ):
/// the weighted mean, or with `plane_fit` where the vertex's normal line meets the weighted
/// least-squares plane (if well defined). Also returns the tangential offset of the mean from
/// the normal line (the rim test). \pre sw > 0.
Eigen::Vector3d kernel_target(const Eigen::Vector3d& vj, const Eigen::Vector3d& nj, double sw, const Eigen::Vector3d& sp,
                              const Eigen::Matrix3d& spp, bool plane_fit, double in_ball, double* tangential_offset) {
  Eigen::Vector3d q = sp / sw;  // weighted average of §5.3
  *tangential_offset = ((q - vj) - (q - vj).dot(nj) * nj).norm();
  if (plane_fit && in_ball >= 6) {
    // weighted plane through q: the normal line of the vertex meets it at the projection
    // (unbiased for one-sided neighbourhoods at the rim of the data)
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(spp / sw - q * q.transpose());
    Eigen::Vector3d m = es.eigenvectors().col(0);
    if (m.dot(nj) < 0) m = -m;
    if (m.dot(nj) > 0.7 && es.eigenvalues()(1) > 4 * es.eigenvalues()(0)) q = vj + ((q - vj).dot(m) / m.dot(nj)) * nj;
    else q = vj + (q - vj).dot(nj) * nj;
  }
  return q;
}

/// Kernel sums over the cloud points `nb` (index, squared distance) within radius rr of a vertex
/// with normal nj: ROI points whose normals deviate at most θ_max (cos_max).
void kernel_sums(const std::vector<std::pair<Eigen::Index, double>>& nb, const Eigen::MatrixX3d& P, const Eigen::MatrixX3d& N,
                 const std::vector<char>& roi_ok, const Eigen::Vector3d& nj, double cos_max, double rr, double& sw,
                 Eigen::Vector3d& sp, Eigen::Matrix3d& spp, double* sw2) {
  for (const auto& [k, d2] : nb) {
    if (!roi_ok[std::size_t(k)] || N.row(k).dot(nj) < cos_max) continue;
    const double w = bspline_weight(std::sqrt(d2) / rr);
    const Eigen::Vector3d pk = P.row(k).transpose();
    sw += w;
    if (sw2) *sw2 += w * w;
    sp += w * pk;
    spp += w * pk * pk.transpose();
  }
}

double percentile99_move(const Eigen::MatrixX3d& A, const Eigen::MatrixX3d& B, const std::vector<char>& use) {
  std::vector<double> mm;
  for (Eigen::Index j = 0; j < A.rows(); ++j)
    if (use[std::size_t(j)]) mm.push_back((A.row(j) - B.row(j)).norm());
  if (mm.empty()) return 0;
  const std::size_t k = std::size_t(0.99 * double(mm.size() - 1));
  std::nth_element(mm.begin(), mm.begin() + long(k), mm.end());
  return mm[k];
}

bool match_vertices(FitState& s, double r, bool frozen_phase, const std::vector<int>& frozen_ids, NeighbourCache& cache,
                    Eigen::VectorXd& match_scale) {
  const FitParameters& u = s.u;
  const Eigen::MatrixX3d& V = s.V;
  const Eigen::MatrixX3d& P = s.cloud.P;
  const Eigen::MatrixX3d& N = s.N;
  const std::vector<char>& roi_ok = s.cloud.roi_ok;
  const std::vector<char>& masked = s.masked;
  const PointSearch& search = s.cloud.search;
  const double cos_max = s.cos_max;
  std::vector<char>& matched = s.matched;
  Eigen::MatrixX3d& target = s.target;
  const Eigen::MatrixX3d VN = vertex_normals(V, s.F);
  std::fill(matched.begin(), matched.end(), 0);
  matched.resize(std::size_t(V.rows()), 0);
  target = V;
  match_scale = Eigen::VectorXd::Ones(V.rows());
  // large radius: match against the binned cloud (bins of r/3) when it has under half as
  // many entries as the cloud (FitParameters::binned_matching)
  std::optional<BinnedCloud> binned;
  if (u.binned_matching && !frozen_phase && !u.laplacian_updating && !u.remeshing && r > u.max_match_distance)
    binned = bin_cloud(P, N, roi_ok, r / 3, int((s.cloud.np - 1) / 2));  // 2 · bins < np
  auto& nb_cache = cache.nb;
  auto& nb_cache_at = cache.at;
  auto& nb_cache_r = cache.r;
  if (frozen_phase && nb_cache.empty()) {
    nb_cache.resize(std::size_t(V.rows()));
    nb_cache_at = Eigen::MatrixX3d::Constant(V.rows(), 3, std::numeric_limits<double>::quiet_NaN());
    nb_cache_r.assign(std::size_t(V.rows()), 0.0);
  }
#pragma omp parallel
  {
    std::vector<std::pair<Eigen::Index, double>> nb;
#pragma omp for schedule(dynamic, 256)
    for (Eigen::Index j = 0; j < V.rows(); ++j) {
      if (masked[std::size_t(j)]) continue;
      if (frozen_phase && frozen_ids[std::size_t(j)] < 0) continue;  // cannot join the frozen set
      const Eigen::Vector3d vj = V.row(j).transpose(), nj = VN.row(j).transpose();
      if (nj.squaredNorm() == 0) continue;
      // expanding search: the scheduled radius first (precision), then doubled up to the
      // initial radius for vertices the fit has not brought close to the data yet (reach)
      bool found = false;
      double neff = 0;  // effective number of points of the accepted match
      Eigen::Vector3d q;
      double used_r = r;
      for (double rr = r; rr <= u.initial_match_distance * 1.0001 && !found; rr *= 2) {
        double sw = 0, sw2 = 0, in_ball = 0;
        Eigen::Vector3d sp = Eigen::Vector3d::Zero();
        Eigen::Matrix3d spp = Eigen::Matrix3d::Zero();
        if (binned) {
          binned->search.radius(vj, rr, nb);
          for (const auto& [k, d2] : nb) {
            in_ball += binned->count(k);
            if (binned->normal.row(k).dot(nj) < cos_max) continue;
            const double w = bspline_weight(std::sqrt(d2) / rr);
            sw += w * binned->count(k);
            sw2 += w * w * binned->count(k);  // every point of a bin at the bin's weight
            sp += w * binned->sum_p.row(k).transpose();
            spp += w * binned->sum_pp[std::size_t(k)];
          }
        } else if (frozen_phase && rr == r) {
          // the cached neighbours (see nb_cache), refreshed with a 25 % margin when the
          // vertex has left the region where they are complete
          const std::size_t js = std::size_t(j);
          const double dc = (vj - nb_cache_at.row(j).transpose()).norm();  // NaN before the first search
          if (!(dc + rr <= nb_cache_r[js])) {
            nb_cache_r[js] = 1.25 * rr;
            nb_cache_at.row(j) = vj.transpose();
            search.radius(vj, nb_cache_r[js], nb_cache[js]);
          }
          nb.clear();
          const double rr2 = rr * rr;
          for (const auto& e : nb_cache[js]) {
            const double d2 = (P.row(e.first).transpose() - vj).squaredNorm();
            if (d2 <= rr2) nb.emplace_back(e.first, d2);
          }
          in_ball = double(nb.size());
          kernel_sums(nb, P, N, roi_ok, nj, cos_max, rr, sw, sp, spp, &sw2);
        } else {
          search.radius(vj, rr, nb);
          in_ball = double(nb.size());
          kernel_sums(nb, P, N, roi_ok, nj, cos_max, rr, sw, sp, spp, &sw2);
        }
        if (sw <= 0) continue;
        double off = 0;
        q = kernel_target(vj, nj, sw, sp, spp, u.plane_fit, in_ball, &off);
        // one-sided neighbourhood far beyond the rim of the data: no match
        found = off <= u.rim_rejection * rr;
        neff = sw * sw / sw2;
        used_r = rr;
        if (rr >= u.initial_match_distance) break;
      }
      if (!found) continue;
      // a step of at most the scheduled radius, and matches found only at an expanded radius
      // count less: targets then vary continuously with the shape and the iteration settles
      const double d = std::clamp((q - vj).dot(nj), -r, r);
      target.row(j) = (vj + d * nj).transpose();
      match_scale(j) = (r / used_r) * (r / used_r);
      // sparse support: weight ∝ n_eff (inverse variance of the mean of n_eff noisy points)
      if (u.support_points > 0 && !u.laplacian_updating) match_scale(j) *= std::min(1.0, neff / u.support_points);
      matched[std::size_t(j)] = 1;
    }
  }
  return binned.has_value();
}

}  // namespace fit_impl
}  // namespace tbsp
