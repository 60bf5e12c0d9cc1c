#include "tbsp/cloth/retarget.h"

#include <Eigen/Geometry>
#include <Eigen/SVD>
#include <algorithm>
#include <cmath>

#include "tbsp/core/error.h"

namespace tbsp {

namespace {

std::string trim(const std::string& s) {
  std::string t;
  for (char c : s)
    if (c != ' ' && c != '\t' && c != '\n' && c != '\r') t += c;
  return t;
}

std::string some_names(const std::vector<std::string>& names) {
  std::string s;
  for (std::size_t i = 0; i < names.size() && i < 30; ++i) s += (i ? ", " : "") + names[i];
  if (names.size() > 30) s += ", ...";
  return s;
}

int index_of(const std::vector<std::string>& names, const std::string& n) {
  const auto it = std::find(names.begin(), names.end(), n);
  return it == names.end() ? -1 : int(it - names.begin());
}

}  // namespace

std::vector<int> parse_joint_map(const std::string& spec, const std::vector<std::string>& model_joints,
                                 const std::vector<std::string>& clip_joints) {
  const std::string who = "[tbsp::parse_joint_map] ";
  std::vector<int> src(model_joints.size(), -1);
  std::vector<char> used(clip_joints.size(), 0);
  const std::string s = trim(spec);
  if (s.empty()) throw InvalidInput(who + "the joint map is empty: give model=clip pairs separated by commas");
  std::size_t pos = 0;
  int entry = 0;
  while (pos <= s.size()) {
    const std::size_t comma = std::min(s.find(',', pos), s.size());
    const std::string item = s.substr(pos, comma - pos);
    ++entry;
    const std::string where = who + "entry " + std::to_string(entry) + " '" + item + "': ";
    const std::size_t eq = item.find('=');
    if (item.empty()) throw InvalidInput(where + "empty (two commas in a row, or a trailing comma)");
    if (eq == std::string::npos || item.find('=', eq + 1) != std::string::npos)
      throw InvalidInput(where + "expected one model=clip pair");
    const std::string m = item.substr(0, eq), c = item.substr(eq + 1);
    if (m.empty() || c.empty()) throw InvalidInput(where + "a joint name is empty");
    const int mi = index_of(model_joints, m), ci = index_of(clip_joints, c);
    if (mi < 0) throw InvalidInput(where + "the model has no joint '" + m + "' (it has: " + some_names(model_joints) + ")");
    if (ci < 0) throw InvalidInput(where + "the clip has no joint '" + c + "' (it has: " + some_names(clip_joints) + ")");
    if (src[std::size_t(mi)] >= 0) throw InvalidInput(where + "the model joint '" + m + "' is mapped twice");
    if (used[std::size_t(ci)]) throw InvalidInput(where + "the clip joint '" + c + "' is used twice");
    src[std::size_t(mi)] = ci;
    used[std::size_t(ci)] = 1;
    pos = comma + 1;
  }
  return src;
}

PoseRetargeter::PoseRetargeter(const Skeleton& model, std::vector<int> source, const Eigen::MatrixX3d& clip_first)
    : model_(model), source_(std::move(source)), first_(clip_first) {
  const std::string who = "[tbsp::PoseRetargeter] ";
  validate_skeleton(model_, "tbsp::PoseRetargeter");
  const int n = model_.numJoints();
  if (int(source_.size()) != n)
    throw InvalidInput(who + "the joint map has " + std::to_string(source_.size()) + " entries for " + std::to_string(n) + " model joints");
  for (int j = 0; j < n; ++j) {
    const int s = source_[std::size_t(j)];
    if (s >= first_.rows()) throw InvalidInput(who + "model joint '" + model_.names[std::size_t(j)] + "': clip joint index out of range");
    if (model_.parents[std::size_t(j)] < 0 && s < 0)
      throw InvalidInput(who + "the model root '" + model_.names[std::size_t(j)] + "' is not mapped: map it to the clip's root (hips)");
  }
  if (!first_.allFinite()) throw InvalidInput(who + "the clip's first-frame positions are not finite");
  // nearest mapped descendants of every joint (children lists, then a walk down through unmapped ones)
  std::vector<std::vector<int>> children(static_cast<std::size_t>(n));
  for (int j = 0; j < n; ++j)
    if (model_.parents[std::size_t(j)] >= 0) children[std::size_t(model_.parents[std::size_t(j)])].push_back(j);
  targets_.assign(std::size_t(n), {});
  double len_model = 0, len_clip = 0;
  for (int j = 0; j < n; ++j) {
    if (source_[std::size_t(j)] < 0) continue;
    std::vector<int> stack(children[std::size_t(j)].rbegin(), children[std::size_t(j)].rend());
    while (!stack.empty()) {
      const int c = stack.back();
      stack.pop_back();
      if (source_[std::size_t(c)] >= 0) {
        targets_[std::size_t(j)].push_back(c);
        len_model += (model_.restPosition(c) - model_.restPosition(j)).norm();
        len_clip += (first_.row(source_[std::size_t(c)]) - first_.row(source_[std::size_t(j)])).norm();
      } else {
        for (auto it = children[std::size_t(c)].rbegin(); it != children[std::size_t(c)].rend(); ++it) stack.push_back(*it);
      }
    }
  }
  if (!(len_model > 0) || !(len_clip > 0))
    throw InvalidInput(who + "no mapped bone (two mapped joints, one below the other) of non-zero length: map more joints");
  rho_ = len_model / len_clip;
}

SkeletonPose PoseRetargeter::retarget(const Eigen::MatrixX3d& Q) const {
  const int n = model_.numJoints();
  if (Q.rows() != first_.rows())
    throw InvalidInput("[tbsp::PoseRetargeter::retarget] " + std::to_string(Q.rows()) + " clip joints given, " + std::to_string(first_.rows()) +
                       " expected");
  std::vector<Eigen::Matrix3d> R(static_cast<std::size_t>(n));
  std::vector<Eigen::Vector3d> P(static_cast<std::size_t>(n));
  SkeletonPose out(static_cast<std::size_t>(n));
  for (int j = 0; j < n; ++j) {
    const int p = model_.parents[std::size_t(j)];
    const Eigen::Matrix3d Rp = p >= 0 ? R[std::size_t(p)] : Eigen::Matrix3d::Identity();
    Eigen::Matrix3d Rj = Rp;
    const int sj = source_[std::size_t(j)];
    const auto& tg = targets_[std::size_t(j)];
    if (sj >= 0 && !tg.empty()) {
      std::vector<Eigen::Vector3d> u, v;
      for (int d : tg) {
        const Eigen::Vector3d a = model_.restPosition(d) - model_.restPosition(j);
        const Eigen::Vector3d b = (Q.row(source_[std::size_t(d)]) - Q.row(sj)).transpose();
        if (a.norm() < 1e-12 || b.norm() < 1e-12) continue;
        u.push_back(a.normalized());
        v.push_back(b.normalized());
      }
      bool done = false;
      if (u.size() >= 2) {  // best rotation of the unit directions (Kabsch), if they span a plane
        Eigen::Matrix3d H = Eigen::Matrix3d::Zero();
        for (std::size_t k = 0; k < u.size(); ++k) H += v[k] * u[k].transpose();
        Eigen::JacobiSVD<Eigen::Matrix3d> svd(H, Eigen::ComputeFullU | Eigen::ComputeFullV);
        if (svd.singularValues()(1) > 1e-6 * svd.singularValues()(0)) {
          Eigen::Matrix3d D = Eigen::Matrix3d::Identity();
          D(2, 2) = (svd.matrixU() * svd.matrixV().transpose()).determinant() < 0 ? -1 : 1;
          Rj = svd.matrixU() * D * svd.matrixV().transpose();
          done = true;
        }
      }
      if (!done && !u.empty()) Rj = Eigen::Quaterniond::FromTwoVectors(Rp * u[0], v[0]).toRotationMatrix() * Rp;
    }
    R[std::size_t(j)] = Rj;
    if (p < 0)
      P[std::size_t(j)] = model_.restPosition(j) + rho_ * (Q.row(sj) - first_.row(sj)).transpose();
    else
      P[std::size_t(j)] = P[std::size_t(p)] + R[std::size_t(p)] * (model_.restPosition(j) - model_.restPosition(p));
    Eigen::Isometry3d G = Eigen::Isometry3d::Identity();
    G.linear() = Rj * model_.rest[std::size_t(j)].linear();
    G.translation() = P[std::size_t(j)];
    out[std::size_t(j)] = G;
  }
  return out;
}

}  // namespace tbsp
