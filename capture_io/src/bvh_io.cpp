// BVH skeletons with motion: read_bvh, write_bvh, forward kinematics.
#include "tbsp/io/mocap_io.h"

#include <cmath>
#include <cstring>
#include <iomanip>
#include <functional>
#include <limits>
#include <map>
#include <sstream>

#include "tbsp/core/error.h"
#include "tbsp/core/logging.h"
#include "tbsp/io/atomic_file.h"
#include "text_buffer.h"

namespace tbsp {
int BvhMotion::numJoints() const {
  int n = 0;
  for (const auto& j : joints) n += !j.end_site;
  return n;
}

std::vector<Eigen::Isometry3d> BvhMotion::globalTransforms(int frame) const {
  if (frame < 0 || frame >= numFrames())
    throw InvalidInput("[tbsp::BvhMotion::globalTransforms] frame " + std::to_string(frame) + " out of range [0, " +
                       std::to_string(numFrames()) + ")");
  std::vector<Eigen::Isometry3d> G(joints.size());
  for (std::size_t i = 0; i < joints.size(); ++i) {
    const BvhJoint& j = joints[i];
    Eigen::Vector3d tr = j.offset;
    Eigen::Matrix3d R = Eigen::Matrix3d::Identity();
    for (std::size_t c = 0; c < j.channels.size(); ++c) {
      const double v = motion(frame, j.first_channel + static_cast<int>(c));
      switch (j.channels[c]) {
        case BvhJoint::Xposition: tr.x() += v; break;
        case BvhJoint::Yposition: tr.y() += v; break;
        case BvhJoint::Zposition: tr.z() += v; break;
        case BvhJoint::Xrotation: R = R * Eigen::AngleAxisd(v * M_PI / 180.0, Eigen::Vector3d::UnitX()).toRotationMatrix(); break;
        case BvhJoint::Yrotation: R = R * Eigen::AngleAxisd(v * M_PI / 180.0, Eigen::Vector3d::UnitY()).toRotationMatrix(); break;
        case BvhJoint::Zrotation: R = R * Eigen::AngleAxisd(v * M_PI / 180.0, Eigen::Vector3d::UnitZ()).toRotationMatrix(); break;
      }
    }
    Eigen::Isometry3d L = Eigen::Isometry3d::Identity();
    L.linear() = R;
    L.translation() = tr;
    G[i] = j.parent >= 0 ? G[static_cast<std::size_t>(j.parent)] * L : L;
  }
  return G;
}

Eigen::MatrixX3d BvhMotion::jointPositions(int frame) const {
  const auto G = globalTransforms(frame);
  Eigen::MatrixX3d P(G.size(), 3);
  for (std::size_t i = 0; i < G.size(); ++i) P.row(static_cast<Eigen::Index>(i)) = G[i].translation().transpose();
  return P;
}

namespace {
void bvh_expect(detail::TextBuffer& tb, std::string_view want) {
  std::string_view t;
  if (!tb.token(t)) tb.fail("file ends where '" + std::string(want) + "' was expected (truncated BVH?)");
  if (t != want) tb.fail("expected '" + std::string(want) + "', found '" + std::string(t) + "'");
}

void bvh_joint(detail::TextBuffer& tb, BvhMotion& m, int parent, bool end_site, std::string name, int depth, int& nch) {
  if (depth > 1000) tb.fail("hierarchy nested deeper than 1000 levels");
  if (m.joints.size() > 100000) tb.fail("more than 100000 joints");
  BvhJoint j;
  j.name = std::move(name);
  j.parent = parent;
  j.end_site = end_site;
  j.first_channel = nch;
  bvh_expect(tb, "{");
  bvh_expect(tb, "OFFSET");
  for (int k = 0; k < 3; ++k) {
    j.offset(k) = tb.readDouble("OFFSET value of '" + j.name + "'");
    if (!std::isfinite(j.offset(k))) tb.fail("OFFSET of '" + j.name + "' is not finite");
  }
  const int me = static_cast<int>(m.joints.size());
  std::string_view t;
  if (!end_site) {
    bvh_expect(tb, "CHANNELS");
    const long long n = tb.readInt("channel count of '" + j.name + "'");
    if (n < 0 || n > 6) tb.fail("joint '" + j.name + "' has " + std::to_string(n) + " channels (0..6 allowed)");
    for (long long c = 0; c < n; ++c) {
      if (!tb.token(t)) tb.fail("file ends inside the CHANNELS of '" + j.name + "'");
      static const std::pair<const char*, BvhJoint::Channel> names[] = {
          {"Xposition", BvhJoint::Xposition}, {"Yposition", BvhJoint::Yposition}, {"Zposition", BvhJoint::Zposition},
          {"Xrotation", BvhJoint::Xrotation}, {"Yrotation", BvhJoint::Yrotation}, {"Zrotation", BvhJoint::Zrotation}};
      bool ok = false;
      for (const auto& [s, ch] : names)
        if (t == s) { j.channels.push_back(ch); ok = true; }
      if (!ok) tb.fail("unknown channel '" + std::string(t) + "' of joint '" + j.name + "' (X/Y/Z position/rotation)");
    }
    nch += static_cast<int>(n);
  }
  m.joints.push_back(j);
  while (true) {
    if (!tb.token(t)) tb.fail("file ends inside joint '" + m.joints[me].name + "' (missing '}')");
    if (t == "}") break;
    if (end_site) tb.fail("unexpected '" + std::string(t) + "' inside an End Site");
    if (t == "JOINT") {
      std::string_view nm;
      if (!tb.token(nm)) tb.fail("JOINT without a name");
      bvh_joint(tb, m, me, false, std::string(nm), depth + 1, nch);
    } else if (t == "End") {
      bvh_expect(tb, "Site");
      bvh_joint(tb, m, me, true, m.joints[me].name + "_End", depth + 1, nch);
    } else {
      tb.fail("expected JOINT, End Site or '}', found '" + std::string(t) + "'");
    }
  }
}
}  // namespace

BvhMotion read_bvh(const std::string& path) {
  auto tb = detail::TextBuffer::load(path);
  BvhMotion m;
  std::string_view t;
  if (!tb.token(t) || t != "HIERARCHY") tb.fail("not a BVH file: it must start with 'HIERARCHY'");
  int nch = 0;
  while (true) {
    if (!tb.token(t)) tb.fail("file ends before MOTION (truncated BVH?)");
    if (t == "MOTION") break;
    if (t != "ROOT") tb.fail("expected ROOT or MOTION, found '" + std::string(t) + "'");
    std::string_view nm;
    if (!tb.token(nm)) tb.fail("ROOT without a name");
    bvh_joint(tb, m, -1, false, std::string(nm), 0, nch);
  }
  if (m.joints.empty()) tb.fail("no ROOT joint before MOTION");
  bvh_expect(tb, "Frames:");
  const long long nframes = tb.readInt("frame count after 'Frames:'");
  if (nframes < 0 || nframes > 10000000) tb.fail("frame count " + std::to_string(nframes) + " is not plausible");
  bvh_expect(tb, "Frame");
  bvh_expect(tb, "Time:");
  m.frame_time = tb.readDouble("frame time after 'Frame Time:'");
  if (!(m.frame_time > 0) || !std::isfinite(m.frame_time)) tb.fail("frame time must be a positive number");
  // Every value needs at least 2 bytes ("0 "): reject absurd counts before allocating.
  if (static_cast<double>(nframes) * std::max(nch, 1) > static_cast<double>(tb.remaining()))
    tb.fail("'Frames: " + std::to_string(nframes) + "' x " + std::to_string(nch) + " channels cannot fit in the remaining " +
            std::to_string(tb.remaining()) + " bytes (truncated file or wrong frame count)");
  m.motion.resize(nframes, nch);
  for (long long f = 0; f < nframes; ++f)
    for (int c = 0; c < nch; ++c) {
      double v;
      if (!tb.token(t)) tb.fail("file ends in frame " + std::to_string(f + 1) + " of " + std::to_string(nframes) + " (truncated BVH?)");
      if (!detail::parse_double(t, v) || !std::isfinite(v))
        tb.fail("motion value '" + std::string(t) + "' (frame " + std::to_string(f + 1) + ", channel " + std::to_string(c + 1) + ") is not a finite number");
      m.motion(f, c) = v;
    }
  if (tb.token(t)) tb.fail("unexpected '" + std::string(t) + "' after the " + std::to_string(nframes) + " frames (wrong 'Frames:' count?)");
  return m;
}

void write_bvh(const std::string& path, const BvhMotion& m) {
  int nch = 0;
  for (const auto& j : m.joints) nch += static_cast<int>(j.channels.size());
  if (nch != m.numChannels())
    throw InvalidInput("[tbsp::write_bvh] joints declare " + std::to_string(nch) + " channels but motion has " + std::to_string(m.numChannels()));
  static const char* cname[] = {"Xposition", "Yposition", "Zposition", "Xrotation", "Yrotation", "Zrotation"};
  std::ostringstream os;
  os << std::setprecision(10) << "HIERARCHY\n";
  std::vector<std::vector<int>> children(m.joints.size());
  for (std::size_t i = 0; i < m.joints.size(); ++i)
    if (m.joints[i].parent >= 0) children[static_cast<std::size_t>(m.joints[i].parent)].push_back(static_cast<int>(i));
  std::function<void(int, int)> emit = [&](int i, int depth) {
    const BvhJoint& j = m.joints[static_cast<std::size_t>(i)];
    const std::string ind(static_cast<std::size_t>(2 * depth), ' ');
    if (j.end_site) os << ind << "End Site\n";
    else os << ind << (j.parent < 0 ? "ROOT " : "JOINT ") << j.name << "\n";
    os << ind << "{\n" << ind << "  OFFSET " << j.offset.x() << ' ' << j.offset.y() << ' ' << j.offset.z() << "\n";
    if (!j.end_site) {
      os << ind << "  CHANNELS " << j.channels.size();
      for (auto c : j.channels) os << ' ' << cname[c];
      os << "\n";
    }
    for (int c : children[static_cast<std::size_t>(i)]) emit(c, depth + 1);
    os << ind << "}\n";
  };
  for (std::size_t i = 0; i < m.joints.size(); ++i)
    if (m.joints[i].parent < 0) emit(static_cast<int>(i), 0);
  os << "MOTION\nFrames: " << m.numFrames() << "\nFrame Time: " << m.frame_time << "\n";
  for (int f = 0; f < m.numFrames(); ++f) {
    for (int c = 0; c < nch; ++c) os << (c ? " " : "") << m.motion(f, c);
    os << "\n";
  }
  write_text_file_atomic(path, os.str());
}

}  // namespace tbsp
