#include "tbsp/plugins/synthetic_scan.h"

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <numeric>
#include <random>
#include <spdlog/fmt/fmt.h>
#include <string>

#include "tbsp/core/error.h"
#include "tbsp/mesh/point_mesh_distance.h"
#include "tbsp/mesh/point_search.h"

namespace tbsp::synth {

namespace {
struct Frame {
  Eigen::Vector3d c, axis, perp, third;
  double length;
};
Frame principal_frame(const Eigen::MatrixX3d& V) {
  Frame f;
  f.c = V.colwise().mean().transpose();
  const Eigen::MatrixX3d X = V.rowwise() - f.c.transpose();
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(X.transpose() * X);
  f.axis = es.eigenvectors().col(2);
  f.perp = es.eigenvectors().col(1);
  f.third = es.eigenvectors().col(0);
  const Eigen::VectorXd s = X * f.axis;
  f.length = s.maxCoeff() - s.minCoeff();
  return f;
}
}  // namespace

Eigen::MatrixX3d bend_twist_scale(const Eigen::MatrixX3d& V, const ScenarioOptions& o) {
  const Frame f = principal_frame(V);
  const double diag = bbox_diagonal(V);
  const Eigen::Vector3d bend_axis = f.axis.cross(f.perp).normalized();
  Eigen::MatrixX3d out(V.rows(), 3);
  for (Eigen::Index i = 0; i < V.rows(); ++i) {
    const Eigen::Vector3d u = V.row(i).transpose() - f.c;
    const double t = u.dot(f.axis) / f.length;  // about -0.5 .. 0.5
    const Eigen::Matrix3d R = (Eigen::AngleAxisd(o.bend_deg * M_PI / 180 * t, bend_axis) *
                               Eigen::AngleAxisd(o.twist_deg * M_PI / 180 * t, f.axis))
                                  .toRotationMatrix();
    out.row(i) = (o.scale * (R * u) + f.c + o.translation * diag).transpose();
  }
  return out;
}

namespace {
// Blend weight (smoothstep across ±falloff of the joint's plane) of every vertex of the rest
// shape; with a seed, zero outside the part connected to the seed through vertices of weight > 0.
Eigen::VectorXd joint_weights(const Eigen::MatrixX3d& V, const Eigen::MatrixX3i& F, const Joint& J) {
  const double w = std::max(J.falloff, 1e-12);
  Eigen::VectorXd s(V.rows());
  for (Eigen::Index i = 0; i < V.rows(); ++i) {
    const double t = std::clamp(((V.row(i).transpose() - J.centre).dot(J.side.normalized()) / w + 1) / 2, 0.0, 1.0);
    s(i) = t * t * (3 - 2 * t);
  }
  if (!J.seed.allFinite()) return s;
  if (F.rows() == 0) throw InvalidInput("synth::articulate: a joint with a seed needs the faces (articulate(V, F, joints))");
  Eigen::Index start = -1;
  double best = 1e300;
  for (Eigen::Index i = 0; i < V.rows(); ++i)
    if (s(i) > 0 && (V.row(i).transpose() - J.seed).squaredNorm() < best) { best = (V.row(i).transpose() - J.seed).squaredNorm(); start = i; }
  if (start < 0) throw InvalidInput("synth::articulate: no vertex on the turning side of a joint with a seed");
  std::vector<std::vector<int>> adj(std::size_t(V.rows()));
  for (Eigen::Index f = 0; f < F.rows(); ++f)
    for (int k = 0; k < 3; ++k) {
      const int a = F(f, k), b = F(f, (k + 1) % 3);
      if (s(a) > 0 && s(b) > 0) { adj[std::size_t(a)].push_back(b); adj[std::size_t(b)].push_back(a); }
    }
  std::vector<char> reached(std::size_t(V.rows()), 0);
  std::vector<int> stack{int(start)};
  reached[std::size_t(start)] = 1;
  while (!stack.empty()) {
    const int v = stack.back();
    stack.pop_back();
    for (int u : adj[std::size_t(v)])
      if (!reached[std::size_t(u)]) { reached[std::size_t(u)] = 1; stack.push_back(u); }
  }
  for (Eigen::Index i = 0; i < V.rows(); ++i)
    if (!reached[std::size_t(i)]) s(i) = 0;
  return s;
}
}  // namespace

Eigen::MatrixX3d articulate(const Eigen::MatrixX3d& V, const std::vector<Joint>& joints) {
  return articulate(V, Eigen::MatrixX3i(), joints);
}

Eigen::MatrixX3d articulate(const Eigen::MatrixX3d& V, const Eigen::MatrixX3i& F, const std::vector<Joint>& joints) {
  Eigen::MatrixX3d out = V;
  // each joint's frame moves with the joints before it: track its centre through them
  std::vector<Eigen::Vector3d> centre(joints.size()), axis(joints.size()), side(joints.size());
  for (std::size_t j = 0; j < joints.size(); ++j) {
    centre[j] = joints[j].centre;
    axis[j] = joints[j].axis.normalized();
    side[j] = joints[j].side.normalized();
  }
  for (std::size_t j = 0; j < joints.size(); ++j) {
    const Joint& J = joints[j];
    // which side of the joint: measured on the rest shape, so parts keep their membership
    const Eigen::VectorXd s = joint_weights(V, F, J);
    for (Eigen::Index i = 0; i < V.rows(); ++i) {
      if (s(i) == 0) continue;
      const Eigen::Matrix3d R = Eigen::AngleAxisd(s(i) * J.angle_deg * M_PI / 180, axis[j]).toRotationMatrix();
      out.row(i) = (centre[j] + R * (out.row(i).transpose() - centre[j])).transpose();
    }
    // later joints on this one's side follow it
    const Eigen::Matrix3d R = Eigen::AngleAxisd(J.angle_deg * M_PI / 180, axis[j]).toRotationMatrix();
    for (std::size_t k = j + 1; k < joints.size(); ++k)
      if ((joints[k].centre - J.centre).dot(J.side.normalized()) > 0) {
        centre[k] = centre[j] + R * (centre[k] - centre[j]);
        axis[k] = R * axis[k];
        side[k] = R * side[k];
      }
  }
  return out;
}

std::vector<Joint> bunny_head_and_ears(double angle_deg) {
  Joint head;  // the neck: everything in front of and above it (head, ears)
  head.centre = Eigen::Vector3d(-0.045, 0.105, -0.02);
  head.side = Eigen::Vector3d(-1, 1, 0).normalized();
  head.axis = Eigen::Vector3d::UnitZ();
  head.falloff = 0.035;  // narrower blends fold the neck's inner side through itself at 30-45 deg
  head.angle_deg = angle_deg;
  Joint ears;  // the base of the ears
  ears.centre = Eigen::Vector3d(-0.045, 0.148, -0.03);
  ears.side = Eigen::Vector3d::UnitY();
  ears.axis = Eigen::Vector3d::UnitZ();
  ears.falloff = 0.01;
  ears.angle_deg = -angle_deg;  // tilted back: forwards they fold into the head at 45 deg
  return {head, ears};
}

namespace {
Joint joint(Eigen::Vector3d centre, Eigen::Vector3d side, Eigen::Vector3d axis, double falloff, double angle_deg, Eigen::Vector3d seed) {
  Joint J;
  J.centre = centre;
  J.side = side;
  J.axis = axis;
  J.falloff = falloff;
  J.angle_deg = angle_deg;
  J.seed = seed;
  return J;
}
}  // namespace

std::vector<Joint> armadillo_limbs(double a) {
  const Eigen::Vector3d X = Eigen::Vector3d::UnitX(), Y = Eigen::Vector3d::UnitY(), Z = Eigen::Vector3d::UnitZ();
  return {joint({0.27, 0.18, 0.10}, X, Z, 0.05, a, {0.36, 0.24, 0.23}),        // right forearm raised
          joint({-0.27, 0.16, 0.035}, -X, Z, 0.05, a, {-0.37, 0.24, 0.145}),   // left forearm lowered
          joint({-0.18, -0.36, -0.07}, -Y, X, 0.06, -a, {-0.17, -0.56, 0.0})};  // left knee straightens
}

std::vector<Joint> human_limbs(double a) {
  const Eigen::Vector3d X = Eigen::Vector3d::UnitX(), Y = Eigen::Vector3d::UnitY(), Z = Eigen::Vector3d::UnitZ();
  return {joint({0.22, 1.43, -0.04}, X, Z, 0.04, -a, {0.85, 1.42, -0.03}),     // left arm lowered
          joint({-0.22, 1.43, -0.04}, -X, Z, 0.04, -a, {-0.85, 1.42, -0.03}),  // right arm raised
          joint({0.0, 1.55, 0.0}, Y, X, 0.04, a, {0.0, 1.75, 0.0}),            // head nods
          joint({-0.1, 0.47, -0.01}, -Y, X, 0.04, a, {-0.12, 0.03, 0.05})};    // right knee bends
}

namespace {

// Options a scenario cannot be made from: an InvalidInput naming the option, its value and the
// range (the CLI's synth-scan passes them straight through).
void check_scenario_options(const ScenarioOptions& o) {
  const std::string who = "synth::make_scenario: ";
  auto bad = [&](const std::string& what, double v, const std::string& range) {
    throw InvalidInput(fmt::format("{}{} = {} is out of range; use {}", who, what, v, range));  // 1e+300, not 300 digits
  };
  if (o.hole_axis < 0 || o.hole_axis > 2)
    throw InvalidInput(who + "hole_axis " + std::to_string(o.hole_axis) + " is not 0, 1 or 2 (a principal axis)");
  if (o.points < 1 || o.points > 50000000) bad("points", o.points, "1..50,000,000");
  if (!(o.outliers >= 0 && o.outliers < 1)) bad("outliers", o.outliers, "a fraction in [0, 1)");
  if (!(o.hole >= 0 && o.hole < 1)) bad("hole", o.hole, "a fraction of the surface in [0, 1)");
  if (!(o.noise >= 0 && o.noise <= 1)) bad("noise", o.noise, "a fraction of the bbox diagonal in [0, 1]");
  if (!(o.scale > 0 && std::isfinite(o.scale))) bad("scale", o.scale, "a finite factor > 0");
  if (!std::isfinite(o.bend_deg)) bad("bend", o.bend_deg, "a finite angle in degrees");
  if (!std::isfinite(o.twist_deg)) bad("twist", o.twist_deg, "a finite angle in degrees");
  if (!o.translation.allFinite()) throw InvalidInput(who + "translation is not finite");
  if (!(o.fragment_offset >= 0 && std::isfinite(o.fragment_offset))) bad("fragment_offset", o.fragment_offset, "a finite value >= 0");
  if (o.markers < 0) bad("markers", o.markers, "a count >= 0");
}

}  // namespace

Scenario make_scenario(const TriMesh& templ, const ScenarioOptions& o) {
  check_scenario_options(o);
  if (templ.F.rows() == 0) throw InvalidInput("synth::make_scenario: the mesh has no faces; a scan is sampled from its surface");
  Scenario s;
  s.templ = templ;
  s.target = bend_twist_scale(o.joints.empty() ? templ.V : articulate(templ.V, templ.F, o.joints), o);
  s.diag = bbox_diagonal(s.target);
  std::mt19937 rng(o.seed);
  const Eigen::MatrixX3i& F = templ.F;
  // hole: faces whose rest centroid lies beyond a plane along the second principal axis
  const Frame fr = principal_frame(templ.V);
  Eigen::VectorXd key(F.rows()), area(F.rows());
  for (Eigen::Index f = 0; f < F.rows(); ++f) {
    const Eigen::Vector3d c = (templ.V.row(F(f, 0)) + templ.V.row(F(f, 1)) + templ.V.row(F(f, 2))).transpose() / 3.0;
    key(f) = (c - fr.c).dot(o.hole_axis == 0 ? fr.axis : o.hole_axis == 2 ? fr.third : fr.perp);
    const Eigen::Vector3d a = s.target.row(F(f, 0)), b = s.target.row(F(f, 1)), d = s.target.row(F(f, 2));
    area(f) = 0.5 * (b - a).cross(d - a).norm();
  }
  std::vector<Eigen::Index> order(std::size_t(F.rows()));
  std::iota(order.begin(), order.end(), 0);
  std::sort(order.begin(), order.end(), [&](Eigen::Index a, Eigen::Index b) { return key(a) > key(b); });
  std::vector<char> hole_face(std::size_t(F.rows()), 0);
  const double total = area.sum();
  double removed = 0;
  for (Eigen::Index f : order) {
    if (removed >= o.hole * total) break;
    hole_face[std::size_t(f)] = 1;
    removed += area(f);
  }
  if (!(total > 0))
    throw InvalidInput("synth::make_scenario: the deformed mesh has no surface area (every face degenerate, or NaN "
                       "coordinates); check the mesh with tbsp validate");
  s.hole_area_fraction = removed / total;
  s.hole_vertex.assign(std::size_t(templ.V.rows()), 1);
  std::vector<char> touched(std::size_t(templ.V.rows()), 0);
  for (Eigen::Index f = 0; f < F.rows(); ++f)
    for (int k = 0; k < 3; ++k) {
      touched[std::size_t(F(f, k))] = 1;
      if (!hole_face[std::size_t(f)]) s.hole_vertex[std::size_t(F(f, k))] = 0;
    }
  for (std::size_t v = 0; v < touched.size(); ++v)
    if (!touched[v]) s.hole_vertex[v] = 0;
  // area-weighted samples on the kept part of the target
  std::vector<double> cdf;
  std::vector<Eigen::Index> faces;
  double acc = 0;
  for (Eigen::Index f = 0; f < F.rows(); ++f)
    if (!hole_face[std::size_t(f)]) { acc += area(f); cdf.push_back(acc); faces.push_back(f); }
  if (!(acc > 0))
    throw InvalidInput("synth::make_scenario: the hole (" + std::to_string(o.hole) +
                       ") leaves no surface to sample; make it smaller");
  const int n_out = int(std::lround(o.points * o.outliers));
  const int n_in = o.points - n_out;
  if (n_in < 1)
    throw InvalidInput("synth::make_scenario: " + std::to_string(o.points) + " points with outliers " + std::to_string(o.outliers) +
                       " leave no inlier; raise points or lower outliers");
  std::uniform_real_distribution<double> uni(0, 1);
  std::normal_distribution<double> gauss(0, o.noise * s.diag);
  Eigen::MatrixX3d P(o.points, 3), N(o.points, 3), C(o.points, 3);
  std::vector<char> inl(std::size_t(o.points), 0);
  const Eigen::Vector3d lo = s.target.colwise().minCoeff().transpose(), hi = s.target.colwise().maxCoeff().transpose();
  const Eigen::Vector3d split_dir = fr.axis;
  for (int i = 0; i < n_in; ++i) {
    const double r = uni(rng) * acc;
    const Eigen::Index f = faces[std::size_t(std::lower_bound(cdf.begin(), cdf.end(), r) - cdf.begin())];
    double a = uni(rng), b = uni(rng);
    if (a + b > 1) { a = 1 - a; b = 1 - b; }
    const Eigen::Vector3d p0 = s.target.row(F(f, 0)), p1 = s.target.row(F(f, 1)), p2 = s.target.row(F(f, 2));
    const Eigen::Vector3d p = p0 + a * (p1 - p0) + b * (p2 - p0);
    Eigen::Vector3d q = p + Eigen::Vector3d(gauss(rng), gauss(rng), gauss(rng));
    if (o.fragment_offset > 0 && (p - 0.5 * (lo + hi)).dot(split_dir) > 0) q += o.fragment_offset * s.diag * Eigen::Vector3d(1, 1, 1).normalized();
    P.row(i) = q.transpose();
    N.row(i) = (p1 - p0).cross(p2 - p0).normalized().transpose();
    C.row(i) = p.transpose();
    inl[std::size_t(i)] = 1;
  }
  for (int i = n_in; i < o.points; ++i) {
    const Eigen::Vector3d ext = 0.1 * (hi - lo);
    Eigen::Vector3d q;
    for (int d = 0; d < 3; ++d) q(d) = lo(d) - ext(d) + uni(rng) * (hi(d) - lo(d) + 2 * ext(d));
    P.row(i) = q.transpose();
    N.row(i) = Eigen::Vector3d(gauss(rng), gauss(rng), gauss(rng)).normalized().transpose();
    C.row(i).setConstant(std::numeric_limits<double>::quiet_NaN());
  }
  // deterministic shuffle
  std::vector<int> perm(std::size_t(o.points));
  std::iota(perm.begin(), perm.end(), 0);
  std::shuffle(perm.begin(), perm.end(), rng);
  s.P.resize(o.points, 3); s.N.resize(o.points, 3); s.clean.resize(o.points, 3);
  s.inlier.resize(std::size_t(o.points));
  for (int i = 0; i < o.points; ++i) {
    s.P.row(i) = P.row(perm[std::size_t(i)]);
    s.N.row(i) = N.row(perm[std::size_t(i)]);
    s.clean.row(i) = C.row(perm[std::size_t(i)]);
    s.inlier[std::size_t(i)] = inl[std::size_t(perm[std::size_t(i)])];
  }
  // markers: farthest points on the template outside the hole, each tied to the nearest inlier
  Eigen::MatrixX3d inP(n_in, 3);
  std::vector<Eigen::Index> in_idx;
  for (int i = 0; i < o.points; ++i)
    if (s.inlier[std::size_t(i)]) { inP.row(Eigen::Index(in_idx.size())) = s.P.row(i); in_idx.push_back(i); }
  const PointSearch tree(inP);
  std::vector<int> chosen;
  Eigen::Index eligible = 0;  // template vertices on a face, outside the hole
  for (Eigen::Index v = 0; v < templ.V.rows(); ++v) eligible += !s.hole_vertex[std::size_t(v)] && touched[std::size_t(v)];
  if (o.markers > eligible)
    throw InvalidInput("synth::make_scenario: " + std::to_string(o.markers) + " markers asked for, but only " +
                       std::to_string(eligible) + " template vertices lie outside the hole; ask for fewer");
  Eigen::VectorXd d = Eigen::VectorXd::Constant(templ.V.rows(), 1e300);
  int start = 0;
  while (s.hole_vertex[std::size_t(start)] || !touched[std::size_t(start)]) ++start;
  if (o.markers > 0) chosen.push_back(start);
  while (int(chosen.size()) < o.markers) {
    d = d.cwiseMin((templ.V.rowwise() - templ.V.row(chosen.back())).rowwise().norm());
    Eigen::Index best = -1;
    for (Eigen::Index v = 0; v < templ.V.rows(); ++v)
      if (!s.hole_vertex[std::size_t(v)] && !touched.empty() && touched[std::size_t(v)] && (best < 0 || d(v) > d(best))) best = v;
    chosen.push_back(int(best));
  }
  for (int v : chosen) {
    FitMarker m;
    m.template_vertex = v;
    m.cloud_index = in_idx[std::size_t(tree.nearest(s.target.row(v).transpose()))];
    s.markers.push_back(m);
  }
  return s;
}

void turn_scenario(Scenario& s, double deg) {
  const Eigen::Matrix3d R = Eigen::AngleAxisd(deg * M_PI / 180, Eigen::Vector3d(1, 2, 0.5).normalized()).toRotationMatrix();
  const Eigen::RowVector3d c = s.target.colwise().mean();
  auto turn = [&](Eigen::MatrixX3d& X, bool about_centre) {
    for (Eigen::Index i = 0; i < X.rows(); ++i) {
      if (!X.row(i).allFinite()) continue;  // (clean rows of outliers are NaN)
      const Eigen::RowVector3d x = X.row(i);
      X.row(i) = about_centre ? Eigen::RowVector3d((x - c) * R.transpose() + c) : Eigen::RowVector3d(x * R.transpose());
    }
  };
  turn(s.target, true);
  turn(s.P, true);
  turn(s.clean, true);
  turn(s.N, false);
  for (auto& m : s.markers)
    if (m.cloud_index < 0) m.position = R * (m.position - c.transpose()) + c.transpose();
}

ScenarioErrors evaluate(const Scenario& s, const TriMesh& fit) {
  ScenarioErrors e{};
  const MeshDistance md(fit.V, fit.F);
  std::vector<Eigen::Index> in;
  for (std::size_t i = 0; i < s.inlier.size(); ++i)
    if (s.inlier[i]) in.push_back(Eigen::Index(i));
  Eigen::MatrixX3d C(Eigen::Index(in.size()), 3), Q(Eigen::Index(in.size()), 3);
  for (std::size_t k = 0; k < in.size(); ++k) { C.row(Eigen::Index(k)) = s.clean.row(in[k]); Q.row(Eigen::Index(k)) = s.P.row(in[k]); }
  e.hausdorff_clean_rel = md.distances(C).maxCoeff() / s.diag;
  e.hausdorff_noisy_rel = md.distances(Q).maxCoeff() / s.diag;
  if (fit.V.rows() >= s.target.rows()) {  // remeshing appends vertices; the template's keep their indices
    const Eigen::VectorXd err = (fit.V.topRows(s.target.rows()) - s.target).rowwise().norm();
    double sum = 0;
    int n = 0;
    for (Eigen::Index v = 0; v < err.rows(); ++v)
      if (s.hole_vertex[std::size_t(v)]) { sum += err(v); ++n; }
    e.hole_mean_rel = n ? sum / n / s.diag : 0;
    e.all_mean_rel = err.mean() / s.diag;
  }
  return e;
}

}  // namespace tbsp::synth
