#include "tbsp/deform/deformation_transfer.h"

#include <Eigen/LU>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <utility>
#include <vector>

#include "tbsp/core/error.h"
#include "tbsp/core/timer.h"
#include "tbsp/mesh/point_search.h"

namespace tbsp {

bool DeformationTransferOptions::isValid(std::string* why) const {
  if (radius >= 0 && std::isfinite(radius)) return true;
  if (why) *why = "radius = " + std::to_string(radius) + " must be >= 0 and finite (0: 5 % of the tet mesh's diagonal)";
  return false;
}

void DeformationTransfer::setOptions(const DeformationTransferOptions& o) {
  std::string why;
  if (!o.isValid(&why)) throw InvalidInput("[tbsp::DeformationTransfer::setOptions] " + why);
  options_ = o;
}

void DeformationTransfer::precompute(const TetMesh& tets, const Eigen::MatrixX3d& hires, double radius) {
  const auto t0 = Clock::now();
  const std::string who = "[tbsp::DeformationTransfer::precompute] ";
  require_valid_tet_mesh(tets, "tbsp::DeformationTransfer::precompute");
  if (hires.rows() == 0) throw InvalidInput(who + "the high-resolution mesh has no vertices");
  for (Eigen::Index i = 0; i < hires.rows(); ++i)
    if (!hires.row(i).allFinite()) throw InvalidInput(who + "high-resolution vertex " + std::to_string(i) + " is not finite");
  if (!(radius >= 0 && std::isfinite(radius))) throw InvalidInput(who + "radius must be >= 0 and finite");
  const Eigen::Index m = tets.T.rows(), n = tets.V.rows(), N = hires.rows();
  const double r_opt = radius > 0 ? radius : options_.radius;
  const double r_used = r_opt > 0 ? r_opt : 0.05 * bbox_diagonal(tets.V);
  Eigen::MatrixX3d centers(m, 3);
  std::vector<Eigen::Matrix3d> Einv(static_cast<std::size_t>(m));
  for (Eigen::Index j = 0; j < m; ++j) {
    centers.row(j) = 0.25 * (tets.V.row(tets.T(j, 0)) + tets.V.row(tets.T(j, 1)) + tets.V.row(tets.T(j, 2)) + tets.V.row(tets.T(j, 3)));
    Eigen::Matrix3d E;
    for (int k = 0; k < 3; ++k) E.col(k) = (tets.V.row(tets.T(j, k)) - tets.V.row(tets.T(j, 3))).transpose();
    Einv[std::size_t(j)] = E.inverse();
  }
  const PointSearch search(centers);
  // A tet mesh of several parts (a template modelled as overlapping closed bodies): a vertex
  // blends only the tets of the part its nearest tet belongs to, so an arm does not drag the
  // torso along where the two are within r.
  Eigen::VectorXi vlabel;
  const bool parts = tet_connected_components(tets, vlabel) > 1;
  std::vector<int> tet_part(static_cast<std::size_t>(m), 0);
  if (parts)
    for (Eigen::Index j = 0; j < m; ++j) tet_part[std::size_t(j)] = vlabel(tets.T(j, 0));
  std::vector<std::vector<std::pair<int, double>>> rows(static_cast<std::size_t>(N));
  Eigen::Index fallback = 0;
  double total_tets = 0;
  const double r = r_used;
  // rows in blocks, progress (and cancellation) between blocks
  const Eigen::Index block = 65536;
  for (Eigen::Index b0 = 0; b0 < N; b0 += block) {
    report_progress(progress_, double(b0) / double(N), "transfer");
    const Eigen::Index b1 = std::min(N, b0 + block);
#pragma omp parallel reduction(+ : fallback, total_tets)
  {
    std::vector<std::pair<Eigen::Index, double>> found;
    std::vector<std::pair<int, double>> acc;
#pragma omp for schedule(dynamic, 256)
    for (Eigen::Index i = b0; i < b1; ++i) {
      const Eigen::Vector3d p = hires.row(i).transpose();
      search.radius(p, r, found);
      if (parts && found.size() > 1) {
        const int part = tet_part[std::size_t(search.nearest(p))];
        found.erase(std::remove_if(found.begin(), found.end(), [&](const auto& f) { return tet_part[std::size_t(f.first)] != part; }), found.end());
      }
      if (found.empty()) {
        double d2;
        found.push_back({search.nearest(p, &d2), 0.0});
        ++fallback;
      }
      total_tets += double(found.size());
      acc.clear();
      double wsum = 0;
      for (const auto& [j, d2] : found) {
        const double d = std::sqrt(d2) / r;
        const double w = found.size() == 1 ? 1.0 : std::pow(1 - d, 4) * (4 * d + 1);
        if (!(w > 0)) continue;
        const Eigen::Vector3d b = Einv[std::size_t(j)] * (p - tets.V.row(tets.T(j, 3)).transpose());
        const double c[4] = {b(0), b(1), b(2), 1.0 - b.sum()};
        for (int k = 0; k < 4; ++k) acc.push_back({tets.T(j, k), w * c[k]});
        wsum += w;
      }
      std::sort(acc.begin(), acc.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
      auto& row = rows[std::size_t(i)];
      row.clear();
      for (std::size_t k = 0; k < acc.size();) {
        double v = 0;
        const int col = acc[k].first;
        for (; k < acc.size() && acc[k].first == col; ++k) v += acc[k].second;
        row.push_back({col, v / wsum});
      }
    }
  }
  }
  report_progress(progress_, 1.0, "transfer");
  B_.resize(N, n);
  Eigen::VectorXi nnz(N);
  for (Eigen::Index i = 0; i < N; ++i) nnz(i) = int(rows[std::size_t(i)].size());
  B_.reserve(nnz);
  for (Eigen::Index i = 0; i < N; ++i)
    for (const auto& [c, v] : rows[std::size_t(i)]) B_.insert(i, c) = v;
  B_.makeCompressed();
  radius_ = r_used;
  fallback_ = fallback;
  mean_tets_ = total_tets / double(N);
  t_precompute_ = seconds_since(t0);
  report_.vertices = N;
  report_.radius = r_used;
  report_.mean_tets_per_vertex = mean_tets_;
  report_.fallback_vertices = fallback_;
  report_.t_precompute = t_precompute_;
}

Eigen::MatrixX3d DeformationTransfer::apply(const Eigen::MatrixX3d& X) const {
  if (B_.rows() == 0) throw InvalidInput("[tbsp::DeformationTransfer::apply] call precompute() first");
  if (X.rows() != B_.cols())
    throw InvalidInput("[tbsp::DeformationTransfer::apply] " + std::to_string(X.rows()) + " positions given, the tet mesh has " +
                       std::to_string(B_.cols()) + " vertices");
  Eigen::MatrixX3d out(B_.rows(), 3);
  const int* outer = B_.outerIndexPtr();
  const int* inner = B_.innerIndexPtr();
  const double* val = B_.valuePtr();
  const double* x = X.data();
  const Eigen::Index n = X.rows();
#pragma omp parallel for schedule(static) if (B_.rows() > 5000)
  for (Eigen::Index i = 0; i < B_.rows(); ++i) {
    double a = 0, b = 0, c = 0;
    for (int k = outer[i]; k < outer[i + 1]; ++k) {
      const double w = val[k];
      const int col = inner[k];
      a += w * x[col];
      b += w * x[col + n];
      c += w * x[col + 2 * n];
    }
    out(i, 0) = a;
    out(i, 1) = b;
    out(i, 2) = c;
  }
  return out;
}

}  // namespace tbsp
