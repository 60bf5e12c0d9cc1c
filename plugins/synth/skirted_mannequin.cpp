#include "tbsp/plugins/skirted_mannequin.h"

#include "tbsp/cloth/animatable_model.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <string>

#include "tbsp/core/error.h"
#include "tbsp/io/bvh_skeleton.h"
#include "tbsp/mesh/primitives.h"

namespace tbsp::synth {

namespace {

std::string lower(std::string s) {
  for (auto& c : s) c = char(std::tolower(static_cast<unsigned char>(c)));
  return s;
}
bool has(const std::string& s, const char* k) { return s.find(k) != std::string::npos; }

// Radii (start, end) of the tube of the bone joint -> child; (0, 0) = no tube.
std::pair<double, double> limb_radii(const std::string& joint_in, const std::string& child_in) {
  const std::string j = lower(joint_in), c = lower(child_in);
  if (has(c, "eye") || has(c, "thumb") || has(c, "index") || has(c, "mid") || has(c, "ring") || has(c, "pinky") ||
      has(c, "_end") || has(j, "hand") || has(j, "head"))
    return {0, 0};
  if (has(j, "thigh") || has(j, "upleg")) return {0.075, 0.052};
  if (has(j, "shin") || (has(j, "leg") && !has(j, "up"))) return {0.05, 0.04};
  if (has(j, "foot")) return {0, 0};
  if (has(j, "buttock")) return {0.075, 0.075};
  if (has(c, "buttock") || has(c, "upleg")) return {0.07, 0.075};
  if (has(j, "hip") || has(j, "abdomen") || has(j, "spine")) return {0.12, 0.12};
  if (has(j, "chest") && has(c, "neck")) return {0.12, 0.06};
  if (has(j, "chest") && has(c, "collar")) return {0.06, 0.05};
  if (has(j, "neck")) return {0.05, 0.05};
  if (has(j, "collar") || (has(j, "shoulder") && !has(c, "arm"))) return {0.05, 0.045};
  if (has(j, "shldr") || (has(j, "arm") && !has(j, "fore"))) return {0.045, 0.038};
  if (has(j, "forearm")) return {0.035, 0.03};
  return {0, 0};
}

void append(TriMesh& out, const TriMesh& part) {
  const Eigen::Index v0 = out.V.rows(), f0 = out.F.rows();
  out.V.conservativeResize(v0 + part.V.rows(), 3);
  out.F.conservativeResize(f0 + part.F.rows(), 3);
  out.V.bottomRows(part.V.rows()) = part.V;
  out.F.bottomRows(part.F.rows()) = part.F.array() + int(v0);
}

// Inside the tapered tube of limb l (flat caps), by more than 1e-4 m?
bool inside_tube(const Eigen::Vector3d& p, const CollisionProxy& l) {
  const Eigen::Vector3d ab = l.cone.b - l.cone.a;
  const double t = (p - l.cone.a).dot(ab) / ab.squaredNorm();
  if (t <= 0 || t >= 1) return false;
  const double r = (p - (l.cone.a + t * ab)).norm();
  return r < l.cone.ra + (l.cone.rb - l.cone.ra) * t - 1e-4;
}

// The union of the tubes as a scanner would see it: faces with a corner inside another tube are
// removed, with the vertices left unused; the seams stay open by up to one ring of faces.
void remove_interior(TriMesh& mesh, std::vector<std::pair<int, int>>& owner, const std::vector<CollisionProxy>& limbs) {
  const Eigen::Index n = mesh.V.rows();
  std::vector<char> inside(std::size_t(n), 0);
  for (Eigen::Index i = 0; i < n; ++i)
    for (std::size_t l = 0; l < limbs.size() && !inside[std::size_t(i)]; ++l)
      if (int(l) != owner[std::size_t(i)].second && inside_tube(mesh.V.row(i).transpose(), limbs[l])) inside[std::size_t(i)] = 1;
  std::vector<int> keep_face;
  for (Eigen::Index f = 0; f < mesh.F.rows(); ++f)
    if (!(inside[std::size_t(mesh.F(f, 0))] || inside[std::size_t(mesh.F(f, 1))] || inside[std::size_t(mesh.F(f, 2))])) keep_face.push_back(int(f));
  std::vector<int> remap(std::size_t(n), -1);
  int next = 0;
  for (int f : keep_face)
    for (int k = 0; k < 3; ++k)
      if (remap[std::size_t(mesh.F(f, k))] < 0) remap[std::size_t(mesh.F(f, k))] = 0;
  std::vector<std::pair<int, int>> owner2;
  Eigen::MatrixX3d V(n, 3);
  for (Eigen::Index i = 0; i < n; ++i)
    if (remap[std::size_t(i)] == 0) {
      remap[std::size_t(i)] = next;
      V.row(next++) = mesh.V.row(i);
      owner2.push_back(owner[std::size_t(i)]);
    }
  Eigen::MatrixX3i F(Eigen::Index(keep_face.size()), 3);
  for (std::size_t q = 0; q < keep_face.size(); ++q)
    for (int k = 0; k < 3; ++k) F(Eigen::Index(q), k) = remap[std::size_t(mesh.F(keep_face[q], k))];
  mesh.V = V.topRows(next);
  mesh.F = F;
  owner = owner2;
}

}  // namespace

SkirtedMannequin make_skirted_mannequin(const Skeleton& s, const MannequinOptions& o) {
  validate_skeleton(s, "tbsp::synth::make_skirted_mannequin");
  if (o.tube_segments < 6 || !(o.tube_ring_spacing > 0) || o.skirt_rings < 4 || o.skirt_segments < 8 || !(o.skirt_length > 0) ||
      !(o.waist_radius > 0) || !(o.hem_radius > 0))
    throw InvalidInput("[tbsp::synth::make_skirted_mannequin] options out of range");
  SkirtedMannequin m;
  std::vector<std::pair<int, int>> owner;  // per vertex: joint (rigid weight)
  for (const Bone& b : skeleton_bones(s)) {
    const auto [ra, rb] = limb_radii(s.names[std::size_t(b.joint)], s.names[std::size_t(b.child)]);
    if (ra <= 0) continue;
    const Eigen::Vector3d a = s.restPosition(b.joint), c = s.restPosition(b.child);
    const double len = (c - a).norm();
    const int rings = std::max(2, int(std::round(len / o.tube_ring_spacing)) + 1);
    TriMesh tube = make_tube(rings, o.tube_segments, len, 1.0);
    for (Eigen::Index i = 0; i < tube.V.rows(); ++i) {
      const double r = ra + (rb - ra) * tube.V(i, 0) / len;
      tube.V(i, 1) *= r;
      tube.V(i, 2) *= r;
    }
    const Eigen::Quaterniond q = Eigen::Quaterniond::FromTwoVectors(Eigen::Vector3d::UnitX(), (c - a) / len);
    for (Eigen::Index i = 0; i < tube.V.rows(); ++i) tube.V.row(i) = (q * tube.V.row(i).transpose() + a).transpose();
    append(m.mesh, tube);
    for (Eigen::Index i = 0; i < tube.V.rows(); ++i) owner.emplace_back(b.joint, int(m.limbs.size()));
    CollisionProxy p;
    p.bone = b;
    p.cone = RoundCone{a, c, ra, rb};
    p.vertices = int(tube.V.rows());
    m.limbs.push_back(p);
  }
  if (m.limbs.empty())
    throw InvalidInput("[tbsp::synth::make_skirted_mannequin] no bone of the skeleton has a known limb name (thigh, shin, abdomen, ...)");
  remove_interior(m.mesh, owner, m.limbs);
  // the skirt: an open flared tube around the root joint
  int root = 0;
  while (root < s.numJoints() && s.parents[std::size_t(root)] >= 0) ++root;
  const Eigen::Vector3d centre = s.restPosition(root);
  m.skirt_begin = m.mesh.V.rows();
  TriMesh skirt;
  skirt.V.resize(o.skirt_rings * o.skirt_segments, 3);
  for (int r = 0; r < o.skirt_rings; ++r) {
    const double t = double(r) / (o.skirt_rings - 1);
    const double radius = o.waist_radius + (o.hem_radius - o.waist_radius) * t;
    for (int k = 0; k < o.skirt_segments; ++k) {
      const double a = 2 * M_PI * k / o.skirt_segments;
      skirt.V.row(r * o.skirt_segments + k) =
          (centre + Eigen::Vector3d(radius * std::cos(a), o.skirt_top - o.skirt_length * t, radius * std::sin(a))).transpose();
    }
  }
  skirt.F.resize(2 * (o.skirt_rings - 1) * o.skirt_segments, 3);
  int f = 0;
  for (int r = 0; r + 1 < o.skirt_rings; ++r)
    for (int k = 0; k < o.skirt_segments; ++k) {
      const int a = r * o.skirt_segments + k, b = r * o.skirt_segments + (k + 1) % o.skirt_segments;
      skirt.F.row(f++) << a, b + o.skirt_segments, a + o.skirt_segments;  // outward normals
      skirt.F.row(f++) << a, b, b + o.skirt_segments;
    }
  append(m.mesh, skirt);
  const Eigen::Index n = m.mesh.V.rows();
  m.cloth = Eigen::VectorXi::Zero(n);
  m.clothness = Eigen::VectorXd::Zero(n);
  std::vector<Eigen::Triplet<double>> w;
  for (Eigen::Index i = 0; i < m.skirt_begin; ++i) w.emplace_back(int(i), owner[std::size_t(i)].first, 1.0);
  for (Eigen::Index i = m.skirt_begin; i < n; ++i) {
    const int ring = int((i - m.skirt_begin) / o.skirt_segments);
    m.clothness(i) = ring == 0 ? 0.0 : ring == 1 ? 0.5 : 1.0;
    m.cloth(i) = ring >= 2;
    w.emplace_back(int(i), root, 1.0);
  }
  m.weights = SkinningWeights(n, s.numJoints());
  m.weights.setFromTriplets(w.begin(), w.end());
  return m;
}

AnimatableModel generating_model(const SkirtedMannequin& m, const Skeleton& skeleton, const ClothMaterial& material, const PbdSettings& settings) {
  AnimatableModel gen;
  gen.mesh = m.mesh;
  gen.skeleton = skeleton;
  gen.weights = m.weights;
  gen.clothness = m.clothness;
  gen.proxies = m.limbs;
  gen.materials = {material};
  gen.settings = settings;
  gen.validate("tbsp::synth::generating_model");
  return gen;
}

void simulate_skirt_sequence(const SkirtedMannequin& m, const Skeleton& s, const BvhMotion& clip, const SkirtSequenceOptions& o,
                             const std::function<void(int, const Eigen::MatrixX3d&)>& frame) {
  const std::string w = "[tbsp::synth::simulate_skirt_sequence] ";
  if (o.frames < 1 || o.bvh_step < 1 || o.first_bvh_frame < 0 || o.settle_frames < 0)
    throw InvalidInput(w + "frames and bvh_step must be ≥ 1, first_bvh_frame and settle_frames ≥ 0");
  const int last = o.first_bvh_frame + (o.frames - 1) * o.bvh_step;
  if (last >= clip.numFrames())
    throw InvalidInput(w + "the clip has " + std::to_string(clip.numFrames()) + " frames; " + std::to_string(o.frames) + " frames every " +
                       std::to_string(o.bvh_step) + " from " + std::to_string(o.first_bvh_frame) + " need " + std::to_string(last + 1));
  require_bvh_joints(clip, s.names, "simulate_skirt_sequence");
  if (int(clip.joints.size()) != s.numJoints())
    throw InvalidInput(w + "the clip has " + std::to_string(clip.joints.size()) + " joints, the skeleton " + std::to_string(s.numJoints()));
  // The generating model: rigid weights, the true clothness, the limb tubes as proxies, the true
  // material. Animated exactly as an AnimatableModel is (ModelAnimator), so the material
  // estimation's truth is defined by the same simulation it searches with.
  PbdSettings st = o.settings;
  st.time_step = o.bvh_step * clip.frame_time;
  const AnimatableModel gen = generating_model(m, s, o.material, st);
  ModelAnimator anim(gen);
  for (int f = 0; f < o.frames; ++f) {
    const SkeletonPose pose = bvh_pose(clip, o.first_bvh_frame + f * o.bvh_step, o.bvh_scale);
    frame(f, f == 0 ? anim.start(pose, o.settle_frames) : anim.step(pose));
  }
}

}  // namespace tbsp::synth
