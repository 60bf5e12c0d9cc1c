#include "tbsp/io/range_scan_conf.h"

#include <cmath>
#include <filesystem>
#include <set>
#include <sstream>

#include "tbsp/core/error.h"
#include "tbsp/io/cloud_io.h"
#include "text_buffer.h"

namespace tbsp {

namespace {

// Splits a line into whitespace-separated tokens, dropping a '#' comment.
std::vector<std::string> tokens(std::string_view line) {
  const std::size_t hash = line.find('#');
  if (hash != std::string_view::npos) line = line.substr(0, hash);
  std::vector<std::string> out;
  std::istringstream ss{std::string(line)};
  for (std::string t; ss >> t;) out.push_back(t);
  return out;
}

// Seven numbers (translation, quaternion x y z w) from tokens[first..]; fails naming the field.
Eigen::Isometry3d pose_from(const std::vector<std::string>& tok, std::size_t first, const std::string& where) {
  static const char* names[7] = {"tx", "ty", "tz", "qx", "qy", "qz", "qw"};
  if (tok.size() != first + 7)
    throw FileError(where + ": expected 7 numbers after '" + tok[0] + (first > 1 ? " " + tok[1] : std::string()) +
                    "' (tx ty tz qx qy qz qw), found " + std::to_string(tok.size() - first));
  double v[7];
  for (int k = 0; k < 7; ++k) {
    if (!detail::parse_double(tok[first + std::size_t(k)], v[k]) || !std::isfinite(v[k]))
      throw FileError(where + ": " + names[k] + " '" + tok[first + std::size_t(k)] + "' is not a finite number");
  }
  const Eigen::Quaterniond q(v[6], v[3], v[4], v[5]);
  if (q.norm() < 1e-6) throw FileError(where + ": the quaternion (qx qy qz qw) is zero; a rotation needs a unit quaternion");
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = q.normalized().toRotationMatrix().transpose();  // the inverse rotation (see the header)
  T.translation() << v[0], v[1], v[2];
  return T;
}

}  // namespace

std::vector<RangeScanPose> read_range_scan_conf(const std::string& path) {
  detail::TextBuffer tb = detail::TextBuffer::load(path);
  std::vector<RangeScanPose> out;
  std::set<std::string> seen;
  std::string_view line;
  for (int n = 1; tb.nextLine(line); ++n) {
    const std::vector<std::string> tok = tokens(line);
    if (tok.empty()) continue;
    const std::string where = path + ":" + std::to_string(n);
    if (tok[0] == "camera") {
      pose_from(tok, 1, where);  // validated, not used
    } else if (tok[0] == "bmesh") {
      if (tok.size() < 2) throw FileError(where + ": 'bmesh' needs a scan file name and 7 numbers");
      RangeScanPose p;
      p.file = tok[1];
      p.scan_to_world = pose_from(tok, 2, where);
      if (!seen.insert(p.file).second) throw FileError(where + ": scan '" + p.file + "' is listed twice");
      out.push_back(p);
    } else {
      throw FileError(where + ": unknown keyword '" + tok[0] + "' (a .conf line starts with 'bmesh' or 'camera')");
    }
  }
  if (out.empty()) throw FileError(path + ": no 'bmesh FILE tx ty tz qx qy qz qw' line; not a range-scan registration");
  return out;
}

Eigen::MatrixX3d read_registered_range_scans(const std::string& conf_path, const std::vector<std::string>& files) {
  const std::vector<RangeScanPose> poses = read_range_scan_conf(conf_path);
  std::vector<const RangeScanPose*> chosen;
  if (files.empty()) {
    for (const auto& p : poses) chosen.push_back(&p);
  } else {
    for (const std::string& f : files) {
      const RangeScanPose* hit = nullptr;
      for (const auto& p : poses)
        if (p.file == f) hit = &p;
      if (!hit) {
        std::string listed;
        for (const auto& p : poses) listed += (listed.empty() ? "" : ", ") + p.file;
        throw FileError(conf_path + ": has no pose for scan '" + f + "' (it lists " + listed + ")");
      }
      chosen.push_back(hit);
    }
  }
  const std::filesystem::path dir = std::filesystem::path(conf_path).parent_path();
  std::vector<Eigen::Vector3d> pts;
  for (const RangeScanPose* p : chosen) {
    const auto cloud = read_cloud_normals((dir / p->file).string());
    pts.reserve(pts.size() + cloud->size());
    for (const auto& q : *cloud) {
      const Eigen::Vector3d x(q.x, q.y, q.z);
      if (x.allFinite()) pts.push_back(p->scan_to_world * x);
    }
  }
  Eigen::MatrixX3d P(Eigen::Index(pts.size()), 3);
  for (std::size_t i = 0; i < pts.size(); ++i) P.row(Eigen::Index(i)) = pts[i].transpose();
  return P;
}

}  // namespace tbsp
