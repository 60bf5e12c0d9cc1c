#include "capture_pose.h"

#include <algorithm>
#include <cmath>

#include <cblas.h>
#include <nlopt.h>

#include "tbsp/core/error.h"
#include "tbsp/multiview/rasterizer.h"
#include "silhouette_match.h"

namespace tbsp::detail {

namespace {
double median(std::vector<double> v) {
  if (v.empty()) return 0;
  std::nth_element(v.begin(), v.begin() + long(v.size() / 2), v.end());
  return v[v.size() / 2];
}
}  // namespace

Eigen::MatrixXd handle_stiffness(const Eigen::MatrixXd& R, const Eigen::MatrixX2i& edges) {
  Eigen::MatrixXd D(edges.rows(), R.cols());
  for (Eigen::Index e = 0; e < edges.rows(); ++e) D.row(e) = R.row(edges(e, 0)) - R.row(edges(e, 1));
  return D.transpose() * D;
}

Eigen::Matrix3d constraint_projector(const RayConstraint& c) {
  if (c.plane_normal.squaredNorm() > 0) return c.plane_normal * c.plane_normal.transpose();
  const Eigen::Vector3d d = c.dir.normalized();
  return Eigen::Matrix3d::Identity() - d * d.transpose();
}

int constraint_projector_basis(const RayConstraint& c, Eigen::Vector3d u[2]) {
  if (c.plane_normal.squaredNorm() > 0) {
    u[0] = c.plane_normal.normalized();
    return 1;
  }
  const Eigen::Vector3d d = c.dir.normalized();
  u[0] = d.unitOrthogonal();
  u[1] = d.cross(u[0]);
  return 2;
}

Eigen::MatrixXd assemble_constraint_normals(const Eigen::MatrixXd& M, const std::vector<RayConstraint>& C, const std::vector<double>& omega) {
  const Eigen::Index H = M.cols(), n3 = 3 * H;
  Eigen::MatrixXd N = Eigen::MatrixXd::Zero(n3, n3);
  // N = Jᵀ J with one row of J per projector direction u of a constraint i:
  // J_row = sqrt(ω_i) / s_i · (u ⊗ m_i) (column block c holds u_c · m_i), since
  // P_i ⊗ m_i m_iᵀ = Σ_u (u ⊗ m_i)(u ⊗ m_i)ᵀ. Rows go to BLAS in fixed blocks (symmetric rank-k
  // updates of the lower triangle): the summation order does not depend on the thread count.
  constexpr Eigen::Index kBlock = 1024;
  const Eigen::MatrixXd Mt = M.transpose();
  Eigen::MatrixXd Jt(n3, kBlock);  // Jᵀ: one column per row of J (contiguous writes)
  Eigen::Index rows = 0;
  auto flush = [&]() {
    if (rows == 0) return;
    cblas_dsyrk(CblasColMajor, CblasLower, CblasNoTrans, int(n3), int(rows), 1.0, Jt.data(), int(n3), 1.0, N.data(), int(n3));
    rows = 0;
  };
  for (std::size_t i = 0; i < C.size(); ++i) {
    if (omega[i] == 0) continue;
    Eigen::Vector3d u[2];
    const int rank = constraint_projector_basis(C[i], u);
    const double f = std::sqrt(omega[i]) / C[i].pixel_size;
    for (int r = 0; r < rank; ++r) {
      if (rows == kBlock) flush();
      for (int c = 0; c < 3; ++c) Jt.col(rows).segment(c * H, H) = (f * u[r](c)) * Mt.col(Eigen::Index(i));
      ++rows;
    }
  }
  flush();
  N.triangularView<Eigen::StrictlyUpper>() = N.transpose();
  return N;
}

HandleSolveResult solve_handles(const Eigen::MatrixXd& R, const Eigen::MatrixXd& K, const std::vector<RayConstraint>& C,
                                const HandleSolveOptions& o) {
  const Eigen::Index H = R.cols(), nc = Eigen::Index(C.size());
  HandleSolveResult res;
  res.dh = Eigen::MatrixX3d::Zero(H, 3);
  if (nc == 0 || H == 0) return res;
  // m_i = Σ_k w_k R.row(v_k): how the constrained point moves per unit handle move
  Eigen::MatrixXd M(nc, H);
  std::vector<double> sizes(C.size());
  Eigen::MatrixX3d r0(nc, 3);  // P_i (p_i - o_i)
  std::vector<Eigen::Matrix3d> P(C.size());
  for (Eigen::Index i = 0; i < nc; ++i) {
    const RayConstraint& c = C[std::size_t(i)];
    M.row(i).setZero();
    for (int a = 0; a < 4; ++a)
      if (c.v[std::size_t(a)] >= 0) M.row(i) += c.w[std::size_t(a)] * R.row(c.v[std::size_t(a)]);
    P[std::size_t(i)] = constraint_projector(c);
    r0.row(i) = (P[std::size_t(i)] * (c.p - c.origin)).transpose();
    sizes[std::size_t(i)] = c.pixel_size;
  }
  const double sbar = median(sizes);
  std::vector<double> omega(C.size());
  for (std::size_t i = 0; i < C.size(); ++i) omega[i] = C[i].weight;
  std::vector<double> resid(C.size(), 0.0);
  for (int round = 0; round <= o.reweights; ++round) {
    Eigen::MatrixXd N = assemble_constraint_normals(M, C, omega);
    Eigen::VectorXd b = Eigen::VectorXd::Zero(3 * H);
    Eigen::VectorXd a(nc);
    for (int c = 0; c < 3; ++c) {
      for (Eigen::Index i = 0; i < nc; ++i) {
        const RayConstraint& k = C[std::size_t(i)];
        a(i) = omega[std::size_t(i)] / (k.pixel_size * k.pixel_size);
      }
      // b_c = -Σ_i a_i m_i (P_i r0_i)_c  (P r0 = r0 since P is a projection)
      b.segment(c * H, H) = -M.transpose() * (a.asDiagonal() * r0.col(c));
    }
    for (int c = 0; c < 3; ++c) N.block(c * H, c * H, H, H) += (o.smoothness / (sbar * sbar)) * K;
    N.diagonal().array() += o.prior / (sbar * sbar);
    const Eigen::VectorXd x = N.ldlt().solve(b);
    for (int c = 0; c < 3; ++c) res.dh.col(c) = x.segment(c * H, H);
    const Eigen::MatrixX3d move = M * res.dh;
    for (Eigen::Index i = 0; i < nc; ++i)
      resid[std::size_t(i)] = (P[std::size_t(i)] * (r0.row(i) + move.row(i)).transpose()).norm() / C[std::size_t(i)].pixel_size;
    if (round == o.reweights) break;
    for (std::size_t i = 0; i < C.size(); ++i) {
      const double r = resid[i];
      omega[i] = r > o.reject_px ? 0.0 : C[i].weight * (r <= o.robust_px ? 1.0 : o.robust_px / r);
    }
  }
  std::vector<double> in;
  for (std::size_t i = 0; i < C.size(); ++i) {
    if (resid[i] > o.reject_px) continue;
    in.push_back(resid[i]);
    (C[i].feature ? res.feature_inliers : res.rim_inliers)++;
  }
  res.median_residual_px = median(in);
  return res;
}

namespace {

struct Problem {
  TetDeformer* D;
  const std::vector<int>* key;
  const std::vector<Eigen::Vector3d>* targets;
  const HandleOptimization* o;
  std::vector<Eigen::Matrix3d> R0;
  Rasterizer rast;
  std::vector<RenderBuffers> buf;
  TriMesh surf;
  int evaluations = 0;
  double last_overlap = 0;
  std::vector<SilhouetteView> views;  // o->silhouettes, prepared once for the overlap counts

