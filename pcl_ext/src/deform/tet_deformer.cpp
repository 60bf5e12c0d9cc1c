#include "tbsp/deform/tet_deformer.h"

#include <Eigen/Geometry>
#include <Eigen/SparseCore>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <map>

#include "tbsp/core/error.h"
#include "tbsp/core/timer.h"
#include "tbsp/core/logging.h"
#include "tbsp/deform/rotations.h"
#include "tbsp/solve/sparse_cholesky.h"

namespace tbsp {

namespace {

using Mat34 = Eigen::Matrix<double, 3, 4, Eigen::RowMajor>;
using Mat3r = Eigen::Matrix<double, 3, 3, Eigen::RowMajor>;

}  // namespace

Eigen::Matrix3d RigidMotion::R() const {
  const double n = axis.norm();
  if (angle == 0.0 || !(n > 0)) return Eigen::Matrix3d::Identity();
  return Eigen::AngleAxisd(angle, axis / n).toRotationMatrix();
}

struct TetDeformer::Solver {
  SparseCholesky chol;
  Eigen::SparseMatrix<double> Af;   // #free x 3#T  (rows of Gᵀ D S for free vertices)
  Eigen::SparseMatrix<double> Lfc;  // #free x #constrained
  Eigen::MatrixX3d Gs;              // 3#T x 3, rotated gradients (step V)
  // rotation interpolation over the tet dual graph
};

bool TetDeformerOptions::isValid(std::string* why) const {
  auto bad = [&](const std::string& m) {
    if (why) *why = m;
    return false;
  };
  if (!(max_handle_step_deg > 0 && max_handle_step_deg < 180))
    return bad("max_handle_step_deg = " + std::to_string(max_handle_step_deg) + " is outside (0, 180) degrees");
  if (!(tolerance > 0 && std::isfinite(tolerance))) return bad("tolerance = " + std::to_string(tolerance) + " must be > 0");
  return true;
}

void TetDeformer::setOptions(const TetDeformerOptions& o) {
  std::string why;
  if (!o.isValid(&why)) throw InvalidInput("[tbsp::TetDeformer::setOptions] " + why);
  options_ = o;
}

TetDeformer::TetDeformer() = default;
TetDeformer::~TetDeformer() = default;

void TetDeformer::requireMesh(const char* who) const {
  if (mesh_.T.rows() == 0) throw InvalidInput(std::string("[tbsp::TetDeformer::") + who + "] no mesh: call setMesh() first");
}

void TetDeformer::checkVertex(int v, const char* who) const {
  requireMesh(who);
  if (v < 0 || v >= mesh_.V.rows())
    throw InvalidInput(std::string("[tbsp::TetDeformer::") + who + "] vertex " + std::to_string(v) +
                       " does not exist (the tet mesh has " + std::to_string(mesh_.V.rows()) + " vertices)");
}

void TetDeformer::setMesh(const TetMesh& mesh) {
  require_valid_tet_mesh(mesh, "tbsp::TetDeformer::setMesh");
  mesh_ = mesh;
  const Eigen::Index flipped = orient_tets(mesh_);
  if (flipped > 0) logger()->debug("TetDeformer: re-oriented {} of {} tetrahedra", flipped, mesh_.T.rows());
  rest_ = mesh_.V;
  n_input_vertices_ = mesh_.V.rows();
  n_input_tets_ = mesh_.T.rows();
  parent_.resize(std::size_t(n_input_tets_));
  for (Eigen::Index t = 0; t < n_input_tets_; ++t) parent_[std::size_t(t)] = int(t);
  virtual_.assign(std::size_t(n_input_tets_), 0);
  stiffness_input_ = Eigen::VectorXd::Ones(n_input_tets_);
  handles_.clear();
  rigid_regions_.clear();
  diag_ = std::max(bbox_diagonal(mesh_.V), 1e-300);
  solver_.reset();
  operators_dirty_ = constrained_dirty_ = true;
  report_ = {};
  reset();
}

void TetDeformer::setStiffness(const Eigen::VectorXd& s) {
  requireMesh("setStiffness");
  if (s.size() != n_input_tets_)
    throw InvalidInput("[tbsp::TetDeformer::setStiffness] " + std::to_string(s.size()) + " values given for " +
                       std::to_string(n_input_tets_) + " tetrahedra; give one stiffness per input tetrahedron");
  for (Eigen::Index i = 0; i < s.size(); ++i)
    if (!(s(i) > 0) || !std::isfinite(s(i)))
      throw InvalidInput("[tbsp::TetDeformer::setStiffness] stiffness of tet " + std::to_string(i) + " is " +
                         std::to_string(s(i)) + "; it must be a finite value > 0 (use rigid regions for rigidity)");
  stiffness_input_ = s;
  operators_dirty_ = true;
}

void TetDeformer::reset() {
  X_ = rest_;
  R_.assign(std::size_t(mesh_.T.rows()), Eigen::Matrix3d::Identity());
  for (auto& h : handles_) {
    if (h.kind == Handle::Region) {
      h.from_motion = RigidMotion::identity();
      h.from_motion.center = h.motion.center;
    } else {
      h.from_target = rest_.row(h.vertices[0]).transpose();
    }
  }
  ramp_iteration_ = 0;
  ramp_steps_ = rampSteps();
  constrained_dirty_ = true;
  report_.iterations = 0;
  report_.converged = false;
  report_.e_nonrigid.clear();
  report_.e_arap.clear();
  report_.max_move.clear();
  report_.t_def = report_.t_rotext = report_.t_rotint = report_.t_rigid = report_.t_difupd = 0;
  if (solver_ && !operators_dirty_) {
    solver_->Gs.resize(3 * mesh_.T.rows(), 3);
    for (Eigen::Index j = 0; j < mesh_.T.rows(); ++j)
      solver_->Gs.middleRows<3>(3 * j) = Eigen::Map<const Mat3r>(g_.row(j).data());
  }
}

void TetDeformer::setRotations(const std::vector<Eigen::Matrix3d>& R) {
  requireMesh("setRotations");
  if (Eigen::Index(R.size()) != mesh_.T.rows())
    throw InvalidInput("[tbsp::TetDeformer::setRotations] " + std::to_string(R.size()) + " rotations for " +
                       std::to_string(mesh_.T.rows()) + " tetrahedra");
  prepare();
  R_ = R;
  for (Eigen::Index j = 0; j < mesh_.T.rows(); ++j)
    solver_->Gs.middleRows<3>(3 * j) = Eigen::Map<const Mat3r>(g_.row(j).data()) * R_[std::size_t(j)].transpose();
}

void TetDeformer::buildOperators() {
  const auto t0 = Clock::now();
  const Eigen::Index n = mesh_.V.rows(), m = mesh_.T.rows();
  if (handles_.empty())
    throw InvalidInput("[tbsp::TetDeformer] no handles: the deformation is undetermined. Add at least one vertex, region or "
                       "point handle (addVertexHandle / addRegionHandle / addPointHandle)");
  // constrained vertices
  std::vector<int> owner(std::size_t(n), -1), slot(std::size_t(n), -1);
  for (std::size_t hi = 0; hi < handles_.size(); ++hi)
    for (std::size_t k = 0; k < handles_[hi].vertices.size(); ++k) {
      const int v = handles_[hi].vertices[k];
      if (owner[std::size_t(v)] >= 0 && owner[std::size_t(v)] != int(hi))
        throw InvalidInput("[tbsp::TetDeformer] vertex " + std::to_string(v) + " belongs to handle " +
                           std::to_string(owner[std::size_t(v)]) + " and handle " + std::to_string(hi) +
                           "; a vertex can follow one handle only");
      owner[std::size_t(v)] = int(hi);
      slot[std::size_t(v)] = int(k);
    }
  free_index_.assign(std::size_t(n), -1);
  constrained_index_.assign(std::size_t(n), -1);
  free_vertices_.clear();
  constrained_vertices_.clear();
  constraint_handle_.clear();
  constraint_slot_.clear();
  std::vector<char> used(std::size_t(n), 0);
  for (Eigen::Index t = 0; t < m; ++t)
    for (int k = 0; k < 4; ++k) used[std::size_t(mesh_.T(t, k))] = 1;
  for (Eigen::Index v = 0; v < n; ++v) {
    if (owner[std::size_t(v)] >= 0 || !used[std::size_t(v)]) {
      constrained_index_[std::size_t(v)] = int(constrained_vertices_.size());
      constrained_vertices_.push_back(int(v));
      constraint_handle_.push_back(owner[std::size_t(v)]);  // -1: unreferenced vertex, kept in place
      constraint_slot_.push_back(slot[std::size_t(v)]);
    } else {
      free_index_[std::size_t(v)] = int(free_vertices_.size());
      free_vertices_.push_back(int(v));
    }
  }
  // every component needs a handle
  Eigen::VectorXi labels;
  const int nc = tet_connected_components(mesh_, labels);
  std::vector<char> anchored(std::size_t(nc), 0);
  for (int v : constrained_vertices_)
    if (owner[std::size_t(v)] >= 0) anchored[std::size_t(labels(v))] = 1;
  for (Eigen::Index v = 0; v < n; ++v)
    if (used[std::size_t(v)] && !anchored[std::size_t(labels(v))])
      throw InvalidInput("[tbsp::TetDeformer] the connected part containing vertex " + std::to_string(v) +
                         " has no handle, so it is free to float away; add a handle on it");

  // gradient operators
  G_.resize(m, 12);
  g_.resize(m, 9);
  weight_.resize(m);
  rest_volume_ = tet_signed_volumes(rest_, mesh_.T);
  for (Eigen::Index j = 0; j < m; ++j) {
    Eigen::Matrix3d E;
    for (int k = 0; k < 3; ++k) E.row(k) = rest_.row(mesh_.T(j, k)) - rest_.row(mesh_.T(j, 3));
    const Eigen::Matrix3d Ei = E.inverse();
    Mat34 Gj;
    Gj.leftCols<3>() = Ei;
    Gj.col(3) = -Ei.rowwise().sum();
    Eigen::Map<Mat34>(G_.row(j).data()) = Gj;
    Eigen::Matrix<double, 4, 3> Vj;
    for (int k = 0; k < 4; ++k) Vj.row(k) = rest_.row(mesh_.T(j, k));
    Eigen::Map<Mat3r>(g_.row(j).data()) = Gj * Vj;
    const int par = parent_[std::size_t(j)];
    const double s = par >= 0 ? stiffness_input_(par) : 1.0;
    weight_(j) = std::abs(rest_volume_(j)) * s;
  }
  const Eigen::Index nf = Eigen::Index(free_vertices_.size()), ncs = Eigen::Index(constrained_vertices_.size());
  if (nf == 0) logger()->debug("TetDeformer: every vertex is constrained");
  std::vector<Eigen::Triplet<double>> tA, tff, tfc;
  tA.reserve(std::size_t(m) * 12);
  tff.reserve(std::size_t(m) * 16);
  for (Eigen::Index j = 0; j < m; ++j) {
    const Eigen::Map<const Mat34> Gj(G_.row(j).data());
    const Eigen::Matrix4d Lj = weight_(j) * Gj.transpose() * Gj;
    for (int k = 0; k < 4; ++k) {
      const int vk = mesh_.T(j, k), fk = free_index_[std::size_t(vk)];
      if (fk < 0) continue;
      for (int r = 0; r < 3; ++r) tA.emplace_back(fk, int(3 * j + r), weight_(j) * Gj(r, k));
      for (int l = 0; l < 4; ++l) {
        const int vl = mesh_.T(j, l);
        if (free_index_[std::size_t(vl)] >= 0)
          tff.emplace_back(fk, free_index_[std::size_t(vl)], Lj(k, l));
        else
          tfc.emplace_back(fk, constrained_index_[std::size_t(vl)], Lj(k, l));
      }
    }
  }
  solver_ = std::make_unique<Solver>();
  solver_->Af.resize(nf, 3 * m);
  solver_->Af.setFromTriplets(tA.begin(), tA.end());
  solver_->Lfc.resize(nf, ncs);
  solver_->Lfc.setFromTriplets(tfc.begin(), tfc.end());
  Eigen::SparseMatrix<double> Lff(nf, nf);
  Lff.setFromTriplets(tff.begin(), tff.end());
  report_.t_setup = seconds_since(t0);
  const auto t1 = Clock::now();
  if (nf > 0) solver_->chol.compute(Lff);
  report_.t_factorize = seconds_since(t1);
  report_.backend = solver_->chol.backendName();
  solver_->Gs.resize(3 * m, 3);
  for (Eigen::Index j = 0; j < m; ++j)
    solver_->Gs.middleRows<3>(3 * j) = Eigen::Map<const Mat3r>(g_.row(j).data()) * R_[std::size_t(j)].transpose();
  buildRotationInterpolation();
  operators_dirty_ = false;
  constrained_dirty_ = true;
  // report sizes
  report_.vertices = n;
  report_.tets = m;
  report_.constrained_vertices = Eigen::Index(std::count_if(constraint_handle_.begin(), constraint_handle_.end(), [](int h) { return h >= 0; }));
  report_.vertex_handles = report_.region_handles = report_.point_handles = 0;
  for (const auto& h : handles_) {
    if (h.kind == Handle::Vertex) ++report_.vertex_handles;
    if (h.kind == Handle::Region) ++report_.region_handles;
    if (h.kind == Handle::Point) ++report_.point_handles;
  }
  report_.rigid_regions = int(rigid_regions_.size());
}

void TetDeformer::buildRotationInterpolation() {
  // Step (III) interpolates over the vertices with the same operator L and the same
  // eliminated (constrained) vertices as step (I), so it re-uses that factorization. Region-handle
  // vertices carry their handle's rotation increment; other constrained vertices (vertex and
  // point handles) carry none (the identity). A tet's increment is the normalized mean of its
  // vertices'. The interpolation is linear in the handles' quaternions, so it is precomputed
  // here as one harmonic weight per handle (one solve with #regions + 1 right-hand sides); each
  // iteration then only blends the handles' current increments with the per-tet weights.
  const auto t0 = Clock::now();
  int regions = 0;
  for (const auto& h : handles_) regions += h.kind == Handle::Region;
  rotint_active_ = regions >= 1 && int(handles_.size()) >= 2 && !free_vertices_.empty();
  std::vector<int> owner(std::size_t(mesh_.V.rows()), -1);
  for (std::size_t hi = 0; hi < handles_.size(); ++hi)
    if (handles_[hi].kind == Handle::Region)
      for (int v : handles_[hi].vertices) owner[std::size_t(v)] = int(hi);
  report_.rotation_handle_tets = 0;
  for (Eigen::Index j = 0; j < mesh_.T.rows(); ++j) {
    const int h = owner[std::size_t(mesh_.T(j, 0))];
    if (h >= 0 && owner[std::size_t(mesh_.T(j, 1))] == h && owner[std::size_t(mesh_.T(j, 2))] == h && owner[std::size_t(mesh_.T(j, 3))] == h)
      ++report_.rotation_handle_tets;
  }
  rot_groups_.clear();
  rot_tet_weights_.resize(0, 0);
  if (rotint_active_) {
    for (std::size_t hi = 0; hi < handles_.size(); ++hi)
      if (handles_[hi].kind == Handle::Region) rot_groups_.push_back(int(hi));
    const Eigen::Index G = Eigen::Index(rot_groups_.size()) + 1;  // + the identity group
    std::vector<int> group_of(handles_.size(), int(G) - 1);
    for (std::size_t g = 0; g < rot_groups_.size(); ++g) group_of[std::size_t(rot_groups_[g])] = int(g);
    const Eigen::Index nc = Eigen::Index(constrained_vertices_.size());
    Eigen::MatrixXd Wc = Eigen::MatrixXd::Zero(nc, G);
    for (Eigen::Index i = 0; i < nc; ++i) {
      const int h = constraint_handle_[std::size_t(i)];
      Wc(i, h >= 0 ? group_of[std::size_t(h)] : G - 1) = 1.0;
    }
    const Eigen::MatrixXd Wf = solver_->chol.solve(-(solver_->Lfc * Wc));
    rot_tet_weights_.resize(mesh_.T.rows(), G);
    for (Eigen::Index j = 0; j < mesh_.T.rows(); ++j) {
      rot_tet_weights_.row(j).setZero();
      for (int k = 0; k < 4; ++k) {
        const int v = mesh_.T(j, k), f = free_index_[std::size_t(v)];
        rot_tet_weights_.row(j) += 0.25 * (f >= 0 ? Eigen::RowVectorXd(Wf.row(f)) : Eigen::RowVectorXd(Wc.row(constrained_index_[std::size_t(v)])));
      }
    }
  }
  report_.t_factorize_rotint = seconds_since(t0);
}

void TetDeformer::prepare() {
  requireMesh("deform");
  if (operators_dirty_) buildOperators();
}

void TetDeformer::updateConstrained() {
  const double s = std::min(1.0, double(ramp_iteration_ + 1) / double(std::max(1, ramp_steps_)));
  const Eigen::Index nc = Eigen::Index(constrained_vertices_.size());
  Xc_.resize(nc, 3);
  for (Eigen::Index i = 0; i < nc; ++i) {
    const int v = constrained_vertices_[std::size_t(i)], h = constraint_handle_[std::size_t(i)];
    Xc_.row(i) = h < 0 ? Eigen::RowVector3d(rest_.row(v))
                       : Eigen::RowVector3d(handlePosition(handles_[std::size_t(h)], constraint_slot_[std::size_t(i)], s).transpose());
  }
  rhs_c_ = solver_->Lfc * Xc_;
}

double TetDeformer::iterate() {
  prepare();
  const Eigen::Index m = mesh_.T.rows();
  if (ramp_iteration_ == 0) ramp_steps_ = rampSteps();
  const double s = std::min(1.0, double(ramp_iteration_ + 1) / double(std::max(1, ramp_steps_)));
  if (constrained_dirty_ || ramp_iteration_ < ramp_steps_) updateConstrained();
  constrained_dirty_ = false;

  // (III) rotation interpolation. The handles' rotation increments since the previous
  // iteration, ΔR_h = R_h(s_k) R_h(s_{k-1})ᵀ (small: at most max_handle_step), are interpolated
  // harmonically over the tets as quaternions and applied to the current R_j before the solve,
  // so the solve already sees the handles' new orientation. Incremental, hence > 180° total is fine.
  auto t0 = Clock::now();
  if (options_.rotation_interpolation && rotint_active_) {
    const double s_prev = std::min(1.0, double(ramp_iteration_) / double(std::max(1, ramp_steps_)));
    bool any = false;
    std::vector<Eigen::Quaterniond> dq(handles_.size(), Eigen::Quaterniond::Identity());
    for (std::size_t h = 0; h < handles_.size(); ++h)
      if (handles_[h].kind == Handle::Region) {
        Eigen::Quaterniond q(handleRotation(handles_[h], s) * handleRotation(handles_[h], s_prev).transpose());
        if (q.w() < 0) q.coeffs() *= -1;
        dq[h] = q;
        any = any || q.vec().norm() > 1e-15;
      }
    if (any) {
      const Eigen::Index G = Eigen::Index(rot_groups_.size()) + 1;
      Eigen::Matrix<double, Eigen::Dynamic, 4> Q(G, 4);  // the groups' increments (w, x, y, z)
      for (Eigen::Index g = 0; g + 1 < G; ++g) {
        const Eigen::Quaterniond& q = dq[std::size_t(rot_groups_[std::size_t(g)])];
        Q.row(g) << q.w(), q.x(), q.y(), q.z();
      }
      Q.row(G - 1) << 1, 0, 0, 0;
#pragma omp parallel for schedule(static) if (m > 2000)
      for (Eigen::Index j = 0; j < m; ++j) {
        Eigen::Vector4d q = (rot_tet_weights_.row(j) * Q).transpose();
        const double nq = q.norm();
        if (!(nq > 1e-12)) continue;
        q /= nq;
        R_[std::size_t(j)] = Eigen::Quaterniond(q(0), q(1), q(2), q(3)).toRotationMatrix() * R_[std::size_t(j)];
      }
#pragma omp parallel for schedule(static) if (m > 2000)
      for (Eigen::Index j = 0; j < m; ++j)
        solver_->Gs.middleRows<3>(3 * j).noalias() = Eigen::Map<const Mat3r>(g_.row(j).data()) * R_[std::size_t(j)].transpose();
    }
  }
  report_.t_rotint += seconds_since(t0);

  // (I) linear solve
  t0 = Clock::now();
  const Eigen::MatrixX3d Xold = X_;
  if (!free_vertices_.empty()) {
    const Eigen::MatrixX3d b = solver_->Af * solver_->Gs - rhs_c_;
    const Eigen::MatrixXd Xf = solver_->chol.solve(b);
    for (std::size_t i = 0; i < free_vertices_.size(); ++i) X_.row(free_vertices_[i]) = Xf.row(Eigen::Index(i));
  }
  for (std::size_t i = 0; i < constrained_vertices_.size(); ++i) X_.row(constrained_vertices_[i]) = Xc_.row(Eigen::Index(i));
  report_.t_def += seconds_since(t0);

  // (II) rotation extraction
  t0 = Clock::now();
  Xrow_ = X_;  // row-major copy: the four corners of a tet are 4 contiguous triples
  // per-tet terms, summed in tet order below: the energies (and the convergence test on them)
  // do not depend on the number of threads
  tet_e2_.resize(m);
#pragma omp parallel for schedule(static) if (m > 2000)
  for (Eigen::Index j = 0; j < m; ++j) {
    const Eigen::Map<const Mat34> Gj(G_.row(j).data());
    Eigen::Matrix<double, 4, 3> Xj;
    for (int k = 0; k < 4; ++k) Xj.row(k) = Xrow_.row(mesh_.T(j, k));
    const Eigen::Matrix3d F = (Gj * Xj).transpose();  // deformation gradient x' = F x
    const Eigen::Matrix3d R = polar_rotation(F, R_[std::size_t(j)]);
    R_[std::size_t(j)] = R;
    // S = Rᵀ F; ‖F − R‖ = ‖S − I‖ for orthogonal R
    tet_e2_(j) = (R.transpose() * F - Eigen::Matrix3d::Identity()).squaredNorm();
  }
  double energy = 0, arap = 0;
  for (Eigen::Index j = 0; j < m; ++j) {
    energy += std::sqrt(tet_e2_(j));
    arap += weight_(j) * tet_e2_(j);
  }
  report_.t_rotext += seconds_since(t0);

  // (IV) rigid regions
  t0 = Clock::now();
  if (!rigid_regions_.empty()) {
    std::vector<int> region_of(std::size_t(n_input_tets_), -1);
    for (std::size_t r = 0; r < rigid_regions_.size(); ++r)
      for (int t : rigid_regions_[r]) region_of[std::size_t(t)] = int(r);
    std::vector<Eigen::Matrix3d> sum(rigid_regions_.size(), Eigen::Matrix3d::Zero());
    for (Eigen::Index j = 0; j < m; ++j) {
      const int p = parent_[std::size_t(j)];
      if (p >= 0 && region_of[std::size_t(p)] >= 0) sum[std::size_t(region_of[std::size_t(p)])] += weight_(j) * R_[std::size_t(j)];
    }
    for (auto& M : sum) M = closest_rotation(M);
    for (Eigen::Index j = 0; j < m; ++j) {
      const int p = parent_[std::size_t(j)];
      if (p >= 0 && region_of[std::size_t(p)] >= 0) R_[std::size_t(j)] = sum[std::size_t(region_of[std::size_t(p)])];
    }
  }
  report_.t_rigid += seconds_since(t0);

  // (V) differential coordinate update
  t0 = Clock::now();
  Eigen::MatrixX3d& Gs = solver_->Gs;
#pragma omp parallel for schedule(static) if (m > 2000)
  for (Eigen::Index j = 0; j < m; ++j)
    Gs.middleRows<3>(3 * j).noalias() = Eigen::Map<const Mat3r>(g_.row(j).data()) * R_[std::size_t(j)].transpose();
  report_.t_difupd += seconds_since(t0);

  const double move = (X_ - Xold).rowwise().norm().maxCoeff() / diag_;
  report_.e_nonrigid.push_back(energy);
  report_.e_arap.push_back(arap);
  report_.max_move.push_back(move);
  ++report_.iterations;
  ++ramp_iteration_;
  return energy;
}

Eigen::MatrixXd TetDeformer::handleResponse(const std::vector<int>& vertices) {
  prepare();
  for (int v : vertices) checkVertex(v, "handleResponse");
  const Eigen::Index nc = Eigen::Index(constrained_vertices_.size()), H = Eigen::Index(handles_.size());
  Eigen::MatrixXd E = Eigen::MatrixXd::Zero(nc, H);  // constrained vertex <- handle (unit move)
  for (Eigen::Index i = 0; i < nc; ++i) {
    const int h = constraint_handle_[std::size_t(i)];
    if (h >= 0 && handles_[std::size_t(h)].kind != Handle::Region) E(i, h) = 1.0;
  }
  Eigen::MatrixXd Yf;
  if (!free_vertices_.empty()) Yf = solver_->chol.solve(-(solver_->Lfc * E));
  Eigen::MatrixXd out(Eigen::Index(vertices.size()), H);
  for (std::size_t k = 0; k < vertices.size(); ++k) {
    const int v = vertices[k], f = free_index_[std::size_t(v)];
    out.row(Eigen::Index(k)) = f >= 0 ? Yf.row(f) : E.row(constrained_index_[std::size_t(v)]);
  }
  return out;
}

double TetDeformer::nonrigidEnergy(const Eigen::MatrixX3d& X) const {
  if (X.rows() != mesh_.V.rows()) throw InvalidInput("[tbsp::TetDeformer::nonrigidEnergy] wrong number of positions");
  double e = 0;
  for (Eigen::Index j = 0; j < mesh_.T.rows(); ++j) {
    Eigen::Matrix3d E, Ed;
    for (int k = 0; k < 3; ++k) {
      E.col(k) = (rest_.row(mesh_.T(j, k)) - rest_.row(mesh_.T(j, 3))).transpose();
      Ed.col(k) = (X.row(mesh_.T(j, k)) - X.row(mesh_.T(j, 3))).transpose();
    }
    const Eigen::Matrix3d F = Ed * E.inverse();
    e += (closest_rotation(F).transpose() * F - Eigen::Matrix3d::Identity()).norm();
  }
  return e;
}

Eigen::MatrixX3d TetDeformer::deform(int max_iterations) {
  prepare();
  const double tol = options_.tolerance;
  for (int k = 0; k < max_iterations; ++k) {
    iterate();
    report_progress(progress_, double(k + 1) / double(max_iterations), "tet iterations");
    if (ramp_iteration_ >= ramp_steps_ && report_.max_move.back() < tol) {
      report_.converged = true;
      break;
    }
  }
  // final statistics
  const Eigen::VectorXd v0 = tet_signed_volumes(rest_, mesh_.T), v1 = tet_signed_volumes(X_, mesh_.T);
  double a = 0, b = 0;
  for (Eigen::Index j = 0; j < mesh_.T.rows(); ++j)
    if (!virtual_[std::size_t(j)]) {
      a += v0(j);
      b += v1(j);
    }
  report_.volume_ratio = a != 0 ? b / a : 1.0;
  double res = 0;
  for (const auto& h : handles_)
    for (std::size_t k = 0; k < h.vertices.size(); ++k)
      res = std::max(res, (X_.row(h.vertices[k]).transpose() - handlePosition(h, int(k), 1.0)).norm());
  report_.max_handle_residual = res;
  // handle targets far beyond the mesh (a translation of 1e300) overflow the energies while the
  // positions stay finite: not a deformation to hand out (found by hand 2026-12-06)
  if (!X_.allFinite() || (!report_.e_nonrigid.empty() && !std::isfinite(report_.e_nonrigid.back())) ||
      !std::isfinite(report_.volume_ratio))
    throw NumericalFailure("[tbsp::TetDeformer::deform] the deformation overflowed double precision (E_nonrigid or the volume is "
                           "not finite): the handle targets lie far beyond the mesh's size; check their units");
  return inputPositions();
}

}  // namespace tbsp
