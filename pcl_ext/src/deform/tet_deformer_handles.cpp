// TetDeformer: handles (vertex, region, point handles with tet refinement), rigid regions and the
// handle ramps (large handle rotations applied in steps).
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
using Mat3r = Eigen::Matrix<double, 3, 3, Eigen::RowMajor>;
}  // namespace

int TetDeformer::addVertexHandle(int v, const Eigen::Vector3d& target) {
  checkVertex(v, "addVertexHandle");
  if (!target.allFinite()) throw InvalidInput("[tbsp::TetDeformer::addVertexHandle] the target of vertex " + std::to_string(v) + " is not finite");
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
  if (vertices.empty()) throw InvalidInput("[tbsp::TetDeformer::addRegionHandle] the region has no vertices");
  for (int v : vertices) checkVertex(v, "addRegionHandle");
  if (!motion.axis.allFinite() || !std::isfinite(motion.angle) || !motion.center.allFinite() || !motion.translation.allFinite())
    throw InvalidInput("[tbsp::TetDeformer::addRegionHandle] the motion has non-finite values");
  if (motion.angle != 0 && !(motion.axis.norm() > 0))
    throw InvalidInput("[tbsp::TetDeformer::addRegionHandle] the rotation axis is zero; give a direction");
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
    throw InvalidInput("[tbsp::TetDeformer::addPointHandle] the point or its target is not finite");
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
      throw InvalidInput("[tbsp::TetDeformer::addPointHandle] the point (" + std::to_string(p.x()) + ", " + std::to_string(p.y()) +
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
    throw InvalidInput("[tbsp::TetDeformer::setHandleTarget] " + std::to_string(id) + " is not a vertex or point handle");
  if (!target.allFinite()) throw InvalidInput("[tbsp::TetDeformer::setHandleTarget] the target is not finite");
  freezeRamp();
  handles_[std::size_t(id)].target = target;
  ramp_iteration_ = 0;
  ramp_steps_ = rampSteps();
  constrained_dirty_ = true;
  report_.converged = false;
}

void TetDeformer::setRegionMotion(int id, const RigidMotion& motion) {
  if (id < 0 || id >= int(handles_.size()) || handles_[std::size_t(id)].kind != Handle::Region)
    throw InvalidInput("[tbsp::TetDeformer::setRegionMotion] " + std::to_string(id) + " is not a region handle");
  if (!motion.axis.allFinite() || !std::isfinite(motion.angle) || !motion.center.allFinite() || !motion.translation.allFinite())
    throw InvalidInput("[tbsp::TetDeformer::setRegionMotion] the motion has non-finite values");
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
  if (tets.empty()) throw InvalidInput("[tbsp::TetDeformer::addRigidRegion] the region has no tetrahedra");
  for (int t : tets)
    if (t < 0 || t >= n_input_tets_)
      throw InvalidInput("[tbsp::TetDeformer::addRigidRegion] tetrahedron " + std::to_string(t) + " does not exist (the mesh has " +
                         std::to_string(n_input_tets_) + ")");
  rigid_regions_.push_back(tets);
}

void TetDeformer::clearHandles() {
  handles_.clear();
  rigid_regions_.clear();
  operators_dirty_ = true;
}

int TetDeformer::rampSteps() const {
  int steps = 1;
  const double step = options_.max_handle_step_deg * M_PI / 180.0;  // (0, 180): setOptions validates
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

}  // namespace tbsp
