#include "tbsp/cloth/cloth_segmentation.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>

#include "ray_caster.h"
#include "tbsp/core/error.h"
#include "tbsp/mesh/cotan_laplacian.h"
#include "tbsp/mesh/topology.h"
#include "tbsp/mesh/tri_mesh.h"
#include "tbsp/solve/sparse_cholesky.h"

namespace tbsp {

namespace {
const char* kSegmentationWhere = "[tbsp::ClothSegmentation] ";
}

void ClothSegmentation::setOptions(const ClothSegmentationOptions& o) {
  if (!(o.t_rigid >= 0) || !(o.t_cloth > o.t_rigid) || !std::isfinite(o.t_cloth))
    throw InvalidInput(std::string(kSegmentationWhere) + "setOptions: need 0 ≤ t_rigid < t_cloth (got " + std::to_string(o.t_rigid) + ", " +
                       std::to_string(o.t_cloth) + ")");
  if (!(o.diffusion >= 0 && o.diffusion <= 1e4)) throw InvalidInput(std::string(kSegmentationWhere) + "setOptions: diffusion must be in [0, 1e4]");
  if (o.median_passes < 0 || o.median_passes > 10) throw InvalidInput(std::string(kSegmentationWhere) + "setOptions: median_passes must be in 0..10");
  options_ = o;
}

void ClothSegmentation::begin(const Eigen::MatrixX3d& V, const Eigen::MatrixX3i& F) {
  if (V.rows() == 0 || F.rows() == 0) throw InvalidInput(std::string(kSegmentationWhere) + "begin: the first frame is empty");
  if (!V.allFinite()) throw InvalidInput(std::string(kSegmentationWhere) + "begin: the first frame has non-finite coordinates");
  if (F.minCoeff() < 0 || F.maxCoeff() >= V.rows())
    throw InvalidInput(std::string(kSegmentationWhere) + "begin: a face index is out of range (" + std::to_string(V.rows()) + " vertices)");
  V0_ = V;
  F_ = F;
  const Eigen::Index n = V.rows();
  const Eigen::MatrixX3d N = vertex_normals(V, F);
  const double diag = bbox_diagonal(V);
  detail::RayCaster rays(V, F);
  face_ = Eigen::VectorXi::Constant(n, -1);
  bary_ = Eigen::MatrixX3d::Zero(n, 3);
#pragma omp parallel for schedule(dynamic, 256)
  for (Eigen::Index i = 0; i < n; ++i) {
    const Eigen::Vector3d nrm = N.row(i).transpose();
    if (nrm.squaredNorm() == 0) continue;
    const detail::RayHit h = rays.cast(V.row(i).transpose(), -nrm, 1e-7 * diag, 2 * diag, int(i));
    if (h.face < 0) continue;
    face_(i) = h.face;
    bary_.row(i) = h.bary.transpose();
  }
  mean_ = Eigen::VectorXd::Zero(n);
  m2_ = Eigen::VectorXd::Zero(n);
  frames_ = 0;
  addFrame(V);
}

void ClothSegmentation::addFrame(const Eigen::MatrixX3d& V) {
  if (face_.size() == 0) throw InvalidInput(std::string(kSegmentationWhere) + "addFrame: call begin() with the first frame first");
  const int frame = frames_ + 1;
  if (V.rows() != V0_.rows())
    throw InvalidInput(std::string(kSegmentationWhere) + "frame " + std::to_string(frame) + " has " + std::to_string(V.rows()) +
                       " vertices, the first frame " + std::to_string(V0_.rows()) +
                       ": a sequence must keep its connectivity (track one template through it)");
  for (Eigen::Index i = 0; i < V.rows(); ++i)
    if (!V.row(i).allFinite())
      throw InvalidInput(std::string(kSegmentationWhere) + "frame " + std::to_string(frame) + ", vertex " + std::to_string(i) +
                         " is not finite (NaN/Inf): repair or drop the frame");
  ++frames_;
  for (Eigen::Index i = 0; i < V.rows(); ++i) {
    if (face_(i) < 0) continue;
    const int f = face_(i);
    const Eigen::Vector3d p = bary_(i, 0) * V.row(F_(f, 0)).transpose() + bary_(i, 1) * V.row(F_(f, 1)).transpose() +
                              bary_(i, 2) * V.row(F_(f, 2)).transpose();
    const double d = (V.row(i).transpose() - p).norm();
    // Welford
    const double delta = d - mean_(i);
    mean_(i) += delta / frames_;
    m2_(i) += delta * (d - mean_(i));
  }
}

ClothSegmentation::Result ClothSegmentation::finish() const {
  if (face_.size() == 0) throw InvalidInput(std::string(kSegmentationWhere) + "finish: no sequence (call begin and addFrame)");
  if (frames_ < 2) throw InvalidInput(std::string(kSegmentationWhere) + "finish: " + std::to_string(frames_) + " frame(s); σ needs at least 2");
  const Eigen::Index n = V0_.rows();
  const double diag = bbox_diagonal(V0_);
  Result r;
  r.frames = frames_;
  r.t_rigid = options_.t_rigid * diag;
  r.t_cloth = options_.t_cloth * diag;
  r.opposite_face = face_;
  r.opposite_bary = bary_;
  const double nan = std::numeric_limits<double>::quiet_NaN();
  r.sigma = Eigen::VectorXd::Constant(n, nan);
  r.raw = Eigen::VectorXd::Constant(n, nan);
  Eigen::VectorXd known = Eigen::VectorXd::Zero(n);
  for (Eigen::Index i = 0; i < n; ++i) {
    if (face_(i) < 0) continue;
    r.sigma(i) = std::sqrt(std::max(0.0, m2_(i) / frames_));
    r.raw(i) = std::clamp((r.sigma(i) - r.t_rigid) / (r.t_cloth - r.t_rigid), 0.0, 1.0);
    known(i) = 1;
  }
  // robust first: `median_passes` one-ring median filters over the vertices with a hit remove
  // isolated outliers (a ray that left through a hole in the scan and met a moving part)
  Eigen::VectorXd data = r.raw;
  if (options_.median_passes > 0) {
    const std::vector<std::vector<int>> adj = vertex_adjacency(F_, n);
    for (int pass = 0; pass < options_.median_passes; ++pass) {
      Eigen::VectorXd next = data;
      std::vector<double> vals;
      for (Eigen::Index i = 0; i < n; ++i) {
        if (!known(i)) continue;
        vals.assign(1, data(i));
        for (int j : adj[std::size_t(i)])
          if (known(j)) vals.push_back(data(j));
        std::nth_element(vals.begin(), vals.begin() + std::ptrdiff_t(vals.size() / 2), vals.end());
        next(i) = vals[vals.size() / 2];
      }
      data = next;
    }
  }
  // diffusion: (M_known + τ (−C)) δ = M_known δ_raw with M the vertex areas; vertices without a
  // hit have no data term and are filled from their neighbours
  const Eigen::VectorXd area = voronoi_areas(V0_, F_);
  const Eigen::MatrixX2i E = unique_edges(F_);
  double mean_edge = 0;
  for (Eigen::Index e = 0; e < E.rows(); ++e) mean_edge += (V0_.row(E(e, 0)) - V0_.row(E(e, 1))).norm();
  mean_edge /= std::max<Eigen::Index>(1, E.rows());
  const double tau = std::max(options_.diffusion, 1e-9) * mean_edge * mean_edge;
  Eigen::SparseMatrix<double> A = -tau * cotangent_matrix(V0_, F_);
  Eigen::VectorXd rhs = Eigen::VectorXd::Zero(n);
  const double mean_area = area.sum() / double(n);
  Eigen::VectorXi comp;
  const int ncomp = connected_components(F_, n, comp);
  std::vector<char> comp_known(std::size_t(ncomp), 0);
  for (Eigen::Index i = 0; i < n; ++i) {
    const double m = known(i) ? std::max(area(i), 1e-9 * mean_area) : 0.0;
    A.coeffRef(i, i) += m;
    if (known(i)) rhs(i) = m * data(i), comp_known[std::size_t(comp(i))] = 1;
  }
  for (Eigen::Index i = 0; i < n; ++i)  // a component without any hit: δ = 0 there
    if (!comp_known[std::size_t(comp(i))]) A.coeffRef(i, i) += std::max(area(i), 1e-9 * mean_area);
  SparseCholesky solver;
  solver.compute(A);
  r.clothness = solver.solve(rhs).col(0).cwiseMax(0.0).cwiseMin(1.0);
  // the diffusion leaves faint tails: below 0.01 a vertex is body (skinned only, no simulation
  // cost), above 0.99 fully cloth
  for (Eigen::Index i = 0; i < n; ++i) {
    if (r.clothness(i) < 0.01) r.clothness(i) = 0;
    if (r.clothness(i) > 0.99) r.clothness(i) = 1;
  }
  return r;
}

}  // namespace tbsp
