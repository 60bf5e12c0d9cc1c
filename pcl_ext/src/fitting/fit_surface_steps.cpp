// §5.5 inside the iterations of a fit: adaptive subdivision where the data error is large
// (§5.5.2) and tangential area-weighted fairing along the cloud normals (eq. 5.1-5.2).
#include <cmath>
#include <vector>

#include "fit_state.h"
#include "tbsp/core/timer.h"
#include "tbsp/mesh/cotan_laplacian.h"
#include "tbsp/mesh/point_mesh_distance.h"
#include "tbsp/mesh/remeshing.h"
#include "tbsp/mesh/topology.h"

namespace tbsp {
namespace fit_impl {

bool remesh_step(FitState& s, double r) {
  const FitParameters& u = s.u;
  FitReport& rep = s.rep;
  Eigen::MatrixX3d& V = s.V;
  Eigen::MatrixX3i& F = s.F;
  const Eigen::MatrixX3d& P = s.cloud.P;
  const std::vector<char>& roi_ok = s.cloud.roi_ok;
  const Eigen::Index np = s.cloud.np;
  Eigen::MatrixX3d& V0 = s.V0;
  std::vector<char>& masked = s.masked;
  std::vector<char>& matched = s.matched;
  bool remeshed = false;
  const auto tm = Clock::now();
  const MeshDistance md(V, F);
  Eigen::VectorXi face;
  const Eigen::VectorXd dist = md.distances(P, &face);
  Eigen::VectorXd sum = Eigen::VectorXd::Zero(F.rows());
  Eigen::VectorXi cnt = Eigen::VectorXi::Zero(F.rows());
  for (Eigen::Index i = 0; i < np; ++i)
    if (roi_ok[std::size_t(i)] && dist(i) < r) { sum(face(i)) += dist(i); ++cnt(face(i)); }
  std::vector<char> mark(std::size_t(F.rows()), 0);
  int n_mark = 0;
  for (Eigen::Index f = 0; f < F.rows(); ++f)
    if (cnt(f) > 0 && sum(f) / cnt(f) > u.subdivision_error) { mark[std::size_t(f)] = 1; ++n_mark; }
  if (n_mark > 0) {
    SubdivisionResult sub = adaptive_subdivide(V, F, mark);
    valence_edge_flips(sub.V, sub.F);
    const Eigen::Index old_n = V.rows();
    V0.conservativeResize(sub.V.rows(), 3);
    masked.resize(std::size_t(sub.V.rows()), 0);
    for (std::size_t k = 0; k < sub.parents.size(); ++k) {
      const auto [a, b] = sub.parents[k];
      V0.row(old_n + Eigen::Index(k)) = 0.5 * (V0.row(a) + V0.row(b));
      masked[std::size_t(old_n) + k] = masked[std::size_t(a)] && masked[std::size_t(b)];
    }
    V = sub.V;
    F = sub.F;
    // a new mid-edge vertex is matched when both ends are: the fairing below (matched
    // vertices only) then also runs in remeshing iterations. (Resetting every vertex to
    // unmatched skipped it there, and left the stretched regions of a growing sphere
    // unfaired: results then swung between 0.4 % and 3.4 % with ±0.5 % changes of a weight.)
    matched.resize(std::size_t(V.rows()), 0);
    for (std::size_t k = 0; k < sub.parents.size(); ++k) {
      const auto [a, b] = sub.parents[k];
      matched[std::size_t(old_n) + k] = matched[std::size_t(a)] && matched[std::size_t(b)];
    }
    remeshed = true;
  }
  rep.t_remeshing += seconds_since(tm);
  return remeshed;
}

void fairing_step(FitState& s, double r) {
  const FitParameters& u = s.u;
  Eigen::MatrixX3d& V = s.V;
  const Eigen::MatrixX3i& F = s.F;
  const std::vector<char>& masked = s.masked;
  const std::vector<char>& matched = s.matched;
  const Eigen::MatrixX3d& N = s.N;
  const PointSearch& search = s.cloud.search;
  const double cos_max = s.cos_max;
  FitReport& rep = s.rep;
  const auto tm = Clock::now();
  const auto adj = vertex_adjacency(F, V.rows());
  for (int step_i = 0; step_i < u.fairing_steps; ++step_i) {
    const Eigen::VectorXd A = voronoi_areas(V, F);
    const Eigen::MatrixX3d VN2 = vertex_normals(V, F);
    // sharp features (thin rims): the one-ring centroid lies inwards and the tangent plane
    // would let the rim slide in; such vertices are left alone
    const Eigen::MatrixX3d FN2 = face_normals(V, F);
    std::vector<char> sharp(std::size_t(V.rows()), 0);
    for (Eigen::Index f = 0; f < F.rows(); ++f)
      for (int k = 0; k < 3; ++k)
        if (FN2.row(f).dot(VN2.row(F(f, k))) < std::cos(M_PI / 6)) sharp[std::size_t(F(f, k))] = 1;
    Eigen::MatrixX3d Vf = V;
#pragma omp parallel
    {
      std::vector<Eigen::Index> idx;
      std::vector<double> d2;
#pragma omp for schedule(dynamic, 256)
      for (Eigen::Index i = 0; i < V.rows(); ++i) {
        const auto& nb = adj[std::size_t(i)];
        if (nb.empty() || masked[std::size_t(i)] || !matched[std::size_t(i)] || sharp[std::size_t(i)]) continue;
        double mean_edge = 0;
        for (int j : nb) mean_edge += (V.row(j) - V.row(i)).norm();
        mean_edge /= double(nb.size());
        Eigen::Vector3d g = Eigen::Vector3d::Zero();
        double sa = 0;
        for (int j : nb) { g += A(j) * V.row(j).transpose(); sa += A(j); }
        if (!(sa > 0)) continue;
        g /= sa;  // eq. 5.1
        // normal of the target surface: average of the nearest cloud normals (if close)
        Eigen::Vector3d n = VN2.row(i).transpose();
        search.knn(V.row(i).transpose(), u.normal_neighbours, idx, d2);
        Eigen::Vector3d cn = Eigen::Vector3d::Zero();
        for (std::size_t k = 0; k < idx.size(); ++k)  // same side only (thin parts!)
          if (d2[k] < r * r && N.row(idx[k]).dot(n) > cos_max) cn += N.row(idx[k]).transpose();
        if (cn.norm() > 0) n = cn.normalized();
        const Eigen::Vector3d dv = g - V.row(i).transpose();
        Eigen::Vector3d step = u.fairing_lambda * (dv - n * n.dot(dv));  // eq. 5.2
        if (step.norm() > 0.25 * mean_edge) step *= 0.25 * mean_edge / step.norm();
        Vf.row(i) += step.transpose();
      }
    }
    V = Vf;
  }
  rep.t_fairing += seconds_since(tm);
}

}  // namespace fit_impl
}  // namespace tbsp
