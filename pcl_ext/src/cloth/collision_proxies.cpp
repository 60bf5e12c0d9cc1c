#include "tbsp/cloth/collision_proxies.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <map>

#include "tbsp/core/error.h"
#include "tbsp/mesh/tri_mesh.h"

namespace tbsp {

namespace {

// The part of a bone used for the 1-D fit and the inside test: vertices near the joints (t close
// to 0 or 1) are where bones meet the surface (joint caps, end sites) and say nothing about the
// limb's radius.
constexpr double kSideLo = 0.05, kSideHi = 0.95;

Eigen::Vector3d any_perpendicular(const Eigen::Vector3d& u) {
  const Eigen::Vector3d c = std::abs(u.x()) < 0.9 ? Eigen::Vector3d::UnitX() : Eigen::Vector3d::UnitY();
  return u.cross(c).normalized();
}

std::string lower(std::string s) {
  for (auto& c : s) c = char(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

// The name of the mirror joint: Left <-> Right, or a leading L/R (LHip, RThigh, l_knee).
std::string mirror_name(const std::string& n) {
  for (const auto& [a, b] : std::vector<std::pair<std::string, std::string>>{{"Left", "Right"}, {"Right", "Left"}, {"left", "right"}, {"right", "left"}}) {
    const auto pos = n.find(a);
    if (pos != std::string::npos) return n.substr(0, pos) + b + n.substr(pos + a.size());
  }
  if (n.size() > 1 && (n[0] == 'L' || n[0] == 'R' || n[0] == 'l' || n[0] == 'r') &&
      (std::isupper(static_cast<unsigned char>(n[1])) || n[1] == '_')) {
    std::string m = n;
    m[0] = n[0] == 'L' ? 'R' : n[0] == 'R' ? 'L' : n[0] == 'l' ? 'r' : 'l';
    return m;
  }
  return {};
}

}  // namespace

double RoundCone::signedDistance(const Eigen::Vector3d& p, Eigen::Vector3d* normal) const {
  const Eigen::Vector3d ba = b - a;
  const double l2 = ba.squaredNorm();
  const double rr = ra - rb;
  const double a2 = l2 - rr * rr;
  if (a2 <= 0) {  // one sphere holds the other (or a point cone): the larger sphere
    const Eigen::Vector3d c = ra >= rb ? a : b;
    const double r = std::max(ra, rb);
    const Eigen::Vector3d d = p - c;
    const double len = d.norm();
    if (normal) *normal = len > 0 ? Eigen::Vector3d(d / len) : Eigen::Vector3d::UnitY();
    return len - r;
  }
  const double il2 = 1.0 / l2;
  const Eigen::Vector3d pa = p - a;
  const double y = pa.dot(ba);
  const double z = y - l2;
  const double x2 = (pa * l2 - ba * y).squaredNorm();
  const double y2 = y * y * l2;
  const double z2 = z * z * l2;
  const double k = (rr > 0 ? 1.0 : rr < 0 ? -1.0 : 0.0) * rr * rr * x2;
  if ((z > 0 ? 1.0 : z < 0 ? -1.0 : 0.0) * a2 * z2 > k) {  // cap at b
    if (normal) {
      const Eigen::Vector3d d = p - b;
      const double len = d.norm();
      *normal = len > 0 ? Eigen::Vector3d(d / len) : Eigen::Vector3d(ba.normalized());
    }
    return std::sqrt(x2 + z2) * il2 - rb;
  }
  if ((y > 0 ? 1.0 : y < 0 ? -1.0 : 0.0) * a2 * y2 < k) {  // cap at a
    if (normal) {
      const double len = pa.norm();
      *normal = len > 0 ? Eigen::Vector3d(pa / len) : Eigen::Vector3d(-ba.normalized());
    }
    return std::sqrt(x2 + y2) * il2 - ra;
  }
  if (normal) {  // cone side: tilted radial direction
    const double L = std::sqrt(l2);
    const Eigen::Vector3d u = ba / L;
    Eigen::Vector3d e = pa - pa.dot(u) * u;
    const double el = e.norm();
    e = el > 1e-12 * L ? Eigen::Vector3d(e / el) : any_perpendicular(u);
    const double s = rr / L;
    *normal = s * u + std::sqrt(std::max(0.0, 1 - s * s)) * e;
  }
  return (std::sqrt(x2 * a2 * il2) + y * rr) * il2 - ra;
}

RoundCone RoundCone::transformed(const Eigen::Isometry3d& T) const {
  RoundCone c = *this;
  c.a = T * a;
  c.b = T * b;
  return c;
}

std::vector<RoundCone> posed_proxies(const std::vector<CollisionProxy>& proxies, const std::vector<Eigen::Isometry3d>& T) {
  std::vector<RoundCone> out;
  out.reserve(proxies.size());
  for (const auto& p : proxies) {
    if (p.bone.joint < 0 || std::size_t(p.bone.joint) >= T.size())
      throw InvalidInput("[tbsp::posed_proxies] a proxy's joint " + std::to_string(p.bone.joint) + " has no transform (" +
                         std::to_string(T.size()) + " given)");
    out.push_back(p.cone.transformed(T[std::size_t(p.bone.joint)]));
  }
  return out;
}

std::vector<CollisionProxy> fit_collision_proxies(const Eigen::MatrixX3d& V, const Eigen::MatrixX3i& F, const Skeleton& skeleton,
                                                  const Eigen::VectorXd& sigma_in, const Eigen::VectorXd& clothness_in,
                                                  const ProxyFitOptions& o) {
  const std::string w = "[tbsp::fit_collision_proxies] ";
  validate_skeleton(skeleton, "tbsp::fit_collision_proxies");
  if (V.rows() == 0 || F.rows() == 0) throw InvalidInput(w + "the mesh is empty");
  if (!V.allFinite()) throw InvalidInput(w + "the mesh has non-finite vertex coordinates");
  const Eigen::Index n = V.rows();
  const Eigen::VectorXd sigma = sigma_in.size() ? sigma_in : Eigen::VectorXd::Zero(n);
  const Eigen::VectorXd cloth = clothness_in.size() ? clothness_in : Eigen::VectorXd::Zero(n);
  if (sigma.size() != n || cloth.size() != n)
    throw InvalidInput(w + "sigma (" + std::to_string(sigma_in.size()) + ") and clothness (" + std::to_string(clothness_in.size()) +
                       ") need one value per vertex (" + std::to_string(n) + ") or none");
  if (!sigma.allFinite() || !cloth.allFinite() || (sigma.size() && sigma.minCoeff() < 0))
    throw InvalidInput(w + "sigma must be finite and ≥ 0, clothness finite");
  if (o.max_penetration < 0 || o.max_penetration > 1 || o.min_vertices < 3)
    throw InvalidInput(w + "options out of range: max_penetration in [0,1], min_vertices ≥ 3");
  const std::vector<Bone> bones = skeleton_bones(skeleton);
  if (bones.empty()) throw InvalidInput(w + "the skeleton has no bones");
  const int nb = int(bones.size());
  const double diag = bbox_diagonal(V);

  // nearest bone, axial parameter and radial distance of every vertex
  std::vector<int> nearest(std::size_t(n), -1);
  std::vector<double> tpar(static_cast<std::size_t>(n)), rad(static_cast<std::size_t>(n));
  for (Eigen::Index i = 0; i < n; ++i) {
    const Eigen::Vector3d p = V.row(i).transpose();
    double best = std::numeric_limits<double>::infinity();
    for (int b = 0; b < nb; ++b) {
      const Eigen::Vector3d a = skeleton.restPosition(bones[std::size_t(b)].joint), c = skeleton.restPosition(bones[std::size_t(b)].child);
      const Eigen::Vector3d ab = c - a;
      const double t = (p - a).dot(ab) / ab.squaredNorm();
      const double d = (p - (a + std::clamp(t, 0.0, 1.0) * ab)).norm();
      if (d < best) best = d, nearest[std::size_t(i)] = b, tpar[std::size_t(i)] = t, rad[std::size_t(i)] = (p - (a + t * ab)).norm();
    }
  }
  auto selected = [&](const Bone& b) {
    if (o.joints.empty()) return true;
    const std::string name = lower(skeleton.names[std::size_t(b.joint)]);
    for (const auto& j : o.joints)
      if (name.find(lower(j)) != std::string::npos) return true;
    return false;
  };

  std::vector<CollisionProxy> out;
  std::vector<int> out_bone;
  const double eps = 1e-3 * diag;
  for (int b = 0; b < nb; ++b) {
    if (!selected(bones[std::size_t(b)])) continue;
    // weighted linear regression of r − σ on t over the bone's vertices, made robust by
    // iteratively reweighted least squares (Tukey's biweight on the residuals, scale from their
    // median absolute deviation): vertices of other body parts that happen to lie nearest this
    // bone (inner surfaces, a neighbouring limb) do not pull the cone in
    // Where the bone has enough body vertices (clothness < 0.5), they are the proxy's surface;
    // only a bone hidden under cloth is fitted to its cloth vertices moved in by σ.
    int body_count = 0;
    for (Eigen::Index i = 0; i < n; ++i)
      body_count += nearest[std::size_t(i)] == b && cloth(i) < 0.5 && tpar[std::size_t(i)] >= kSideLo && tpar[std::size_t(i)] <= kSideHi;
    const bool body_only = body_count >= o.min_vertices;
    std::vector<double> ts, rs, ws;
    for (Eigen::Index i = 0; i < n; ++i) {
      if (nearest[std::size_t(i)] != b) continue;
      const double t = tpar[std::size_t(i)];
      if (t < kSideLo || t > kSideHi) continue;
      if (body_only && cloth(i) >= 0.5) continue;
      ts.push_back(t);
      rs.push_back(std::max(0.0, rad[std::size_t(i)] - sigma(i)));
      ws.push_back(1.0 / (sigma(i) + eps));
    }
    const int count = int(ts.size());
    if (count < o.min_vertices) continue;
    std::vector<double> robust(ts.size(), 1.0);
    Eigen::Vector2d coef = Eigen::Vector2d::Zero();
    for (int iter = 0; iter < 8; ++iter) {
      Eigen::Matrix2d A = Eigen::Matrix2d::Zero();
      Eigen::Vector2d rhs = Eigen::Vector2d::Zero();
      for (std::size_t q = 0; q < ts.size(); ++q) {
        const Eigen::Vector2d x(1.0, ts[q]);
        A += ws[q] * robust[q] * x * x.transpose();
        rhs += ws[q] * robust[q] * rs[q] * x;
      }
      coef = A.ldlt().solve(rhs);
      std::vector<double> res(ts.size());
      for (std::size_t q = 0; q < ts.size(); ++q) res[q] = std::abs(rs[q] - coef(0) - coef(1) * ts[q]);
      std::vector<double> sorted = res;
      std::nth_element(sorted.begin(), sorted.begin() + std::ptrdiff_t(sorted.size() / 2), sorted.end());
      const double scale = std::max(1.4826 * sorted[sorted.size() / 2], 1e-4 * diag);
      for (std::size_t q = 0; q < ts.size(); ++q) {
        const double u = res[q] / (4.685 * scale);
        robust[q] = u < 1 ? (1 - u * u) * (1 - u * u) : 0.0;
      }
    }
    CollisionProxy p;
    p.bone = bones[std::size_t(b)];
    p.cone.a = skeleton.restPosition(p.bone.joint);
    p.cone.b = skeleton.restPosition(p.bone.child);
    p.cone.ra = std::max(0.0, coef(0));
    p.cone.rb = std::max(0.0, coef(0) + coef(1));
    p.vertices = count;
    out.push_back(p);
    out_bone.push_back(b);
  }

  if (o.symmetrize) {
    // radii at shared joints: the end of a parent bone and the start of its child bones
    std::map<int, std::vector<double*>> at_joint;
    for (auto& p : out) {
      at_joint[p.bone.joint].push_back(&p.cone.ra);
      at_joint[p.bone.child].push_back(&p.cone.rb);
    }
    for (auto& [j, rs] : at_joint) {
      if (rs.size() < 2) continue;
      // a joint with several children (hips): average only the end of the incoming bone with each
      // outgoing start, not all outgoing starts together
      double sum = 0;
      for (double* r : rs) sum += *r;
      const double mean = sum / double(rs.size());
      if (rs.size() == 2)
        for (double* r : rs) *r = mean;
    }
    // left / right pairs
    for (std::size_t i = 0; i < out.size(); ++i) {
      const std::string m = mirror_name(skeleton.names[std::size_t(out[i].bone.joint)]);
      if (m.empty()) continue;
      const std::string mc = mirror_name(skeleton.names[std::size_t(out[i].bone.child)]);
      for (std::size_t k = i + 1; k < out.size(); ++k) {
        if (skeleton.names[std::size_t(out[k].bone.joint)] != m) continue;
        if (!mc.empty() && skeleton.names[std::size_t(out[k].bone.child)] != mc) continue;
        const double ra = 0.5 * (out[i].cone.ra + out[k].cone.ra), rb = 0.5 * (out[i].cone.rb + out[k].cone.rb);
        out[i].cone.ra = out[k].cone.ra = ra;
        out[i].cone.rb = out[k].cone.rb = rb;
      }
    }
  }

  // keep inside (in the 1-D model of the fit): no body vertex of the bone that projects onto its
  // side may lie deeper than allowed inside the cone radius at its t; the caps reach
  // past the joints by design and are not tested
  for (std::size_t k = 0; k < out.size(); ++k) {
    auto& p = out[k];
    const int b = out_bone[k];
    // shrink the end nearer each violating vertex until 99 % of the body vertices are within
    // the allowed depth (at most 50 rounds)
    std::vector<std::pair<double, double>> body;  // (t, r)
    for (Eigen::Index i = 0; i < n; ++i) {
      const double t = tpar[std::size_t(i)];
      if (nearest[std::size_t(i)] != b || cloth(i) >= 0.5 || t < kSideLo || t > kSideHi) continue;
      body.emplace_back(t, rad[std::size_t(i)]);
    }
    double worst = 0;
    for (int round = 0; round < 50 && !body.empty(); ++round) {
      const double allowed = o.max_penetration * 0.5 * (p.cone.ra + p.cone.rb);
      std::vector<std::pair<double, double>> excess;  // (depth − allowed, t)
      for (const auto& [t, r] : body) excess.emplace_back(p.cone.ra + (p.cone.rb - p.cone.ra) * t - r - allowed, t);
      std::sort(excess.begin(), excess.end());
      worst = std::max(0.0, excess.back().first + allowed);
      const auto& [need, t] = excess[std::size_t(0.99 * double(excess.size() - 1))];
      if (need <= 1e-12 * diag) break;
      if (t < 0.5) p.cone.ra = std::max(0.0, p.cone.ra - need / (1 - t));
      else p.cone.rb = std::max(0.0, p.cone.rb - need / t);
    }
    p.penetration = std::max(0.0, worst);
  }
  return out;
}

}  // namespace tbsp
