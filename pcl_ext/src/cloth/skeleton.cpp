#include "tbsp/cloth/skeleton.h"

#include <algorithm>
#include <cmath>
#include <numeric>
#include <string>

#include "ray_caster.h"
#include "tbsp/core/error.h"
#include "tbsp/mesh/cotan_laplacian.h"
#include "tbsp/mesh/topology.h"
#include "tbsp/mesh/tri_mesh.h"
#include "tbsp/solve/sparse_cholesky.h"

namespace tbsp {

namespace {

double segment_distance(const Eigen::Vector3d& p, const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                        Eigen::Vector3d* closest) {
  const Eigen::Vector3d ab = b - a;
  const double l2 = ab.squaredNorm();
  const double t = l2 > 0 ? std::clamp((p - a).dot(ab) / l2, 0.0, 1.0) : 0.0;
  const Eigen::Vector3d c = a + t * ab;
  if (closest) *closest = c;
  return (p - c).norm();
}

// Keeps the `k` largest entries of a non-negative row, drops those below `min_w`, renormalises.
void sparsify_row(std::vector<std::pair<double, int>>& row, int k, double min_w) {
  std::sort(row.begin(), row.end(), [](const auto& a, const auto& b) { return a.first > b.first || (a.first == b.first && a.second < b.second); });
  if (int(row.size()) > k) row.resize(std::size_t(k));
  double sum = 0;
  for (const auto& e : row) sum += e.first;
  if (sum <= 0) return;
  for (auto& e : row) e.first /= sum;
  row.erase(std::remove_if(row.begin() + 1, row.end(), [&](const auto& e) { return e.first < min_w; }), row.end());
  sum = 0;
  for (const auto& e : row) sum += e.first;
  for (auto& e : row) e.first /= sum;
}

}  // namespace

SkinningWeights bone_heat_weights(const Eigen::MatrixX3d& V, const Eigen::MatrixX3i& F, const Skeleton& skeleton,
                                  const BoneHeatOptions& o) {
  const char* where = "tbsp::bone_heat_weights";
  validate_skeleton(skeleton, where);
  if (V.rows() == 0 || F.rows() == 0) throw InvalidInput("[tbsp::bone_heat_weights] the mesh is empty");
  if (!V.allFinite()) throw InvalidInput("[tbsp::bone_heat_weights] the mesh has non-finite vertex coordinates");
  if (F.minCoeff() < 0 || F.maxCoeff() >= V.rows())
    throw InvalidInput("[tbsp::bone_heat_weights] a face index is out of range (mesh has " + std::to_string(V.rows()) + " vertices)");
  if (!(o.heat > 0) || o.tie_factor < 1 || o.tie_factor > 2 || o.max_influences < 1 || o.max_influences > 8 ||
      o.min_weight < 0 || o.min_weight >= 0.5)
    throw InvalidInput("[tbsp::bone_heat_weights] options out of range: heat > 0, tie_factor in [1,2], max_influences in 1..8, "
                       "min_weight in [0,0.5)");
  const std::vector<Bone> bones = skeleton_bones(skeleton);
  if (bones.empty()) throw InvalidInput("[tbsp::bone_heat_weights] the skeleton has no bones (every joint is a root or coincides with its parent)");
  const Eigen::Index n = V.rows();
  const int nb = int(bones.size());
  const double diag = bbox_diagonal(V);

  std::unique_ptr<detail::RayCaster> rays;
  if (o.visibility) rays = std::make_unique<detail::RayCaster>(V, F);

  Eigen::VectorXd heat = Eigen::VectorXd::Zero(n);
  Eigen::MatrixXd P = Eigen::MatrixXd::Zero(n, nb);
  std::vector<int> nearest(std::size_t(n), 0);
#pragma omp parallel for schedule(dynamic, 256)
  for (Eigen::Index i = 0; i < n; ++i) {
    const Eigen::Vector3d p = V.row(i).transpose();
    std::vector<double> d(static_cast<std::size_t>(nb));
    std::vector<Eigen::Vector3d> c(static_cast<std::size_t>(nb));
    double dmin = std::numeric_limits<double>::infinity();
    for (int b = 0; b < nb; ++b) {
      d[std::size_t(b)] = segment_distance(p, skeleton.restPosition(bones[std::size_t(b)].joint),
                                           skeleton.restPosition(bones[std::size_t(b)].child), &c[std::size_t(b)]);
      if (d[std::size_t(b)] < dmin) {
        dmin = d[std::size_t(b)];
        nearest[std::size_t(i)] = b;
      }
    }
    std::vector<int> heated;
    for (int b = 0; b < nb; ++b) {
      if (d[std::size_t(b)] > o.tie_factor * dmin + 1e-12 * diag) continue;
      if (rays && rays->blocked(p, c[std::size_t(b)], std::min(1e-4 * diag, 0.1 * d[std::size_t(b)]))) continue;
      heated.push_back(b);
    }
    if (heated.empty()) continue;
    const double dd = std::max(dmin, 1e-6 * diag);
    heat(i) = o.heat / (dd * dd);
    for (int b : heated) P(i, b) = 1.0 / double(heated.size());
  }

  // A component no bone can see (an open layer of cloth around the body, a mesh around a
  // skeleton placed outside it) is heated from its nearest bones without the visibility test.
  Eigen::VectorXi comp;
  const int ncomp = connected_components(F, n, comp);
  std::vector<char> heated_comp(std::size_t(ncomp), 0);
  for (Eigen::Index i = 0; i < n; ++i)
    if (heat(i) > 0) heated_comp[std::size_t(comp(i))] = 1;
  for (Eigen::Index i = 0; i < n; ++i) {
    if (heated_comp[std::size_t(comp(i))]) continue;
    const Eigen::Vector3d p = V.row(i).transpose();
    double dmin = std::numeric_limits<double>::infinity();
    std::vector<double> d(static_cast<std::size_t>(nb));
    for (int b = 0; b < nb; ++b) {
      d[std::size_t(b)] = segment_distance(p, skeleton.restPosition(bones[std::size_t(b)].joint),
                                           skeleton.restPosition(bones[std::size_t(b)].child), nullptr);
      dmin = std::min(dmin, d[std::size_t(b)]);
    }
    int ties = 0;
    for (int b = 0; b < nb; ++b) ties += d[std::size_t(b)] <= o.tie_factor * dmin + 1e-12 * diag;
    for (int b = 0; b < nb; ++b) P(i, b) = d[std::size_t(b)] <= o.tie_factor * dmin + 1e-12 * diag ? 1.0 / ties : 0.0;
    const double dd = std::max(dmin, 1e-6 * diag);
    heat(i) = o.heat / (dd * dd);
  }

  const Eigen::SparseMatrix<double> C = cotangent_matrix(V, F);
  const Eigen::VectorXd M = voronoi_areas(V, F);
  Eigen::SparseMatrix<double> A = -C;
  Eigen::VectorXd mh = M.cwiseProduct(heat);
  for (Eigen::Index i = 0; i < n; ++i) {
    // isolated vertices (no faces): give them their nearest bone outright
    if (M(i) <= 0) mh(i) = 1, P.row(i).setZero(), P(i, nearest[std::size_t(i)]) = 1;
    A.coeffRef(i, i) += mh(i);
  }
  SparseCholesky solver;
  solver.compute(A);
  const Eigen::MatrixXd Wb = solver.solve(mh.asDiagonal() * P);

  std::vector<Eigen::Triplet<double>> trip;
  trip.reserve(std::size_t(n) * std::size_t(o.max_influences));
  for (Eigen::Index i = 0; i < n; ++i) {
    std::vector<double> per_joint(std::size_t(skeleton.numJoints()), 0.0);
    for (int b = 0; b < nb; ++b) per_joint[std::size_t(bones[std::size_t(b)].joint)] += std::max(0.0, Wb(i, b));
    std::vector<std::pair<double, int>> row;
    for (int j = 0; j < skeleton.numJoints(); ++j)
      if (per_joint[std::size_t(j)] > 0) row.emplace_back(per_joint[std::size_t(j)], j);
    if (row.empty()) row.emplace_back(1.0, bones[std::size_t(nearest[std::size_t(i)])].joint);
    sparsify_row(row, o.max_influences, o.min_weight);
    for (const auto& e : row) trip.emplace_back(int(i), e.second, e.first);
  }
  SkinningWeights W(n, skeleton.numJoints());
  W.setFromTriplets(trip.begin(), trip.end());
  return W;
}

namespace {

void check_skinning_input(const Eigen::MatrixX3d& V, const SkinningWeights& W, const std::vector<Eigen::Isometry3d>& T,
                          const char* where) {
  if (W.rows() != V.rows() || W.cols() != Eigen::Index(T.size()))
    throw InvalidInput(std::string("[") + where + "] weights are " + std::to_string(W.rows()) + " x " + std::to_string(W.cols()) +
                       ", expected #V (" + std::to_string(V.rows()) + ") x #transforms (" + std::to_string(T.size()) + ")");
}

}  // namespace

Eigen::MatrixX3d dual_quaternion_skinning(const Eigen::MatrixX3d& V, const SkinningWeights& W,
                                          const std::vector<Eigen::Isometry3d>& T) {
  check_skinning_input(V, W, T, "tbsp::dual_quaternion_skinning");
  const std::size_t nj = T.size();
  std::vector<Eigen::Vector4d> q0(nj), qe(nj);  // (w, x, y, z)
  for (std::size_t j = 0; j < nj; ++j) {
    const Eigen::Quaterniond r(T[j].rotation());
    const Eigen::Vector3d t = T[j].translation();
    q0[j] = Eigen::Vector4d(r.w(), r.x(), r.y(), r.z()).normalized();
    // qe = 0.5 * (0, t) * q0
    const double w = q0[j](0);
    const Eigen::Vector3d v = q0[j].tail<3>();
    qe[j](0) = -0.5 * t.dot(v);
    qe[j].tail<3>() = 0.5 * (w * t + t.cross(v));
  }
  Eigen::MatrixX3d out(V.rows(), 3);
#pragma omp parallel for schedule(static)
  for (Eigen::Index i = 0; i < V.rows(); ++i) {
    int pivot = -1;
    double wmax = -1;
    for (SkinningWeights::InnerIterator it(W, i); it; ++it)
      if (it.value() > wmax) wmax = it.value(), pivot = int(it.col());
    if (pivot < 0) {
      out.row(i) = V.row(i);
      continue;
    }
    Eigen::Vector4d b0 = Eigen::Vector4d::Zero(), be = Eigen::Vector4d::Zero();
    for (SkinningWeights::InnerIterator it(W, i); it; ++it) {
      const std::size_t j = std::size_t(it.col());
      const double s = q0[j].dot(q0[std::size_t(pivot)]) < 0 ? -it.value() : it.value();
      b0 += s * q0[j];
      be += s * qe[j];
    }
    const double len = b0.norm();
    b0 /= len;
    be /= len;
    const double w0 = b0(0), we = be(0);
    const Eigen::Vector3d v0 = b0.tail<3>(), ve = be.tail<3>();
    const Eigen::Vector3d p = V.row(i).transpose();
    // rotate p by the unit quaternion b0, translate by 2 (w0 ve − we v0 + v0 × ve)
    const Eigen::Vector3d rp = p + 2.0 * v0.cross(v0.cross(p) + w0 * p);
    const Eigen::Vector3d t = 2.0 * (w0 * ve - we * v0 + v0.cross(ve));
    out.row(i) = (rp + t).transpose();
  }
  return out;
}

Eigen::MatrixX3d linear_blend_skinning(const Eigen::MatrixX3d& V, const SkinningWeights& W,
                                       const std::vector<Eigen::Isometry3d>& T) {
  check_skinning_input(V, W, T, "tbsp::linear_blend_skinning");
  Eigen::MatrixX3d out(V.rows(), 3);
#pragma omp parallel for schedule(static)
  for (Eigen::Index i = 0; i < V.rows(); ++i) {
    Eigen::Vector3d p = Eigen::Vector3d::Zero();
    for (SkinningWeights::InnerIterator it(W, i); it; ++it) p += it.value() * (T[std::size_t(it.col())] * V.row(i).transpose());
    if (W.row(i).nonZeros()) out.row(i) = p.transpose(); else out.row(i) = V.row(i);
  }
  return out;
}

}  // namespace tbsp
