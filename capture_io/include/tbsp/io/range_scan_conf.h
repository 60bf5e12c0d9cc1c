#pragma once
/// \file range_scan_conf.h
/// \brief Registration files of the Stanford 3D Scanning Repository (`bun.conf`, `dragon*.conf`,
/// scanalyze's `.conf`): one line per range scan, `bmesh FILE tx ty tz qx qy qz qw`, plus an
/// optional `camera tx ty tz qx qy qz qw` line (the viewer's camera; read and ignored).
///
/// Convention (measured on the bunny's ten scans against bun_zipper.ply: 97-99 % of every scan's
/// points within 1 mm once placed): a scan point p goes to the common frame as
/// `R(q)^T p + t`, the inverse of the quaternion's rotation followed by the translation; used
/// literally (`R(q) p + t`) only the scans with a near-identity or a half-turn rotation align.
#include <Eigen/Geometry>
#include <string>
#include <vector>

namespace tbsp {

/// One `bmesh` line: the scan's file name as written (relative to the .conf's folder) and the
/// rigid motion from the scan's frame to the common frame (units of the scans).
struct RangeScanPose {
  std::string file;
  Eigen::Isometry3d scan_to_world = Eigen::Isometry3d::Identity();
};

/// \brief Reads a Stanford `.conf` registration file. Blank lines and `#` comments are skipped.
/// \throws FileError naming the file and line for: a missing file, an unknown keyword, a line
/// with a missing, extra, non-numeric or non-finite value, a quaternion of norm < 1e-6 (it is
/// normalised otherwise), the same scan listed twice, no `bmesh` line at all.
std::vector<RangeScanPose> read_range_scan_conf(const std::string& path);

/// \brief Reads the scans named in `files` (all of the .conf's scans when empty; any cloud
/// format read_cloud_normals reads, found in the .conf's folder), puts each into the common
/// frame and returns all points, in the order of `files` (rows: x y z). Points with a
/// non-finite coordinate are dropped. \throws FileError for a bad .conf, a scan it does not
/// list (the message names the scans it does list) or an unreadable scan.
Eigen::MatrixX3d read_registered_range_scans(const std::string& conf_path, const std::vector<std::string>& files = {});

}  // namespace tbsp