  double overlap(const Eigen::MatrixX3d& X) {
    if (views.empty()) {
      views.resize(o->silhouettes.size());
      for (std::size_t k = 0; k < views.size(); ++k) views[k].set(o->silhouettes[k]);
    }
    surf.V = X;
    rast.renderViews(surf, o->cameras, buf);
    double iou = 0;
    for (std::size_t k = 0; k < buf.size(); ++k) iou += silhouette_overlap(buf[k], views[k]).iou;
    return iou / double(buf.size());
  }
  // Sets the offsets, restores the rotations, one deformer iteration.
  Eigen::MatrixX3d apply(const double* x) {
    for (std::size_t k = 0; k < key->size(); ++k)
      D->setHandleTarget((*key)[k], (*targets)[k] + Eigen::Vector3d(x[3 * k], x[3 * k + 1], x[3 * k + 2]));
    D->setRotations(R0);
    D->iterate();
    return D->positions();
  }
  double value(const double* x) {
    ++evaluations;
    const Eigen::MatrixX3d X = apply(x);
    last_overlap = overlap(X);
    double dist = 0;
    for (std::size_t i = 0; i < 3 * key->size(); ++i) dist += (x[i] / o->step) * (x[i] / o->step);
    return (1.0 - last_overlap) + o->nonrigid_weight * D->nonrigidEnergy(X) + o->distance_weight * 1e-3 * dist;
  }
};

double objective(unsigned, const double* x, double*, void* data) { return static_cast<Problem*>(data)->value(x); }

}  // namespace

int optimize_handles(TetDeformer& D, const std::vector<int>& key, const std::vector<Eigen::Vector3d>& targets, const HandleOptimization& o,
                     double& overlap_before, double& overlap_after) {
  RasterOptions ro;
  ro.barycentrics = false;
  Problem pb{&D, &key, &targets, &o, D.rotations(), Rasterizer(ro), {}, {}, 0, 0, {}};
  pb.surf.F = o.surface;
  const unsigned dim = unsigned(3 * key.size());
  std::vector<double> x(dim, 0.0), lo(dim, -3 * o.step), hi(dim, 3 * o.step);
  const double f0 = pb.value(x.data());
  overlap_before = pb.last_overlap;
  nlopt_opt opt = nlopt_create(NLOPT_LN_BOBYQA, dim);
  if (!opt) throw Error("[tbsp::PerformanceCapture] NLopt could not create the BOBYQA optimizer");
  nlopt_set_min_objective(opt, objective, &pb);
  nlopt_set_lower_bounds(opt, lo.data());
  nlopt_set_upper_bounds(opt, hi.data());
  nlopt_set_initial_step1(opt, o.step);
  nlopt_set_xtol_abs1(opt, 1e-3 * o.step);
  nlopt_set_maxeval(opt, o.max_evaluations);
  double fmin = f0;
  std::vector<double> best = x;
  const nlopt_result r = nlopt_optimize(opt, best.data(), &fmin);
  nlopt_destroy(opt);
  if (r < 0 || !(fmin < f0)) std::fill(best.begin(), best.end(), 0.0);  // failed or no gain: keep the start
  pb.apply(best.data());
  overlap_after = pb.overlap(D.positions());
  return pb.evaluations;
}

}  // namespace tbsp::detail
