#include "tbsp/deform/laplacian_deformer.h"

#include "laplacian_deformer_cache.h"
#include "../solve/sparse_gram.h"

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>
#include <Eigen/SVD>
#include <algorithm>
#include <chrono>
#include <exception>
#include <cmath>
#include <map>
#include <limits>
#include <set>
#include <string>

#include "tbsp/core/error.h"
#include "tbsp/core/timer.h"
#include "tbsp/core/logging.h"
#include "tbsp/deform/rotation_field.h"
#include "tbsp/deform/rotations.h"
#include "tbsp/mesh/mesh_validation.h"
#include "tbsp/mesh/topology.h"
#include "tbsp/solve/blas_threads.h"
#include "tbsp/solve/sparse_cholesky.h"

#ifdef _OPENMP
#include <omp.h>
#endif

namespace tbsp {

namespace {

// weights enter the normal equations squared: 1e100² is far from overflow, ~1e154² is not
constexpr double kMaxConstraintWeight = 1e100;

// Two unit vectors orthogonal to d (and to each other).
void orthonormal_pair(const Eigen::Vector3d& d, Eigen::Vector3d& n1, Eigen::Vector3d& n2) {
  const Eigen::Vector3d u = d.normalized();
  const Eigen::Vector3d a = std::abs(u.x()) < 0.9 ? Eigen::Vector3d::UnitX() : Eigen::Vector3d::UnitY();
  n1 = u.cross(a).normalized();
  n2 = u.cross(n1).normalized();
}

const char* type_name(ConstraintType t) {
  return t == ConstraintType::Position ? "position" : t == ConstraintType::Line ? "line" : "plane";
}

}  // namespace


LaplacianDeformer::LaplacianDeformer() : cache_(std::make_unique<Cache>()) {}
LaplacianDeformer::~LaplacianDeformer() = default;

void LaplacianDeformer::requireMesh(const char* who) const {
  if (!has_mesh_) throw InvalidInput(std::string("[tbsp::LaplacianDeformer::") + who + "] no mesh set; call setMesh() first");
}

const TriMesh& LaplacianDeformer::mesh() const { return mesh_; }

void LaplacianDeformer::setMesh(const TriMesh& mesh) {
  MeshRequirements req;
  req.allow_nonmanifold = true;
  const MeshReport rep = require_valid_mesh(mesh, req, "tbsp::LaplacianDeformer::setMesh");
  if (!rep.nonmanifold_edges.empty())
    logger()->warn("[LaplacianDeformer] mesh has {} non-manifold edges; the Laplacian sums over all incident faces",
                   rep.nonmanifold_edges.size());
  mesh_ = mesh;
  has_mesh_ = true;
  for (const auto& c : constraints_) checkConstraint(c, "setMesh");
  const auto t0 = Clock::now();
  report_progress(progress_, 0.0, "laplacian");
  L_ = laplacian(mesh_.V, mesh_.F, weights_, sliver_guard_, &cache_->C);
  if (weights_ == LaplacianWeights::Cotangent) {
    const double area = mean_voronoi_area(mesh_.V, mesh_.F);
    if (area > 0) L_ *= area;  // L̂ = Ā L: units of length, scale-free weights
  }
  L_.makeCompressed();
  delta_ = L_ * mesh_.V;
  cache_->num_components = connected_components(mesh_.F, mesh_.V.rows(), cache_->component);
  cache_->isolated.assign(std::size_t(mesh_.V.rows()), 1);
  for (Eigen::Index f = 0; f < mesh_.F.rows(); ++f)
    for (int k = 0; k < 3; ++k) cache_->isolated[std::size_t(mesh_.F(f, k))] = 0;
  report_.t_laplacian = seconds_since(t0);
  cache_->nl_free_index.clear();
  user_rotations_.clear();
  invalidateMatrix();
}

bool LaplacianDeformerOptions::isValid(std::string* why) const {
  auto bad = [&](const std::string& m) {
    if (why) *why = m;
    return false;
  };
  if (!(scale > 0 && std::isfinite(scale))) return bad("scale = " + std::to_string(scale) + " must be > 0 and finite");
  if (!(anchor >= 0 && std::isfinite(anchor))) return bad("anchor = " + std::to_string(anchor) + " must be >= 0 and finite");
  if (!(sliver_guard >= 0 && std::isfinite(sliver_guard)))
    return bad("sliver_guard = " + std::to_string(sliver_guard) + " must be >= 0 and finite");
  return true;
}

void LaplacianDeformer::setOptions(const LaplacianDeformerOptions& o) {
  std::string why;
  if (!o.isValid(&why)) throw InvalidInput("[tbsp::LaplacianDeformer::setOptions] " + why);
  setSliverGuard(o.sliver_guard);
  setAnchor(o.anchor);
  setScale(o.scale);
  setUseRotationField(o.rotation_field);
  setLaplacianWeights(o.weights);
}

LaplacianDeformerOptions LaplacianDeformer::options() const {
  LaplacianDeformerOptions o;
  o.weights = weights_;
  o.rotation_field = use_rotation_field_;
  o.scale = scale_;
  o.anchor = anchor_;
  o.sliver_guard = sliver_guard_;
  return o;
}

void LaplacianDeformer::setLaplacianWeights(LaplacianWeights w) {
  if (w == weights_) return;
  weights_ = w;
  if (has_mesh_) setMesh(TriMesh(mesh_));
}

void LaplacianDeformer::invalidateMatrix() {
  cache_->matrix_valid = false;
  cache_->graph_valid = false;
}

void LaplacianDeformer::checkConstraint(const DeformConstraint& c, const char* who) const {
  const std::string w = std::string("[tbsp::LaplacianDeformer::") + who + "] ";
  requireMesh(who);
  const auto nv = mesh_.V.rows(), nf = mesh_.F.rows();
  if (c.at.vertex >= 0) {
    if (c.at.vertex >= nv)
      throw InvalidInput(w + "constraint on vertex " + std::to_string(c.at.vertex) + ", but the mesh has " +
                         std::to_string(nv) + " vertices (valid: 0.." + std::to_string(nv - 1) + ")");
  } else if (c.at.face >= 0) {
    if (c.at.face >= nf)
      throw InvalidInput(w + "constraint on face " + std::to_string(c.at.face) + ", but the mesh has " +
                         std::to_string(nf) + " faces");
    if (!c.at.bary.allFinite() || (c.at.bary.array() < -1e-9).any() || std::abs(c.at.bary.sum() - 1.0) > 1e-6)
      throw InvalidInput(w + "barycentric coordinates (" + std::to_string(c.at.bary.x()) + ", " +
                         std::to_string(c.at.bary.y()) + ", " + std::to_string(c.at.bary.z()) +
                         ") on face " + std::to_string(c.at.face) + " must be >= 0 and sum to 1");
  } else {
    throw InvalidInput(w + "the constraint is attached to neither a vertex nor a face");
  }
  if (!c.target.allFinite()) throw InvalidInput(w + "the constraint target/point is not finite");
  if (c.type != ConstraintType::Position && !(c.axis.allFinite() && c.axis.norm() > 1e-12))
    throw InvalidInput(w + std::string("the ") + type_name(c.type) + " constraint needs a non-zero, finite " +
                       (c.type == ConstraintType::Line ? "direction" : "normal"));
  if (c.hard) {
    if (c.type != ConstraintType::Position || c.at.vertex < 0)
      throw InvalidInput(w + "hard constraints must be position constraints on a vertex; use a soft constraint "
                             "with a large weight for lines, planes and surface points");
  } else if (!(c.weight > 0 && c.weight <= kMaxConstraintWeight)) {
    throw InvalidInput(w + "constraint weight must be in (0, 1e100] (got " + fmt::format("{}", c.weight) +
                       "; its square enters the system, and beyond ~1e150 it overflows: for an exact position use a hard constraint)");
  }
  if (c.rotation && !(c.rotation->allFinite() && std::abs(c.rotation->determinant() - 1.0) < 1e-3 &&
                      (c.rotation->transpose() * *c.rotation - Eigen::Matrix3d::Identity()).norm() < 1e-3))
    throw InvalidInput(w + "the constraint's rotation is not a rotation matrix (orthonormal, det +1)");
}

int LaplacianDeformer::addConstraint(const DeformConstraint& c) {
  checkConstraint(c, "addConstraint");
  if (c.hard) {  // (a flag per vertex: adding n hard constraints stays O(n))
    const std::size_t v = std::size_t(c.at.vertex);
    if (v < hard_at_.size() && hard_at_[v])
      throw InvalidInput("[tbsp::LaplacianDeformer::addConstraint] vertex " + std::to_string(c.at.vertex) +
                         " already has a hard constraint; move it with setPositionTarget()");
    if (v >= hard_at_.size()) hard_at_.resize(v + 1, 0);
    hard_at_[v] = 1;
  }
  DeformConstraint s = c;
  if (s.type != ConstraintType::Position) s.axis.normalize();
  constraints_.push_back(s);
  invalidateMatrix();
  return int(constraints_.size()) - 1;
}

int LaplacianDeformer::addPositionConstraint(const SurfacePoint& at, const Eigen::Vector3d& target, double weight) {
  DeformConstraint c;
  c.at = at; c.target = target; c.weight = weight;
  return addConstraint(c);
}

int LaplacianDeformer::addHardConstraint(int v, const Eigen::Vector3d& target) {
  DeformConstraint c;
  c.at = SurfacePoint::atVertex(v); c.target = target; c.hard = true;
  return addConstraint(c);
}

int LaplacianDeformer::addLineConstraint(const SurfacePoint& at, const Eigen::Vector3d& point,
                                         const Eigen::Vector3d& direction, double weight) {
  DeformConstraint c;
  c.at = at; c.type = ConstraintType::Line; c.target = point; c.axis = direction; c.weight = weight;
  return addConstraint(c);
}

int LaplacianDeformer::addPlaneConstraint(const SurfacePoint& at, const Eigen::Vector3d& point,
                                          const Eigen::Vector3d& normal, double weight) {
  DeformConstraint c;
  c.at = at; c.type = ConstraintType::Plane; c.target = point; c.axis = normal; c.weight = weight;
  return addConstraint(c);
}

void LaplacianDeformer::clearConstraints() {
  constraints_.clear();
  hard_at_.clear();
  invalidateMatrix();
}

namespace {
DeformConstraint& get(std::vector<DeformConstraint>& cs, int id, const char* who) {
  if (id < 0 || id >= int(cs.size()))
    throw InvalidInput(std::string("[tbsp::LaplacianDeformer::") + who + "] no constraint with id " + std::to_string(id) +
                       " (" + std::to_string(cs.size()) + " constraints)");
  return cs[std::size_t(id)];
}
}  // namespace

void LaplacianDeformer::setPositionTarget(int id, const Eigen::Vector3d& target) {
  auto& c = get(constraints_, id, "setPositionTarget");
  if (c.type != ConstraintType::Position)
    throw InvalidInput("[tbsp::LaplacianDeformer::setPositionTarget] constraint " + std::to_string(id) + " is a " +
                       type_name(c.type) + " constraint; use setLineOrPlane()");
  if (!target.allFinite()) throw InvalidInput("[tbsp::LaplacianDeformer::setPositionTarget] target is not finite");
  c.target = target;  // right-hand side only
}

void LaplacianDeformer::setLineOrPlane(int id, const Eigen::Vector3d& point, const Eigen::Vector3d& axis) {
  auto& c = get(constraints_, id, "setLineOrPlane");
  if (c.type == ConstraintType::Position)
    throw InvalidInput("[tbsp::LaplacianDeformer::setLineOrPlane] constraint " + std::to_string(id) +
                       " is a position constraint; use setPositionTarget()");
  if (!point.allFinite() || !axis.allFinite() || axis.norm() <= 1e-12)
    throw InvalidInput("[tbsp::LaplacianDeformer::setLineOrPlane] point and a non-zero axis must be finite");
  c.target = point;
  const Eigen::Vector3d a = axis.normalized();
  if (a.cross(c.axis).norm() > 1e-12) {  // orientation changed: the matrix changes
    c.axis = a;
    cache_->matrix_valid = false;
  }
}

void LaplacianDeformer::setWeight(int id, double weight) {
  auto& c = get(constraints_, id, "setWeight");
  if (!(weight > 0 && weight <= kMaxConstraintWeight))
    throw InvalidInput("[tbsp::LaplacianDeformer::setWeight] weight must be in (0, 1e100] (got " + fmt::format("{}", weight) + ")");
  if (c.hard) throw InvalidInput("[tbsp::LaplacianDeformer::setWeight] constraint " + std::to_string(id) + " is hard");
  if (c.weight != weight) { c.weight = weight; cache_->matrix_valid = false; }
}

void LaplacianDeformer::setConstraintRotation(int id, const std::optional<Eigen::Matrix3d>& R) {
  auto& c = get(constraints_, id, "setConstraintRotation");
  DeformConstraint t = c;
  t.rotation = R;
  checkConstraint(t, "setConstraintRotation");
  c.rotation = R;
}

void LaplacianDeformer::setUseRotationField(bool on) { use_rotation_field_ = on; }

void LaplacianDeformer::setRotations(const std::vector<Eigen::Matrix3d>& R) {
  requireMesh("setRotations");
  if (!R.empty() && Eigen::Index(R.size()) != mesh_.V.rows())
    throw InvalidInput("[tbsp::LaplacianDeformer::setRotations] got " + std::to_string(R.size()) +
                       " rotations for " + std::to_string(mesh_.V.rows()) + " vertices");
  for (std::size_t i = 0; i < R.size(); ++i)
    if (!R[i].allFinite())
      throw InvalidInput("[tbsp::LaplacianDeformer::setRotations] rotation " + std::to_string(i) + " is not finite");
  user_rotations_ = R;
  if (!R.empty()) use_rotation_field_ = false;
}

void LaplacianDeformer::setSliverGuard(double guard) {
  if (!(guard >= 0 && std::isfinite(guard)))
    throw InvalidInput("[tbsp::LaplacianDeformer::setSliverGuard] guard must be >= 0 and finite (0: off)");
  sliver_guard_ = guard;
}

void LaplacianDeformer::setAnchor(double epsilon) {
  if (!(std::isfinite(epsilon) && epsilon >= 0))
    throw InvalidInput("[tbsp::LaplacianDeformer::setAnchor] epsilon must be >= 0 and finite");
  if (epsilon != anchor_) { anchor_ = epsilon; cache_->matrix_valid = false; }
}

void LaplacianDeformer::setScale(double lambda) {
  if (!(std::isfinite(lambda) && lambda > 0))
    throw InvalidInput("[tbsp::LaplacianDeformer::setScale] scale must be > 0 and finite (got " + std::to_string(lambda) + ")");
  scale_ = lambda;
}

Eigen::Vector3d LaplacianDeformer::evaluate(const SurfacePoint& p, const Eigen::MatrixX3d& X) const {
  if (p.vertex >= 0) return X.row(p.vertex).transpose();
  Eigen::Vector3d r = Eigen::Vector3d::Zero();
  for (int k = 0; k < 3; ++k) r += p.bary(k) * X.row(mesh_.F(p.face, k)).transpose();
  return r;
}

void LaplacianDeformer::checkRank() const {
  // With an anchor every component is pinned (weakly) to its rest position: directions the
  // constraints leave free keep their rest values instead of making the system singular.
  if (anchor_ > 0) return;
  const Cache& c = *cache_;
  std::vector<Eigen::Matrix3d> S(std::size_t(c.num_components), Eigen::Matrix3d::Zero());
  std::vector<char> has_face(std::size_t(c.num_components), 0);
  for (Eigen::Index f = 0; f < mesh_.F.rows(); ++f) has_face[std::size_t(c.component(mesh_.F(f, 0)))] = 1;
  for (const auto& con : constraints_) {
    std::vector<int> verts;
    if (con.at.vertex >= 0) verts.push_back(con.at.vertex);
    else for (int k = 0; k < 3; ++k) if (con.at.bary(k) != 0) verts.push_back(mesh_.F(con.at.face, k));
    Eigen::Matrix3d m;
    if (con.type == ConstraintType::Position) m.setIdentity();
    else if (con.type == ConstraintType::Plane) m = con.axis * con.axis.transpose();
    else m = Eigen::Matrix3d::Identity() - con.axis * con.axis.transpose();
    for (int v : verts) S[std::size_t(c.component(v))] += m;
  }
  for (int k = 0; k < c.num_components; ++k) {
    if (!has_face[std::size_t(k)]) continue;
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(S[std::size_t(k)]);
    if (es.eigenvalues()(0) < 1e-9 * std::max(1.0, es.eigenvalues()(2))) {
      Eigen::Index v = 0;
      while (c.component(v) != k) ++v;
      const Eigen::Vector3d free_dir = es.eigenvectors().col(0);
      throw InvalidInput("[tbsp::LaplacianDeformer::deform] the constraints leave the mesh component containing "
                         "vertex " + std::to_string(v) + " free to translate along (" + std::to_string(free_dir.x()) +
                         ", " + std::to_string(free_dir.y()) + ", " + std::to_string(free_dir.z()) +
                         "), so the system is singular; add a position constraint on that component (or line/plane "
                         "constraints whose directions pin all three axes)");
    }
  }
}

void LaplacianDeformer::buildSystem() {
  Cache& c = *cache_;
  const Eigen::Index n = mesh_.V.rows();
  checkRank();
  // free / fixed split
  c.free_index.assign(std::size_t(n), 0);
  for (Eigen::Index i = 0; i < n; ++i)
    if (c.isolated[std::size_t(i)]) c.free_index[std::size_t(i)] = -1;
  for (const auto& con : constraints_)
    if (con.hard) c.free_index[std::size_t(con.at.vertex)] = -1;
  Eigen::Index nf = 0;
  for (Eigen::Index i = 0; i < n; ++i)
    if (c.free_index[std::size_t(i)] == 0) c.free_index[std::size_t(i)] = int(nf++);
    else c.free_index[std::size_t(i)] = -1;
  c.n_free = nf;
  // L̂ restricted to the free columns and LᵀL: the expensive part, reused while the free set
  // (hard + isolated vertices) is unchanged, e.g. when only soft constraints or weights change
  if (c.nl_free_index != c.free_index) {
    // the free columns keep their order (free indices increase with the vertex): copied whole
    Eigen::Index nnz = 0;
    for (Eigen::Index col = 0; col < n; ++col)
      if (c.free_index[std::size_t(col)] >= 0) nnz += L_.outerIndexPtr()[col + 1] - L_.outerIndexPtr()[col];
    c.L_free.resize(n, nf);
    c.L_free.resizeNonZeros(nnz);
    c.L_free.outerIndexPtr()[0] = 0;
    for (Eigen::Index col = 0, at = 0; col < n; ++col) {
      const int fc = c.free_index[std::size_t(col)];
      if (fc < 0) continue;
      const int b = L_.outerIndexPtr()[col], e = L_.outerIndexPtr()[col + 1];
      std::copy(L_.innerIndexPtr() + b, L_.innerIndexPtr() + e, c.L_free.innerIndexPtr() + at);
      std::copy(L_.valuePtr() + b, L_.valuePtr() + e, c.L_free.valuePtr() + at);
      at += e - b;
      c.L_free.outerIndexPtr()[fc + 1] = int(at);
    }
    // sorted inner indices: the in-place assembly below binary-searches them
    c.NL = detail::gram_sorted(c.L_free);
    c.nl_free_index = c.free_index;
    c.N_work.resize(0, 0);
  }
  // scalar rows
  c.coupled = false;
  for (const auto& con : constraints_)
    if (!con.hard && con.type != ConstraintType::Position) c.coupled = true;
  c.rows.clear();
  for (std::size_t id = 0; id < constraints_.size(); ++id) {
    const auto& con = constraints_[id];
    if (con.hard) continue;
    detail::ScalarRow r;
    r.cid = int(id);
    if (con.at.vertex >= 0) r.stencil.emplace_back(con.at.vertex, 1.0);
    else for (int k = 0; k < 3; ++k) if (con.at.bary(k) != 0) r.stencil.emplace_back(mesh_.F(con.at.face, k), con.at.bary(k));
    if (!c.coupled) { c.rows.push_back(r); continue; }
    if (con.type == ConstraintType::Position) {
      for (int d = 0; d < 3; ++d) { r.m = Eigen::Vector3d::Unit(d); c.rows.push_back(r); }
    } else if (con.type == ConstraintType::Plane) {
      r.m = con.axis; c.rows.push_back(r);
    } else {
      Eigen::Vector3d n1, n2;
      orthonormal_pair(con.axis, n1, n2);
      r.m = n1; c.rows.push_back(r);
      r.m = n2; c.rows.push_back(r);
    }
  }
  // normal matrix: NL (per coordinate) + the constraint terms
  const Eigen::SparseMatrix<double>& NL = c.NL;
  // fast path (uncoupled): every constraint term falls on NL's pattern (a vertex, or vertices of
  // one face, which are neighbours in LᵀL), so N is NL with values added in place — no triplet
  // sort of the whole matrix on every re-weighting; falls back below if an entry is missing
  // every term w²·b_a·b_b of a scalar row between the free unknowns fa, fb; f returns false to stop
  auto for_each_term = [&](auto&& f) {
    for (const auto& r : c.rows) {
      const double w2 = constraints_[std::size_t(r.cid)].weight * constraints_[std::size_t(r.cid)].weight;
      for (auto [va, ba] : r.stencil) {
        const int fa = c.free_index[std::size_t(va)];
        if (fa < 0) continue;
        for (auto [vb, bb] : r.stencil) {
          const int fb = c.free_index[std::size_t(vb)];
          if (fb >= 0 && !f(r, fa, fb, w2 * ba * bb)) return false;
        }
      }
    }
    return true;
  };
  // optional anchor ε‖x − V_rest‖² (setAnchor): keeps the factorization positive definite when
  // a folded or degenerate mesh gives the Laplacian extra (near-)null vectors
  auto factorize = [&](Eigen::SparseMatrix<double>& N) {
    c.anchor = 0.0;
    if (nf > 0 && anchor_ > 0) {
      // relative to the median diagonal entry: robust to a few huge entries (the cotangents of
      // a nearly degenerate triangle), which made a mean-relative anchor outweigh every
      // constraint so the solve returned the rest shape
      std::vector<double> dg(std::size_t(N.rows()));
      for (Eigen::Index i = 0; i < N.rows(); ++i) dg[std::size_t(i)] = std::abs(N.coeff(i, i));
      std::nth_element(dg.begin(), dg.begin() + long(dg.size() / 2), dg.end());
      c.anchor = anchor_ * dg[dg.size() / 2];
    }
    if (c.anchor > 0)
      for (Eigen::Index i = 0; i < N.rows(); ++i) N.coeffRef(i, i) += c.anchor;
    report_progress(progress_, 0.3, "factorize");
    const auto t0 = Clock::now();
    if (nf > 0) c.solver.compute(N);
    report_.t_factorize = seconds_since(t0);
    c.matrix_valid = true;
    c.rhs_base_valid = false;
  };
  // fast path (uncoupled): every constraint term falls on NL's pattern (a vertex, or vertices of
  // one face, which are neighbours in LᵀL), so N is NL with values added in place — no triplet
  // sort of the whole matrix on every re-weighting; falls back below if an entry is missing.
  // The terms are summed first and NL added last, as the triplet path does: bit-identical
  // matrices whichever path runs.
  if (!c.coupled) {
    // N and the term buffer live in the cache: re-weightings overwrite them instead of
    // allocating (and page-faulting) tens of MB each time
    Eigen::SparseMatrix<double>& N = c.N_work;
    if (N.rows() != NL.rows() || N.nonZeros() != NL.nonZeros()) {
      N = NL;
      N.makeCompressed();
    } else {
      std::copy(NL.valuePtr(), NL.valuePtr() + NL.nonZeros(), N.valuePtr());
    }
    std::vector<double>& add = c.add_work;
    add.assign(std::size_t(N.nonZeros()), 0.0);
    const bool ok = for_each_term([&](const detail::ScalarRow&, int fa, int fb, double v) {
      const int* first = N.innerIndexPtr() + N.outerIndexPtr()[fb];
      const int* last = N.innerIndexPtr() + N.outerIndexPtr()[fb + 1];
      const int* at = std::lower_bound(first, last, fa);
      if (at == last || *at != fa) return false;
      add[std::size_t(at - N.innerIndexPtr())] += v;
      return true;
    });
    if (ok) {
      for (std::size_t k = 0; k < add.size(); ++k) N.valuePtr()[k] = add[k] + N.valuePtr()[k];
      factorize(N);
      return;
    }
  }
  std::vector<Eigen::Triplet<double>> t;
  const int dims = c.coupled ? 3 : 1;
  t.reserve((c.coupled ? std::size_t(NL.nonZeros()) * 3 : 0) + c.rows.size() * 27);
  if (c.coupled)
    for (int d = 0; d < 3; ++d)
      for (int col = 0; col < NL.outerSize(); ++col)
        for (Eigen::SparseMatrix<double>::InnerIterator it(NL, col); it; ++it)
          t.emplace_back(int(d * nf + it.row()), int(d * nf + it.col()), it.value());
  for_each_term([&](const detail::ScalarRow& r, int fa, int fb, double v) {
    if (!c.coupled) {
      t.emplace_back(fa, fb, v);
      return true;
    }
    for (int d1 = 0; d1 < 3; ++d1)
      for (int d2 = 0; d2 < 3; ++d2) {
        const double x = v * r.m(d1) * r.m(d2);
        if (x != 0) t.emplace_back(int(d1 * nf + fa), int(d2 * nf + fb), x);
      }
    return true;
  });
  Eigen::SparseMatrix<double> N(dims * nf, dims * nf);
  N.setFromTriplets(t.begin(), t.end());
  if (!c.coupled) N += NL;
  factorize(N);
}

void LaplacianDeformer::copySolverAnalysis(const LaplacianDeformer& other) {
  if (this == &other) return;
  cache_->solver.copyAnalysis(other.cache_->solver);
  cache_->matrix_valid = false;  // (the copy dropped the factorization; the rotation graph stays)
}

const ConstraintGraph* LaplacianDeformer::rotationGraph() const {
  return cache_->graph_valid ? &cache_->graph : nullptr;
}

Eigen::MatrixX3d LaplacianDeformer::deform() {
  requireMesh("deform");
  Cache& c = *cache_;
  const Eigen::Index n = mesh_.V.rows();
  const double t_laplacian = report_.t_laplacian;
  report_ = DeformReport{};
  report_.t_laplacian = t_laplacian;
  report_.vertices = n;
  report_progress(progress_, 0.0, "laplacian");
  report_.refactorized = !c.matrix_valid;
  if (!c.matrix_valid) {
    report_.t_graph = report_.t_factorize = 0;
    const bool graph_too = user_rotations_.empty() && use_rotation_field_ && !c.graph_valid;
#ifdef _OPENMP
    if (graph_too && omp_get_max_threads() > 1 && !omp_in_parallel()) {
      // the factorization and the rotation field's set-up (geodesics + a Laplacian system of
      // their own) do not depend on each other: one thread each. Thread 0 is the caller's and
      // reports progress; errors are rethrown in the sequential order. One BLAS thread each:
      // OpenBLAS's own threads on top of ours oversubscribe the cores (the survey's 40k plane:
      // 1.25 s with them, 0.75 s on one thread in all).
      const ScopedBlasThreads blas_threads(1);
      std::exception_ptr err[2];
#pragma omp parallel num_threads(2)
      {
        const bool both = omp_get_num_threads() < 2;
        if (omp_get_thread_num() == 0) {
          try { buildSystem(); } catch (...) { err[0] = std::current_exception(); }
          if (both && !err[0]) {
            try { buildRotationGraph(true); } catch (...) { err[1] = std::current_exception(); }
          }
        } else {
          try { buildRotationGraph(false); } catch (...) { err[1] = std::current_exception(); }
        }
      }
      for (const auto& e : err)
        if (e) std::rethrow_exception(e);
    } else {
      buildSystem();
    }
#else
    (void)graph_too;
    buildSystem();
#endif
  }
  const Eigen::MatrixX3d d = rotatedDelta();
  report_progress(progress_, 0.8, "solve");
  const auto t0 = Clock::now();
  // fixed values
  c.X0 = Eigen::MatrixX3d::Zero(n, 3);
  for (Eigen::Index i = 0; i < n; ++i)
    if (c.isolated[std::size_t(i)]) c.X0.row(i) = mesh_.V.row(i);
  for (const auto& con : constraints_)
    if (con.hard) c.X0.row(con.at.vertex) = con.target.transpose();
  const Eigen::Index nf = c.n_free;
  Eigen::MatrixX3d X = c.X0;
  if (nf > 0) {
    if (!c.coupled) {
      // the targets of soft constraints are what an interactive drag changes: the rest of the
      // right-hand side is reused while δ' and the fixed positions stay the same
      const bool same_base = c.rhs_base_valid && c.rhs_base.rows() == nf && c.rhs_delta.rows() == n &&
                             c.rhs_delta == d && c.rhs_X0 == c.X0;
      if (!same_base) {
        c.rhs_base = c.L_free.transpose() * (d - L_ * c.X0);
        for (Eigen::Index i = 0; i < n; ++i)
          if (c.free_index[std::size_t(i)] >= 0) c.rhs_base.row(c.free_index[std::size_t(i)]) += c.anchor * mesh_.V.row(i);
        c.rhs_delta = d;
        c.rhs_X0 = c.X0;
        c.rhs_base_valid = true;
      }
      Eigen::MatrixXd& rhs = c.rhs_work;
      rhs = c.rhs_base;  // same size after the first solve: no allocation
      for (const auto& r : c.rows) {
        const auto& con = constraints_[std::size_t(r.cid)];
        Eigen::RowVector3d q = con.target.transpose();
        for (auto [v, b] : r.stencil)
          if (c.free_index[std::size_t(v)] < 0) q -= b * c.X0.row(v);
        const double w2 = con.weight * con.weight;
        for (auto [v, b] : r.stencil) {
          const int f = c.free_index[std::size_t(v)];
          if (f >= 0) rhs.row(f) += w2 * b * q;
        }
      }
      c.solver.solve(rhs, c.x_work);
      const Eigen::MatrixXd& Xf = c.x_work;
      for (Eigen::Index i = 0; i < n; ++i)
        if (c.free_index[std::size_t(i)] >= 0) X.row(i) = Xf.row(c.free_index[std::size_t(i)]);
    } else {
      const Eigen::MatrixX3d rL = c.L_free.transpose() * (d - L_ * c.X0);  // nf by 3
      Eigen::VectorXd rhs(3 * nf);
      for (int dd = 0; dd < 3; ++dd) rhs.segment(dd * nf, nf) = rL.col(dd);
      for (Eigen::Index i = 0; i < n; ++i)
        if (c.free_index[std::size_t(i)] >= 0)
          for (int dd = 0; dd < 3; ++dd) rhs(dd * nf + c.free_index[std::size_t(i)]) += c.anchor * mesh_.V(i, dd);
      for (const auto& r : c.rows) {
        const auto& con = constraints_[std::size_t(r.cid)];
        double q = r.m.dot(con.target);
        for (auto [v, b] : r.stencil)
          if (c.free_index[std::size_t(v)] < 0) q -= b * r.m.dot(c.X0.row(v).transpose());
        const double w2 = con.weight * con.weight;
        for (auto [v, b] : r.stencil) {
          const int f = c.free_index[std::size_t(v)];
          if (f < 0) continue;
          for (int dd = 0; dd < 3; ++dd) rhs(dd * nf + f) += w2 * r.m(dd) * b * q;
        }
      }
      const Eigen::VectorXd Xf = c.solver.solve(rhs);
      for (Eigen::Index i = 0; i < n; ++i) {
        const int f = c.free_index[std::size_t(i)];
        if (f >= 0) X.row(i) << Xf(f), Xf(nf + f), Xf(2 * nf + f);
      }
    }
  }
  report_.t_solve = seconds_since(t0);
  if (!X.allFinite()) throw NumericalFailure("[tbsp::LaplacianDeformer::deform] the solution is not finite");
  // report
  report_.free_vertices = nf;
  for (Eigen::Index i = 0; i < n; ++i) report_.fixed_isolated += c.isolated[std::size_t(i)] ? 1 : 0;
  report_.coupled_xyz = c.coupled;
  report_.scale = scale_;
  report_.backend = c.solver.backendName();
  double sq = 0;
  for (std::size_t id = 0; id < constraints_.size(); ++id) {
    const auto& con = constraints_[id];
    const Eigen::Vector3d p = evaluate(con.at, X);
    ConstraintResidual r;
    r.id = int(id);
    r.type = con.type;
    r.hard = con.hard;
    const Eigen::Vector3d e = p - con.target;
    if (con.type == ConstraintType::Position) r.distance = e.norm();
    else if (con.type == ConstraintType::Plane) r.distance = std::abs(e.dot(con.axis));
    else r.distance = (e - e.dot(con.axis) * con.axis).norm();
    report_.residuals.push_back(r);
    report_.max_residual = std::max(report_.max_residual, r.distance);
    sq += r.distance * r.distance;
    if (con.hard) ++report_.hard_constraints;
    else if (con.type == ConstraintType::Position) ++report_.position_constraints;
    else if (con.type == ConstraintType::Line) ++report_.line_constraints;
    else ++report_.plane_constraints;
  }
  report_.rms_residual = constraints_.empty() ? 0 : std::sqrt(sq / double(constraints_.size()));
  report_progress(progress_, 1.0, "solve");
  return X;
}

}  // namespace tbsp
