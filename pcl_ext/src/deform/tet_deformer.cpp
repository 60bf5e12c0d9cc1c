#include "tbsp/deform/tet_deformer.h"

#include <Eigen/Geometry>
#include <Eigen/SparseCore>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <map>

#include "tbsp/core/error.h"
#include "tbsp/core/logging.h"
#include "tbsp/deform/rotations.h"
#include "tbsp/solve/sparse_cholesky.h"

namespace tbsp {

namespace {
using Clock = std::chrono::steady_clock;
double seconds_since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

using Mat34 = Eigen::Matrix<double, 3, 4, Eigen::RowMajor>;
using Mat3r = Eigen::Matrix<double, 3, 3, Eigen::RowMajor>;

// H^{-T} = cof(H) / det(H) for a 3x3 matrix; returns det.
inline double inverse_transpose(const Eigen::Matrix3d& H, Eigen::Matrix3d& out) {
  const Eigen::Vector3d c0 = H.col(1).cross(H.col(2));
  const Eigen::Vector3d c1 = H.col(2).cross(H.col(0));
  const Eigen::Vector3d c2 = H.col(0).cross(H.col(1));
  const double det = H.col(0).dot(c0);
  const double inv = 1.0 / det;
  out.col(0) = c0 * inv;
  out.col(1) = c1 * inv;
  out.col(2) = c2 * inv;
  return det;
}

// Rotation of the polar decomposition F = R S (eq. 7.7-7.8), warm-started from R0:
// A = R0ᵀ F is polar-decomposed by the (determinant-scaled) Newton iteration
// H <- ½(γH + H⁻ᵀ/γ), and R = R0 · polar(A). Reflections / collapsed tets use the SVD.
inline Eigen::Matrix3d polar_rotation(const Eigen::Matrix3d& F, const Eigen::Matrix3d& R0) {
  Eigen::Matrix3d H = R0.transpose() * F;
  const double scale = H.norm();
  if (!(scale > 0) || !std::isfinite(scale)) return R0;
  Eigen::Matrix3d Hit;
  double det = inverse_transpose(H, Hit);
  if (!(det > 1e-10 * scale * scale * scale)) return closest_rotation(F);
  for (int k = 0; k < 30; ++k) {
    // determinant scaling (Higham) while far from orthogonal; plain Newton near convergence
    const double gamma = std::abs(det - 1) > 1e-4 ? std::cbrt(1.0 / det) : 1.0;
    const Eigen::Matrix3d next = 0.5 * (gamma * H + Hit / gamma);
    const double change = (next - H).squaredNorm();
    H = next;
    // quadratic convergence: a step of size c leaves an error of about c^2 (here < 1e-14)
    if (change < 1e-14) break;
    det = inverse_transpose(H, Hit);
  }
  return R0 * H;
}
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

TetDeformer::TetDeformer() = default;
TetDeformer::~TetDeformer() = default;

void TetDeformer::requireMesh(const char* who) const {
  if (mesh_.T.rows() == 0) throw InvalidInput(std::string("[TetDeformer::") + who + "] no mesh: call setMesh() first");
}

void TetDeformer::checkVertex(int v, const char* who) const {
  requireMesh(who);
  if (v < 0 || v >= mesh_.V.rows())
    throw InvalidInput(std::string("[TetDeformer::") + who + "] vertex " + std::to_string(v) +
                       " does not exist (the tet mesh has " + std::to_string(mesh_.V.rows()) + " vertices)");
}

void TetDeformer::setMesh(const TetMesh& mesh) {
  require_valid_tet_mesh(mesh, "TetDeformer::setMesh");
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
    throw InvalidInput("[TetDeformer::setStiffness] " + std::to_string(s.size()) + " values given for " +
                       std::to_string(n_input_tets_) + " tetrahedra; give one stiffness per input tetrahedron");
  for (Eigen::Index i = 0; i < s.size(); ++i)
    if (!(s(i) > 0) || !std::isfinite(s(i)))
      throw InvalidInput("[TetDeformer::setStiffness] stiffness of tet " + std::to_string(i) + " is " +
                         std::to_string(s(i)) + "; it must be a finite value > 0 (use rigid regions for rigidity)");
  stiffness_input_ = s;
  operators_dirty_ = true;
}

int TetDeformer::addVertexHandle(int v, const Eigen::Vector3d& target) {
  checkVertex(v, "addVertexHandle");
  if (!target.allFinite()) throw InvalidInput("[TetDeformer::addVertexHandle] the target of vertex " + std::to_string(v) + " is not finite");
  Handle h;
  h.kind = Handle::Vertex;
  h.vertices = {v};
  h.target = target;
  h.from_target = rest_.row(v).transpose();
  handles_.push_back(h);
  operators_dirty_ = true;
  return int(handles_.size()) - 1;
}

int TetDeformer::addRegionHandle(const std::vector<int>& vertices, const RigidMotion& motion) {
  requireMesh("addRegionHandle");
  if (vertices.empty()) throw InvalidInput("[TetDeformer::addRegionHandle] the region has no vertices");
  for (int v : vertices) checkVertex(v, "addRegionHandle");
  if (!motion.axis.allFinite() || !std::isfinite(motion.angle) || !motion.center.allFinite() || !motion.translation.allFinite())
    throw InvalidInput("[TetDeformer::addRegionHandle] the motion has non-finite values");
  if (motion.angle != 0 && !(motion.axis.norm() > 0))
    throw InvalidInput("[TetDeformer::addRegionHandle] the rotation axis is zero; give a direction");
  Handle h;
  h.kind = Handle::Region;
  h.vertices = vertices;
  std::sort(h.vertices.begin(), h.vertices.end());
  h.vertices.erase(std::unique(h.vertices.begin(), h.vertices.end()), h.vertices.end());
  h.motion = motion;
  h.from_motion = RigidMotion::identity();
  h.from_motion.center = motion.center;
  handles_.push_back(h);
  operators_dirty_ = true;
  return int(handles_.size()) - 1;
}

void TetDeformer::splitTet(int t, const Eigen::Vector3d& /*p*/, int nv) {
  const Eigen::Vector4i tet = mesh_.T.row(t);
  const double vol = std::abs(tet_signed_volumes(mesh_.V, mesh_.T.row(t)).coeff(0));
  std::vector<Eigen::Vector4i> kids;
  for (int k = 0; k < 4; ++k) {
    Eigen::Vector4i c = tet;
    c(k) = nv;
    Eigen::Matrix<int, 1, 4> row = c.transpose();
    const double v = tet_signed_volumes(mesh_.V, row)(0);
    if (v > 1e-9 * vol) kids.push_back(c);
  }
  const int par = parent_[std::size_t(t)];
  mesh_.T.row(t) = kids[0].transpose();
  const Eigen::Index old = mesh_.T.rows();
  mesh_.T.conservativeResize(old + Eigen::Index(kids.size()) - 1, 4);
  for (std::size_t i = 1; i < kids.size(); ++i) {
    mesh_.T.row(old + Eigen::Index(i) - 1) = kids[i].transpose();
    parent_.push_back(par);
    virtual_.push_back(virtual_[std::size_t(t)]);
  }
  report_.split_tets += 1;
}

int TetDeformer::addPointHandle(const Eigen::Vector3d& p, const Eigen::Vector3d& target) {
  requireMesh("addPointHandle");
  if (!p.allFinite() || !target.allFinite())
    throw InvalidInput("[TetDeformer::addPointHandle] the point or its target is not finite");
  // Enclosing tetrahedron (barycentric test).
  int host = -1;
  for (Eigen::Index t = 0; t < mesh_.T.rows() && host < 0; ++t) {
    if (virtual_[std::size_t(t)]) continue;
    const Eigen::Vector3d d = mesh_.V.row(mesh_.T(t, 3));
    Eigen::Matrix3d E;
    for (int k = 0; k < 3; ++k) E.col(k) = mesh_.V.row(mesh_.T(t, k)).transpose() - d;
    const Eigen::Vector3d b = E.inverse() * (p - d);
    const double b3 = 1.0 - b.sum();
    if (b.minCoeff() >= -1e-12 && b3 >= -1e-12) host = int(t);
  }
  const int nv = int(mesh_.V.rows());
  // nearest existing vertex closer than 1e-9 diag: use it instead of a new one
  for (int v = 0; v < nv; ++v)
    if ((mesh_.V.row(v).transpose() - p).norm() < 1e-9 * diag_) return addVertexHandle(v, target);
  mesh_.V.conservativeResize(nv + 1, 3);
  mesh_.V.row(nv) = p.transpose();
  if (host >= 0) {
    splitTet(host, p, nv);
  } else {
    // Virtual tets to the nearest boundary triangles that see p on their outer side.
    TetMesh real;
    real.V = mesh_.V;
    std::vector<int> keep;
    for (Eigen::Index t = 0; t < mesh_.T.rows(); ++t)
      if (!virtual_[std::size_t(t)]) keep.push_back(int(t));
    real.T.resize(Eigen::Index(keep.size()), 4);
    for (std::size_t i = 0; i < keep.size(); ++i) real.T.row(Eigen::Index(i)) = mesh_.T.row(keep[i]);
    std::vector<int> owner;
    const Eigen::MatrixX3i B = tet_boundary_faces(real.T, &owner);
    std::vector<std::pair<double, int>> cand;
    for (Eigen::Index f = 0; f < B.rows(); ++f) {
      const Eigen::Vector3d a = mesh_.V.row(B(f, 0)), b = mesh_.V.row(B(f, 1)), c = mesh_.V.row(B(f, 2));
      const Eigen::Vector3d n = (b - a).cross(c - a);
      const double h = n.dot(p - a) / n.norm();  // signed height above the face
      if (!(h > 1e-6 * diag_)) continue;
      cand.push_back({((a + b + c) / 3.0 - p).squaredNorm(), int(f)});
    }
    std::sort(cand.begin(), cand.end());
    const std::size_t use = std::min<std::size_t>(3, cand.size());
    if (use == 0) {
      mesh_.V.conservativeResize(nv, 3);
      throw InvalidInput("[TetDeformer::addPointHandle] the point (" + std::to_string(p.x()) + ", " + std::to_string(p.y()) +
                         ", " + std::to_string(p.z()) + ") is neither inside the mesh nor above any boundary triangle");
    }
    const Eigen::Index old = mesh_.T.rows();
    mesh_.T.conservativeResize(old + Eigen::Index(use), 4);
    for (std::size_t i = 0; i < use; ++i) {
      const int f = cand[i].second;
      mesh_.T.row(old + Eigen::Index(i)) << B(f, 0), B(f, 1), B(f, 2), nv;
      parent_.push_back(parent_[std::size_t(keep[std::size_t(owner[std::size_t(f)])])]);
      virtual_.push_back(1);
    }
    report_.virtual_tets += Eigen::Index(use);
  }
  rest_ = mesh_.V;
  report_.added_vertices += 1;
  Handle h;
  h.kind = Handle::Point;
  h.vertices = {nv};
  h.target = target;
  h.from_target = p;
  handles_.push_back(h);
  operators_dirty_ = true;
  reset();
  return int(handles_.size()) - 1;
}

void TetDeformer::setHandleTarget(int id, const Eigen::Vector3d& target) {
  if (id < 0 || id >= int(handles_.size()) || handles_[std::size_t(id)].kind == Handle::Region)
    throw InvalidInput("[TetDeformer::setHandleTarget] " + std::to_string(id) + " is not a vertex or point handle");
  if (!target.allFinite()) throw InvalidInput("[TetDeformer::setHandleTarget] the target is not finite");
  freezeRamp();
  handles_[std::size_t(id)].target = target;
  ramp_iteration_ = 0;
  ramp_steps_ = rampSteps();
  constrained_dirty_ = true;
  report_.converged = false;
}

void TetDeformer::setRegionMotion(int id, const RigidMotion& motion) {
  if (id < 0 || id >= int(handles_.size()) || handles_[std::size_t(id)].kind != Handle::Region)
    throw InvalidInput("[TetDeformer::setRegionMotion] " + std::to_string(id) + " is not a region handle");
  if (!motion.axis.allFinite() || !std::isfinite(motion.angle) || !motion.center.allFinite() || !motion.translation.allFinite())
    throw InvalidInput("[TetDeformer::setRegionMotion] the motion has non-finite values");
  freezeRamp();
  handles_[std::size_t(id)].motion = motion;
  ramp_iteration_ = 0;
  ramp_steps_ = rampSteps();
  constrained_dirty_ = true;
  report_.converged = false;
}

void TetDeformer::freezeRamp() {
  // Every handle restarts its ramp from where it is now.
  const double s = std::min(1.0, double(ramp_iteration_) / double(std::max(1, ramp_steps_)));
  for (auto& h : handles_) {
    if (h.kind == Handle::Region) {
      RigidMotion cur;
      const Eigen::AngleAxisd aa(handleRotation(h, s));
      cur.axis = aa.axis();
      cur.angle = aa.angle();
      if (h.from_motion.angle == 0 || std::abs(h.from_motion.axis.normalized().dot(h.motion.axis.normalized())) > 1 - 1e-12) {
        cur.axis = h.motion.axis;
        cur.angle = h.from_motion.angle + s * (h.motion.angle - h.from_motion.angle);
        if (h.from_motion.angle != 0 && h.from_motion.axis.dot(h.motion.axis) < 0)
          cur.angle = -h.from_motion.angle + s * (h.motion.angle + h.from_motion.angle);
      }
      cur.center = h.from_motion.center + s * (h.motion.center - h.from_motion.center);
      cur.translation = h.from_motion.translation + s * (h.motion.translation - h.from_motion.translation);
      h.from_motion = cur;
    } else {
      h.from_target = h.from_target + s * (h.target - h.from_target);
    }
  }
}

void TetDeformer::addRigidRegion(const std::vector<int>& tets) {
  requireMesh("addRigidRegion");
  if (tets.empty()) throw InvalidInput("[TetDeformer::addRigidRegion] the region has no tetrahedra");
  for (int t : tets)
    if (t < 0 || t >= n_input_tets_)
      throw InvalidInput("[TetDeformer::addRigidRegion] tetrahedron " + std::to_string(t) + " does not exist (the mesh has " +
                         std::to_string(n_input_tets_) + ")");
  rigid_regions_.push_back(tets);
}

void TetDeformer::clearHandles() {
  handles_.clear();
  rigid_regions_.clear();
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
    throw InvalidInput("[TetDeformer::setRotations] " + std::to_string(R.size()) + " rotations for " +
                       std::to_string(mesh_.T.rows()) + " tetrahedra");
  prepare();
  R_ = R;
  for (Eigen::Index j = 0; j < mesh_.T.rows(); ++j)
    solver_->Gs.middleRows<3>(3 * j) = Eigen::Map<const Mat3r>(g_.row(j).data()) * R_[std::size_t(j)].transpose();
}

int TetDeformer::rampSteps() const {
  int steps = 1;
  const double step = std::max(1e-3, options_.max_handle_step_deg) * M_PI / 180.0;
  for (const auto& h : handles_) {
    if (h.kind != Handle::Region) continue;
    double delta;
    const Eigen::Vector3d a = h.from_motion.axis.normalized(), b = h.motion.axis.normalized();
    if (h.from_motion.angle == 0)
      delta = std::abs(h.motion.angle);
    else if (std::abs(a.dot(b)) > 1 - 1e-12)
      delta = std::abs(h.motion.angle - (a.dot(b) > 0 ? 1 : -1) * h.from_motion.angle);
    else
      delta = Eigen::AngleAxisd(h.motion.R() * h.from_motion.R().transpose()).angle();
    steps = std::max(steps, int(std::ceil(delta / step - 1e-9)));
  }
  return steps;
}

Eigen::Matrix3d TetDeformer::handleRotation(const Handle& h, double s) const {
  const RigidMotion& a = h.from_motion;
  const RigidMotion& b = h.motion;
  if (a.angle == 0) {
    RigidMotion m = b;
    m.angle = s * b.angle;
    return m.R();
  }
  const Eigen::Vector3d ua = a.axis.normalized(), ub = b.axis.normalized();
  if (b.angle == 0 || std::abs(ua.dot(ub)) > 1 - 1e-12) {
    const double start = (b.angle == 0 || ua.dot(ub) > 0) ? a.angle : -a.angle;
    RigidMotion m = b.angle == 0 ? a : b;
    m.angle = b.angle == 0 ? (1 - s) * a.angle : start + s * (b.angle - start);
    return m.R();
  }
  const Eigen::Matrix3d Ra = a.R();
  Eigen::AngleAxisd d(b.R() * Ra.transpose());
  d.angle() *= s;
  return d.toRotationMatrix() * Ra;
}

Eigen::Vector3d TetDeformer::handlePosition(const Handle& h, int slot, double s) const {
  const int v = h.vertices[std::size_t(slot)];
  if (h.kind != Handle::Region) return h.from_target + s * (h.target - h.from_target);
  const Eigen::Vector3d c = h.from_motion.center + s * (h.motion.center - h.from_motion.center);
  const Eigen::Vector3d t = h.from_motion.translation + s * (h.motion.translation - h.from_motion.translation);
  return c + handleRotation(h, s) * (rest_.row(v).transpose() - c) + t;
}

void TetDeformer::buildOperators() {
  const auto t0 = Clock::now();
  const Eigen::Index n = mesh_.V.rows(), m = mesh_.T.rows();
  if (handles_.empty())
    throw InvalidInput("[TetDeformer] no handles: the deformation is undetermined. Add at least one vertex, region or "
                       "point handle (addVertexHandle / addRegionHandle / addPointHandle)");
  // constrained vertices
  std::vector<int> owner(std::size_t(n), -1), slot(std::size_t(n), -1);
  for (std::size_t hi = 0; hi < handles_.size(); ++hi)
    for (std::size_t k = 0; k < handles_[hi].vertices.size(); ++k) {
      const int v = handles_[hi].vertices[k];
      if (owner[std::size_t(v)] >= 0 && owner[std::size_t(v)] != int(hi))
        throw InvalidInput("[TetDeformer] vertex " + std::to_string(v) + " belongs to handle " +
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
      throw InvalidInput("[TetDeformer] the connected part containing vertex " + std::to_string(v) +
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

double TetDeformer::nonrigidEnergy(const Eigen::MatrixX3d& X) const {
  if (X.rows() != mesh_.V.rows()) throw InvalidInput("[TetDeformer::nonrigidEnergy] wrong number of positions");
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
  return inputPositions();
}

}  // namespace tbsp
