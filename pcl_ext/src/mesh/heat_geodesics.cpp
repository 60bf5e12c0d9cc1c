#include "tbsp/mesh/heat_geodesics.h"

#include <Eigen/Geometry>
#include <cmath>
#include <limits>
#include <numeric>
#include <string>

#include "tbsp/core/error.h"
#include "tbsp/mesh/cotan_laplacian.h"
#include "tbsp/solve/sparse_cholesky.h"

namespace tbsp {

struct HeatGeodesics::Impl {
  Eigen::MatrixX3d V;
  Eigen::MatrixX3i F;
  Eigen::VectorXd mass;            // lumped Voronoi areas
  std::vector<int> component;      // per vertex; -1 for vertices in no triangle
  std::vector<double> comp_mass;   // total mass per component
  Eigen::MatrixX3d normal;         // unit face normals
  Eigen::VectorXd area;            // face areas
  Eigen::MatrixX3d cot;            // cotangent of the angle at corner c of face f
  double h = 0;
  SparseCholesky heat, poisson;
};

namespace {
int find_root(std::vector<int>& p, int i) {
  while (p[i] != i) i = p[i] = p[p[i]];
  return i;
}
}  // namespace

HeatGeodesics::HeatGeodesics(const Eigen::MatrixX3d& V, const Eigen::MatrixX3i& F, const HeatGeodesicsOptions& options)
    : impl_(std::make_unique<Impl>()) {
  const Eigen::Index n = V.rows();
  if (n == 0 || F.rows() == 0) throw InvalidInput("[tbsp::HeatGeodesics] empty mesh: give at least one triangle");
  if (!V.allFinite()) throw InvalidInput("[tbsp::HeatGeodesics] the mesh has non-finite vertex coordinates");
  if (F.minCoeff() < 0 || F.maxCoeff() >= n) throw InvalidInput("[tbsp::HeatGeodesics] a triangle index is out of range [0, " + std::to_string(n) + ")");
  std::string why;
  if (!options.isValid(&why)) throw InvalidInput("[tbsp::HeatGeodesics] " + why);
  Impl& d = *impl_;
  d.V = V;
  d.F = F;
  const Eigen::Index nf = F.rows();
  d.normal.resize(nf, 3);
  d.area.resize(nf);
  d.cot.resize(nf, 3);
  double sum_len = 0;
  for (Eigen::Index f = 0; f < nf; ++f) {
    const Eigen::Vector3d p[3] = {V.row(F(f, 0)), V.row(F(f, 1)), V.row(F(f, 2))};
    const Eigen::Vector3d nrm = (p[1] - p[0]).cross(p[2] - p[0]);
    const double a2 = nrm.norm();
    d.area(f) = 0.5 * a2;
    d.normal.row(f) = a2 > 0 ? Eigen::Vector3d(nrm / a2) : Eigen::Vector3d::Zero();
    for (int c = 0; c < 3; ++c) sum_len += (p[(c + 1) % 3] - p[c]).norm();
  }
  d.cot = face_cotangents(V, F);  // the Laplacian's own (mollified) cotangents
  d.h = sum_len / (3.0 * nf);
  if (!(d.h > 0)) throw InvalidInput("[tbsp::HeatGeodesics] all edges have zero length");

  // Components (union-find over triangles).
  std::vector<int> parent(n);
  std::iota(parent.begin(), parent.end(), 0);
  std::vector<char> used(n, 0);
  for (Eigen::Index f = 0; f < nf; ++f)
    for (int c = 0; c < 3; ++c) {
      used[F(f, c)] = 1;
      const int a = find_root(parent, F(f, c)), b = find_root(parent, F(f, (c + 1) % 3));
      if (a != b) parent[a] = b;
    }
  d.component.assign(n, -1);
  std::vector<int> label(n, -1);
  int nc = 0;
  for (Eigen::Index i = 0; i < n; ++i) {
    if (!used[i]) continue;
    const int r = find_root(parent, static_cast<int>(i));
    if (label[r] < 0) label[r] = nc++;
    d.component[i] = label[r];
  }

  d.mass = voronoi_areas(V, F);
  const double mean_mass = d.mass.sum() / std::max<Eigen::Index>(1, std::count(used.begin(), used.end(), 1));
  for (Eigen::Index i = 0; i < n; ++i)
    if (!used[i] || !(d.mass(i) > 1e-12 * mean_mass)) d.mass(i) = std::max(1e-12 * mean_mass, used[i] ? d.mass(i) : mean_mass);
  d.comp_mass.assign(nc, 0.0);
  for (Eigen::Index i = 0; i < n; ++i)
    if (d.component[i] >= 0) d.comp_mass[d.component[i]] += d.mass(i);

  const Eigen::SparseMatrix<double> K = -cotangent_matrix(V, F);
  Eigen::SparseMatrix<double> M(n, n);
  std::vector<Eigen::Triplet<double>> mt;
  mt.reserve(n);
  for (Eigen::Index i = 0; i < n; ++i) mt.emplace_back(i, i, d.mass(i));
  M.setFromTriplets(mt.begin(), mt.end());
  const double t = options.time > 0 ? options.time : options.time_factor * d.h * d.h;
  report_progress(options.progress, 0.2, "heat geodesics: factorize");
  d.heat.compute(Eigen::SparseMatrix<double>(M + t * K));
  report_progress(options.progress, 0.6, "heat geodesics: factorize");
  // K is singular (constants per component); a tiny mass shift makes it definite. The
  // right-hand sides are projected to zero mean per component, so the shift changes φ by a
  // negligible amount (relative 1e-10) and only by a constant that is removed afterwards.
  const double eps = 1e-10 * K.diagonal().sum() / M.diagonal().sum();
  d.poisson.compute(Eigen::SparseMatrix<double>(K + eps * M));
  report_progress(options.progress, 1.0, "heat geodesics: factorize");
}

bool HeatGeodesicsOptions::isValid(std::string* why) const {
  if (time_factor > 0 && std::isfinite(time_factor) && time >= 0 && std::isfinite(time)) return true;
  if (why) *why = "time_factor must be > 0 and time >= 0 (both finite)";
  return false;
}

HeatGeodesics::~HeatGeodesics() = default;
HeatGeodesics::HeatGeodesics(HeatGeodesics&&) noexcept = default;
HeatGeodesics& HeatGeodesics::operator=(HeatGeodesics&&) noexcept = default;
double HeatGeodesics::meanEdgeLength() const { return impl_->h; }
Eigen::Index HeatGeodesics::numVertices() const { return impl_->V.rows(); }

Eigen::MatrixXd HeatGeodesics::distancesFromVertices(const std::vector<int>& vertices) const {
  std::vector<WeightedSource> s;
  s.reserve(vertices.size());
  for (int v : vertices) s.push_back({{v, 1.0}});
  return distances(s);
}

Eigen::MatrixXd HeatGeodesics::distances(const std::vector<WeightedSource>& sources) const {
  const Impl& d = *impl_;
  const Eigen::Index n = d.V.rows(), nf = d.F.rows();
  const int k = static_cast<int>(sources.size());
  if (k == 0) return Eigen::MatrixXd(n, 0);
  Eigen::MatrixXd B = Eigen::MatrixXd::Zero(n, k);
  std::vector<int> comp(k, -1);
  for (int s = 0; s < k; ++s) {
    double wsum = 0;
    if (sources[s].empty()) throw InvalidInput("[tbsp::HeatGeodesics] source " + std::to_string(s) + " has no vertex");
    for (const auto& [v, w] : sources[s]) {
      if (v < 0 || v >= n) throw InvalidInput("[tbsp::HeatGeodesics] source " + std::to_string(s) + ": vertex " + std::to_string(v) + " is out of range [0, " + std::to_string(n) + ")");
      if (d.component[v] < 0) throw InvalidInput("[tbsp::HeatGeodesics] source " + std::to_string(s) + ": vertex " + std::to_string(v) + " is in no triangle");
      B(v, s) += w;
      wsum += w;
      if (w > 0) comp[s] = d.component[v];
    }
    if (!(wsum > 0)) throw InvalidInput("[tbsp::HeatGeodesics] source " + std::to_string(s) + ": the weights must sum to a positive number");
  }
  const Eigen::MatrixXd U = d.heat.solve(B);

  // Normalized negative gradient per triangle, then its integrated divergence per vertex.
  Eigen::MatrixXd div = Eigen::MatrixXd::Zero(n, k);
#pragma omp parallel for schedule(dynamic, 1)
  for (int s = 0; s < k; ++s) {
    for (Eigen::Index f = 0; f < nf; ++f) {
      if (!(d.area(f) > 0)) continue;
      const int idx[3] = {d.F(f, 0), d.F(f, 1), d.F(f, 2)};
      const Eigen::Vector3d p[3] = {d.V.row(idx[0]), d.V.row(idx[1]), d.V.row(idx[2])};
      const Eigen::Vector3d N = d.normal.row(f);
      Eigen::Vector3d g = Eigen::Vector3d::Zero();
      for (int c = 0; c < 3; ++c) g += U(idx[c], s) * N.cross(p[(c + 2) % 3] - p[(c + 1) % 3]);
      const double gn = g.norm();
      if (!(gn > 0)) continue;
      const Eigen::Vector3d X = -g / gn;
      for (int c = 0; c < 3; ++c) {
        const int j = (c + 1) % 3, l = (c + 2) % 3;
        // ½ [cot θ_l (e_cj · X) + cot θ_j (e_cl · X)]
        div(idx[c], s) += 0.5 * (d.cot(f, l) * (p[j] - p[c]).dot(X) + d.cot(f, j) * (p[l] - p[c]).dot(X));
      }
    }
  }
  // K φ = −div, right-hand side projected to zero mean per component.
  Eigen::MatrixXd R = -div;
  const int nc = static_cast<int>(d.comp_mass.size());
  for (int s = 0; s < k; ++s) {
    std::vector<double> sum(nc, 0.0);
    for (Eigen::Index i = 0; i < n; ++i)
      if (d.component[i] >= 0) sum[d.component[i]] += R(i, s);
    for (Eigen::Index i = 0; i < n; ++i)
      if (d.component[i] >= 0) R(i, s) -= d.mass(i) * sum[d.component[i]] / d.comp_mass[d.component[i]];
  }
  Eigen::MatrixXd phi = d.poisson.solve(R);
  const double inf = std::numeric_limits<double>::infinity();
  for (int s = 0; s < k; ++s) {
    double w = 0, at = 0;
    for (const auto& [v, wt] : sources[s]) {
      at += wt * phi(v, s);
      w += wt;
    }
    at /= w;
    for (Eigen::Index i = 0; i < n; ++i)
      phi(i, s) = d.component[i] == comp[s] ? std::max(0.0, phi(i, s) - at) : inf;
  }
  return phi;
}

}  // namespace tbsp
