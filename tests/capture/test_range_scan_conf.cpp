// Stanford .conf registration files (tbsp/io/range_scan_conf.h): the convention on a hand-made
// case, and every malformed line refused with the file, the line and what is wrong.
#include <gtest/gtest.h>

#include <cmath>
#include <fstream>

#include "test_util.h"
#include "tbsp/core/error.h"
#include "tbsp/io/range_scan_conf.h"

using namespace tbsp;

namespace {
std::string write_conf_file(const std::filesystem::path& dir, const std::string& name, const std::string& text) {
  const auto p = dir / name;
  std::ofstream(p) << text;
  return p.string();
}

}  // namespace

TEST(RangeScanConf, ReadsPosesWithTheInverseRotation) {
  const auto dir = test::temp_dir("conf");
  // a quarter turn about z: q = (0, 0, sin 45°, cos 45°); the scan's x axis must go to -y
  const double s = std::sqrt(0.5);
  const std::string conf = write_conf_file(dir, "a.conf",
                                 "camera 0 0 1  0 0 0 1\n"
                                 "# comment line\n\n"
                                 "bmesh a.ply 1 2 3  0 0 " + std::to_string(s) + " " + std::to_string(s) + "\n"
                                 "bmesh b.ply 0 0 0  0 0 0 2   # unnormalised identity\n");
  const auto poses = read_range_scan_conf(conf);
  ASSERT_EQ(poses.size(), 2u);
  EXPECT_EQ(poses[0].file, "a.ply");
  const Eigen::Vector3d x = poses[0].scan_to_world * Eigen::Vector3d::UnitX();
  EXPECT_NEAR((x - Eigen::Vector3d(1, 1, 3)).norm(), 0, 1e-6);  // R^T e_x = -e_y, then + t
  EXPECT_NEAR((poses[1].scan_to_world.linear() - Eigen::Matrix3d::Identity()).norm(), 0, 1e-12);

  // the scans themselves: an ASCII PLY cloud per scan, placed and concatenated in the asked order
  write_conf_file(dir, "a.ply", "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\nend_header\n1 0 0\n");
  write_conf_file(dir, "b.ply", "ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\nend_header\n5 6 7\n8 9 10\n");
  const Eigen::MatrixX3d P = read_registered_range_scans(conf, {"b.ply", "a.ply"});
  ASSERT_EQ(P.rows(), 3);
  EXPECT_NEAR((P.row(0) - Eigen::RowVector3d(5, 6, 7)).norm(), 0, 1e-6);
  EXPECT_NEAR((P.row(2) - Eigen::RowVector3d(1, 1, 3)).norm(), 0, 1e-6);
  EXPECT_EQ(read_registered_range_scans(conf).rows(), 3);
  const std::string msg = test::file_error_of([&] { read_registered_range_scans(conf, {"c.ply"}); });
  EXPECT_NE(msg.find("c.ply"), std::string::npos) << msg;
  EXPECT_NE(msg.find("a.ply, b.ply"), std::string::npos) << msg;
}

TEST(RangeScanConf, RefusesMalformedLines) {
  const auto dir = test::temp_dir("conf_bad");
  struct Case { const char* text; const char* expect; };
  for (const Case& c : {Case{"bmesh a.ply 0 0 0 0 0 0\n", ":1: expected 7 numbers"},
                        Case{"bmesh a.ply 0 0 0 0 0 0 1 5\n", ":1: expected 7 numbers"},
                        Case{"\nbmesh a.ply 0 0 x 0 0 0 1\n", ":2: tz 'x'"},
                        Case{"bmesh a.ply 0 0 0 0 0 0 nan\n", "qw 'nan'"},
                        Case{"bmesh a.ply 0 0 0 0 0 0 0\n", "quaternion (qx qy qz qw) is zero"},
                        Case{"bmesh\n", "needs a scan file name"},
                        Case{"bmesh a.ply 0 0 0 0 0 0 1\nbmesh a.ply 0 0 0 0 0 0 1\n", ":2: scan 'a.ply' is listed twice"},
                        Case{"mesh a.ply 0 0 0 0 0 0 1\n", "unknown keyword 'mesh'"},
                        Case{"camera 0 0 0 0 0 0\n", "expected 7 numbers"},
                        Case{"# nothing\n", "no 'bmesh"},
                        Case{"", "no 'bmesh"}}) {
    const std::string path = write_conf_file(dir, "bad.conf", c.text);
    const std::string msg = test::file_error_of([&] { read_range_scan_conf(path); });
    EXPECT_NE(msg.find(c.expect), std::string::npos) << "input: " << c.text << "\nmessage: " << msg;
    EXPECT_NE(msg.find("bad.conf"), std::string::npos) << msg;
  }
  EXPECT_NE(test::file_error_of([&] { read_range_scan_conf((dir / "missing.conf").string()); }).find("no such file"), std::string::npos);
  // a listed scan that is not there: the reader's error names it
  const std::string conf = write_conf_file(dir, "ok.conf", "bmesh gone.ply 0 0 0 0 0 0 1\n");
  EXPECT_NE(test::file_error_of([&] { read_registered_range_scans(conf); }).find("gone.ply"), std::string::npos);
}
