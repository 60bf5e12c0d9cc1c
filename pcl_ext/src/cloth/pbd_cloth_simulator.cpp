// PbdClothSimulator: setup (constraints, masses, colouring) and the time step. The constraint
// projections are in pbd_constraints.cpp.
#include "tbsp/cloth/pbd_cloth_simulator.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <queue>
#include <string>

#include "tbsp/core/error.h"
#include "tbsp/mesh/topology.h"
#include "tbsp/mesh/tri_mesh.h"

namespace tbsp {

namespace {

const char* kSimulatorWhere = "[tbsp::PbdClothSimulator] ";

// Greedy colouring: constraint c gets the smallest colour none of its vertices has yet. Colours
// 0..127 are tracked per vertex; a constraint that finds all taken goes to a last colour that is
// swept serially (still deterministic).
template <class VerticesOf>
std::vector<std::vector<int>> greedy_colouring(int num_constraints, Eigen::Index num_vertices, VerticesOf vertices_of) {
  std::vector<std::uint64_t> used(std::size_t(2 * num_vertices), 0);
  std::vector<std::vector<int>> colours;
  std::vector<int> serial;
  for (int c = 0; c < num_constraints; ++c) {
    const std::vector<int> vs = vertices_of(c);
    std::uint64_t m0 = 0, m1 = 0;
    for (int v : vs) m0 |= used[2 * std::size_t(v)], m1 |= used[2 * std::size_t(v) + 1];
    int colour = -1;
    if (~m0) colour = __builtin_ctzll(~m0);
    else if (~m1) colour = 64 + __builtin_ctzll(~m1);
    if (colour < 0) {
      serial.push_back(c);
      continue;
    }
    for (int v : vs) used[2 * std::size_t(v) + std::size_t(colour / 64)] |= std::uint64_t(1) << (colour % 64);
    if (int(colours.size()) <= colour) colours.resize(std::size_t(colour + 1));
    colours[std::size_t(colour)].push_back(c);
  }
  if (!serial.empty()) colours.push_back(serial);  // conflicts allowed: projected by one thread
  return colours;
}

std::size_t conflict_colour(const std::vector<std::vector<int>>& colours) {
  // greedy_colouring appends the conflicting constraints after 128 colours
  return colours.size() > 128 ? colours.size() - 1 : std::size_t(-1);
}

double dihedral(const Eigen::Vector3d& p0, const Eigen::Vector3d& p1, const Eigen::Vector3d& p2, const Eigen::Vector3d& p3) {
  // p2-p3 the shared edge, p0 and p1 the wings; 0 when flat (Bender's PBD convention)
  const Eigen::Vector3d n1 = (p2 - p0).cross(p3 - p0).normalized();
  const Eigen::Vector3d n2 = (p3 - p1).cross(p2 - p1).normalized();
  return std::acos(std::clamp(n1.dot(n2), -1.0, 1.0));
}

}  // namespace

void PbdClothSimulator::setMesh(const Eigen::MatrixX3d& V, const Eigen::MatrixX3i& F) {
  if (V.rows() == 0 || F.rows() == 0) throw InvalidInput(std::string(kSimulatorWhere) + "setMesh: the mesh is empty");
  if (!V.allFinite()) throw InvalidInput(std::string(kSimulatorWhere) + "setMesh: non-finite vertex coordinates");
  if (F.minCoeff() < 0 || F.maxCoeff() >= V.rows())
    throw InvalidInput(std::string(kSimulatorWhere) + "setMesh: a face index is out of range (" + std::to_string(V.rows()) + " vertices)");
  for (Eigen::Index f = 0; f < F.rows(); ++f)
    if (F(f, 0) == F(f, 1) || F(f, 1) == F(f, 2) || F(f, 0) == F(f, 2))
      throw InvalidInput(std::string(kSimulatorWhere) + "setMesh: face " + std::to_string(f) + " repeats a vertex; remove degenerate faces first");
  rest_ = V;
  F_ = F;
  const Eigen::Index n = V.rows();
  // vertex -> faces (ascending face index: the order the normals were scattered in, so the
  // per-vertex gather in applyExternal sums them in the same order)
  vertex_faces(F, n, vf_offsets_, vf_faces_);
  // edges -> wing vertices
  std::map<std::pair<int, int>, std::vector<int>> wings;
  for (Eigen::Index f = 0; f < F.rows(); ++f)
    for (int k = 0; k < 3; ++k) {
      const int a = F(f, k), b = F(f, (k + 1) % 3), c = F(f, (k + 2) % 3);
      wings[{std::min(a, b), std::max(a, b)}].push_back(c);
    }
  stretch_.clear();
  bend_.clear();
  for (const auto& [e, w] : wings) {
    const double len = (V.row(e.first) - V.row(e.second)).norm();
    stretch_.push_back({e.first, e.second, len});
    if (w.size() == 2 && w[0] != w[1]) bend_.push_back({e.first, e.second, w[0], w[1], 0.0, 0});
  }
  mass_ = Eigen::VectorXd::Zero(n);
  const Eigen::VectorXd A = face_areas(V, F);
  for (Eigen::Index f = 0; f < F.rows(); ++f)
    for (int k = 0; k < 3; ++k) mass_(F(f, k)) += A(f) / 3;
  const double mean_mass = mass_.sum() / double(n);
  for (Eigen::Index i = 0; i < n; ++i)
    if (!(mass_(i) > 1e-9 * mean_mass)) mass_(i) = 1e-9 * mean_mass;  // isolated / sliver vertices
  delta_ = Eigen::VectorXd::Ones(n);
  k_blend_.clear();
  region_ = Eigen::VectorXi::Zero(n);
  setSettings(settings_);  // rest angles depend on flat_rest_angle
  buildColours();
  reset(V);
}

void PbdClothSimulator::buildColours() {
  // only constraints that can move a vertex (one of theirs is simulated, δ > 0) are swept: a body
  // with a skirt spends no time on the skinned part
  auto sim = [&](int v) { return delta_(v) > 0; };
  std::vector<int> st, bd;
  for (int c = 0; c < int(stretch_.size()); ++c)
    if (sim(stretch_[std::size_t(c)].a) || sim(stretch_[std::size_t(c)].b)) st.push_back(c);
  for (int c = 0; c < int(bend_.size()); ++c) {
    const auto& b = bend_[std::size_t(c)];
    if (sim(b.a) || sim(b.b) || sim(b.c) || sim(b.d)) bd.push_back(c);
  }
  stretch_colours_ = greedy_colouring(int(st.size()), rest_.rows(), [&](int c) {
    return std::vector<int>{stretch_[std::size_t(st[std::size_t(c)])].a, stretch_[std::size_t(st[std::size_t(c)])].b};
  });
  for (auto& colour : stretch_colours_)
    for (int& c : colour) c = st[std::size_t(c)];
  bend_colours_ = greedy_colouring(int(bd.size()), rest_.rows(), [&](int c) {
    const auto& b = bend_[std::size_t(bd[std::size_t(c)])];
    return std::vector<int>{b.a, b.b, b.c, b.d};
  });
  for (auto& colour : bend_colours_)
    for (int& c : colour) c = bd[std::size_t(c)];
  stretch_conflict_colour_ = conflict_colour(stretch_colours_);
  bend_conflict_colour_ = conflict_colour(bend_colours_);
}

void PbdClothSimulator::buildTethers() {
  // multi-source Dijkstra over the edges of the rest mesh from every kinematic vertex
  const std::size_t n = std::size_t(rest_.rows());
  tether_anchor_.assign(n, -1);
  tether_length_.assign(n, std::numeric_limits<double>::infinity());
  tethers_dirty_ = false;
  if (!settings_.tethers) return;
  std::vector<std::vector<std::pair<int, double>>> adj(n);
  for (const auto& e : stretch_) {
    adj[std::size_t(e.a)].emplace_back(e.b, e.rest);
    adj[std::size_t(e.b)].emplace_back(e.a, e.rest);
  }
  using Item = std::pair<double, int>;
  std::priority_queue<Item, std::vector<Item>, std::greater<Item>> queue;
  for (std::size_t i = 0; i < n; ++i)
    if (delta_(Eigen::Index(i)) <= 0.5) {  // mostly skinned: held near its skinned position
      tether_anchor_[i] = int(i);
      tether_length_[i] = 0;
      queue.emplace(0.0, int(i));
    }
  while (!queue.empty()) {
    const auto [d, v] = queue.top();
    queue.pop();
    if (d > tether_length_[std::size_t(v)]) continue;
    for (const auto& [w, len] : adj[std::size_t(v)]) {
      const double nd = d + len;
      if (nd < tether_length_[std::size_t(w)] ||
          (nd == tether_length_[std::size_t(w)] && tether_anchor_[std::size_t(v)] < tether_anchor_[std::size_t(w)])) {
        tether_length_[std::size_t(w)] = nd;
        tether_anchor_[std::size_t(w)] = tether_anchor_[std::size_t(v)];
        queue.emplace(nd, w);
      }
    }
  }
  for (std::size_t i = 0; i < n; ++i) {
    if (tether_anchor_[i] == int(i)) tether_anchor_[i] = -1;  // anchors need none
    tether_length_[i] *= 1 + settings_.tether_slack;
  }
}

void PbdClothSimulator::setClothness(const Eigen::VectorXd& delta) {
  if (delta.size() != rest_.rows())
    throw InvalidInput(std::string(kSimulatorWhere) + "setClothness: " + std::to_string(delta.size()) + " values for " +
                       std::to_string(rest_.rows()) + " vertices (call setMesh first)");
  for (Eigen::Index i = 0; i < delta.size(); ++i)
    if (!(delta(i) >= 0 && delta(i) <= 1))
      throw InvalidInput(std::string(kSimulatorWhere) + "setClothness: vertex " + std::to_string(i) + " has clothness " +
                         std::to_string(delta(i)) + ", expected a value in [0, 1]");
  delta_ = delta;
  k_blend_.clear();
  tethers_dirty_ = true;
  buildColours();
}

void PbdClothSimulator::setRegions(const Eigen::VectorXi& region) {
  if (region.size() != rest_.rows())
    throw InvalidInput(std::string(kSimulatorWhere) + "setRegions: " + std::to_string(region.size()) + " labels for " +
                       std::to_string(rest_.rows()) + " vertices");
  if (region.size() && region.minCoeff() < 0) throw InvalidInput(std::string(kSimulatorWhere) + "setRegions: labels must be ≥ 0");
  region_ = region;
  for (auto& b : bend_) b.region = std::max(region_(b.a), region_(b.b));
  const int k = region.size() ? region.maxCoeff() + 1 : 1;
  if (int(materials_.size()) < k) materials_.resize(std::size_t(k), materials_.front());
}

void PbdClothSimulator::setMaterial(const ClothMaterial& m, int region) {
  if (region < 0) throw InvalidInput(std::string(kSimulatorWhere) + "setMaterial: region must be ≥ 0");
  if (!(m.d_n >= 0) || !(m.d_t >= 0) || !std::isfinite(m.d_n + m.d_t) || !(m.k_bend >= 0 && m.k_bend <= 1))
    throw InvalidInput(std::string(kSimulatorWhere) + "setMaterial: need finite d_n ≥ 0, d_t ≥ 0 and k_bend in [0, 1] (got " +
                       std::to_string(m.d_n) + ", " + std::to_string(m.d_t) + ", " + std::to_string(m.k_bend) + ")");
  if (int(materials_.size()) <= region) materials_.resize(std::size_t(region + 1), materials_.front());
  materials_[std::size_t(region)] = m;
}

void PbdClothSimulator::setSettings(const PbdSettings& s) {
  validate_pbd_settings(s, "tbsp::PbdClothSimulator::setSettings");
  settings_ = s;
  tethers_dirty_ = true;
  for (auto& b : bend_)
    b.rest = s.flat_rest_angle ? 0.0 : dihedral(rest_.row(b.c).transpose(), rest_.row(b.d).transpose(), rest_.row(b.a).transpose(),
                                                 rest_.row(b.b).transpose());
}

void PbdClothSimulator::reset(const Eigen::MatrixX3d& P) {
  if (P.rows() != rest_.rows()) throw InvalidInput(std::string(kSimulatorWhere) + "reset: " + std::to_string(P.rows()) + " positions for " +
                                                   std::to_string(rest_.rows()) + " vertices");
  if (!P.allFinite()) throw InvalidInput(std::string(kSimulatorWhere) + "reset: non-finite positions");
  const Eigen::Index n = P.rows();
  pos_.resize(std::size_t(n));
  vel_.assign(std::size_t(n), Eigen::Vector3d::Zero());
  pred_.resize(std::size_t(n));
  for (Eigen::Index i = 0; i < n; ++i) pos_[std::size_t(i)] = P.row(i).transpose();
  targets_prev_ = P;
  proxies_prev_.clear();
  syncOut();
}

void PbdClothSimulator::reset(const Eigen::MatrixX3d& P, const Eigen::MatrixX3d& U, const Eigen::MatrixX3d& targets,
                              const std::vector<RoundCone>& proxies) {
  if (U.rows() != P.rows() || targets.rows() != P.rows())
    throw InvalidInput(std::string(kSimulatorWhere) + "reset: " + std::to_string(U.rows()) + " velocities and " + std::to_string(targets.rows()) +
                       " targets for " + std::to_string(P.rows()) + " positions");
  if (!U.allFinite() || !targets.allFinite()) throw InvalidInput(std::string(kSimulatorWhere) + "reset: non-finite velocities or targets");
  reset(P);
  for (Eigen::Index i = 0; i < U.rows(); ++i) vel_[std::size_t(i)] = delta_(i) > 0 ? Eigen::Vector3d(U.row(i).transpose()) : Eigen::Vector3d::Zero();
  targets_prev_ = targets;
  proxies_prev_ = proxies;
  syncOut();
}

void PbdClothSimulator::step(const Eigen::MatrixX3d& targets_in, const std::vector<RoundCone>& proxies) {
  if (x_.rows() == 0) throw InvalidInput(std::string(kSimulatorWhere) + "step: call setMesh first");
  const bool have_targets = targets_in.rows() > 0;
  if (have_targets && targets_in.rows() != x_.rows())
    throw InvalidInput(std::string(kSimulatorWhere) + "step: " + std::to_string(targets_in.rows()) + " targets for " + std::to_string(x_.rows()) +
                       " vertices");
  if (have_targets && !targets_in.allFinite()) throw InvalidInput(std::string(kSimulatorWhere) + "step: the targets contain NaN or Inf");
  for (std::size_t k = 0; k < proxies.size(); ++k)
    if (!proxies[k].a.allFinite() || !proxies[k].b.allFinite() || !(proxies[k].ra >= 0) || !(proxies[k].rb >= 0))
      throw InvalidInput(std::string(kSimulatorWhere) + "step: proxy " + std::to_string(k) + " has non-finite ends or a negative radius");
  const Eigen::MatrixX3d& targets = have_targets ? targets_in : x_;
  if (proxies_prev_.size() != proxies.size()) proxies_prev_ = proxies;
  const int ns = settings_.substeps;
  const double dt = settings_.time_step / ns;
  auto lerp = [&](double t) {
    std::vector<RoundCone> sub = proxies;
    for (std::size_t k = 0; k < proxies.size(); ++k) {
      sub[k].a = (1 - t) * proxies_prev_[k].a + t * proxies[k].a;
      sub[k].b = (1 - t) * proxies_prev_[k].b + t * proxies[k].b;
      sub[k].ra = (1 - t) * proxies_prev_[k].ra + t * proxies[k].ra;
      sub[k].rb = (1 - t) * proxies_prev_[k].rb + t * proxies[k].rb;
    }
    return sub;
  };
  const std::size_t n = pos_.size();
  inv_mass_.resize(n);
#pragma omp parallel for schedule(static) if (n >= kParallelMin)
  for (std::size_t i = 0; i < n; ++i) inv_mass_[i] = delta_(Eigen::Index(i)) > 0 ? 1.0 / mass_(Eigen::Index(i)) : 0.0;
  if (tethers_dirty_) buildTethers();
  const int interval = settings_.contact_interval;
  for (int s = 0; s < ns; ++s) {
    const double t0 = double(s) / ns, t1 = double(s + 1) / ns;
    // proxy candidates every sub-step (cheap: one sphere test per vertex and proxy; constraints
    // such as tethers can move a vertex farther than its velocity says), self-contacts every
    // `contact_interval` sub-steps within the distance a vertex can travel meanwhile
    const int window = s % interval == 0 ? std::min(interval, ns - s) : 1;
    const double T = window * dt;
    std::vector<double>& travel = travel_;
    travel.resize(n);
    double vmax = 0;
    const double fall = 0.5 * settings_.gravity.norm() * T * T;
#pragma omp parallel for schedule(static) reduction(max : vmax) if (n >= kParallelMin)
    for (std::size_t i = 0; i < n; ++i) {
      if (inv_mass_[i] != 0) {
        travel[i] = vel_[i].norm() * T + fall;
        vmax = std::max(vmax, travel[i]);
      } else {
        travel[i] = (targets.row(Eigen::Index(i)).transpose() - pos_[i]).norm();
      }
    }
    findProxyCandidates(lerp(t0), lerp(t1), vmax);
    if (s % interval == 0) findSelfContacts(travel);
    substep(targets, lerp(t0), lerp(t1), t1, dt);
  }
  targets_prev_ = targets;
  proxies_prev_ = proxies;
  syncOut();
  // an explicit step can diverge (drag coefficients far beyond the thesis' ranges, a time step
  // too long for the stiffness): refuse to hand out non-finite positions as a frame
  if (!x_.allFinite() || !u_.allFinite())
    throw NumericalFailure(std::string(kSimulatorWhere) + "step: the simulation diverged (non-finite positions or velocities "
                           "after this frame); lower the drag coefficients d_n / d_t (the thesis searches d_n in [0, 10], "
                           "d_t in [0, 50]) or shorten the time step (more substeps)");
}

void PbdClothSimulator::syncOut() {
  const Eigen::Index n = Eigen::Index(pos_.size());
  x_.resize(n, 3);
  u_.resize(n, 3);
  for (Eigen::Index i = 0; i < n; ++i) {
    x_.row(i) = pos_[std::size_t(i)].transpose();
    u_.row(i) = vel_[std::size_t(i)].transpose();
  }
}

double PbdClothSimulator::kineticEnergy() const {
  double e = 0;
  for (Eigen::Index i = 0; i < x_.rows(); ++i)
    if (delta_(i) > 0) e += 0.5 * mass_(i) * u_.row(i).squaredNorm();
  return e;
}

double PbdClothSimulator::potentialEnergy() const {
  double e = 0;
  for (Eigen::Index i = 0; i < x_.rows(); ++i)
    if (delta_(i) > 0) e -= mass_(i) * settings_.gravity.dot(x_.row(i).transpose());
  return e;
}

double PbdClothSimulator::strainQuantile(double q) const {
  if (stretch_.empty()) return 0;
  std::vector<double> e;
  e.reserve(stretch_.size());
  for (const auto& s : stretch_)
    if (s.rest > 0 && delta_(s.a) > 0 && delta_(s.b) > 0)
      e.push_back(std::abs((pos_[std::size_t(s.a)] - pos_[std::size_t(s.b)]).norm() / s.rest - 1));
  if (e.empty()) return 0;
  const std::size_t k = std::min(e.size() - 1, std::size_t(std::clamp(q, 0.0, 1.0) * double(e.size() - 1)));
  std::nth_element(e.begin(), e.begin() + std::ptrdiff_t(k), e.end());
  return e[k];
}

double PbdClothSimulator::maxStrain() const {
  double m = 0;
  for (const auto& s : stretch_)
    if (s.rest > 0 && delta_(s.a) > 0 && delta_(s.b) > 0)
      m = std::max(m, std::abs((pos_[std::size_t(s.a)] - pos_[std::size_t(s.b)]).norm() / s.rest - 1));
  return m;
}

}  // namespace tbsp
