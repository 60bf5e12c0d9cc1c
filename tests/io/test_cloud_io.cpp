#include <gtest/gtest.h>

#include <pcl/conversions.h>
#include <pcl/point_types.h>

#include <fstream>
#include <iterator>

#include "test_util.h"
#include "tbsp/core/error.h"
#include "tbsp/io/cloud_io.h"

using namespace tbsp;

TEST(CloudIo, PcdAndPlyRoundTrip) {
  pcl::PointCloud<pcl::PointNormal> c;
  for (int i = 0; i < 100; ++i) {
    pcl::PointNormal p;
    p.x = float(i); p.y = float(i) * 0.5f; p.z = -float(i);
    p.normal_x = 0; p.normal_y = 0; p.normal_z = 1;
    c.push_back(p);
  }
  pcl::PCLPointCloud2 blob;
  pcl::toPCLPointCloud2(c, blob);
  const auto dir = test::temp_dir("cloud");
  for (const char* name : {"c.pcd", "c.ply"})
    for (bool binary : {true, false}) {
      const std::string p = (dir / name).string();
      write_cloud(p, blob, binary);
      bool has_normals = false;
      const auto r = read_cloud_normals(p, &has_normals);
      ASSERT_EQ(r->size(), 100u) << p;
      EXPECT_TRUE(has_normals) << p;
      EXPECT_FLOAT_EQ((*r)[42].y, 21.0f);
      EXPECT_FLOAT_EQ((*r)[42].normal_z, 1.0f);
    }
  std::filesystem::remove_all(dir);
}

TEST(CloudIo, PlyWithColourAndExtraFieldsKeepsThemAndReadsBack) {
  // Colour and a custom scalar go through PCL's PLYWriter ("element face 0" without
  // properties, normals as nx/ny/nz); tbsp's reader takes such files.
  pcl::PointCloud<pcl::PointXYZRGBNormal> c;
  for (int i = 0; i < 5; ++i) {
    pcl::PointXYZRGBNormal p;
    p.x = float(i);
    p.y = 2.f * i;
    p.z = -1.f;
    p.normal_x = 0;
    p.normal_y = 0;
    p.normal_z = 1;
    p.r = 200;
    p.g = 10;
    p.b = 30;
    c.push_back(p);
  }
  pcl::PCLPointCloud2 blob;
  pcl::toPCLPointCloud2(c, blob);
  const auto dir = test::temp_dir("cloud_rgb");
  const std::string path = (dir / "c.ply").string();
  write_cloud(path, blob, true);
  bool has_normals = false;
  const auto back = read_cloud_normals(path, &has_normals);
  ASSERT_EQ(back->size(), 5u);
  EXPECT_TRUE(has_normals);
  EXPECT_FLOAT_EQ((*back)[3].y, 6.f);
  EXPECT_FLOAT_EQ((*back)[3].normal_z, 1.f);
  std::ifstream in(path, std::ios::binary);
  std::string header((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  EXPECT_NE(header.find("property uchar red"), std::string::npos);
}

// Found by hand (2026-12-06): a PLY/OBJ/OFF/VTK cloud with coordinates beyond single precision
// (1e40, 1e100) was read as infinite points, and `fit` then said "no finite points (all are
// NaN/Inf)" of a file without any. Now the reader names the file, the vertex and the value.
TEST(CloudIo, CoordinatesBeyondSinglePrecisionAreNamed) {
  const auto dir = test::temp_dir("cloud_big");
  for (const char* name : {"c.ply", "c.obj", "c.off"}) {
    const std::string p = (dir / name).string();
    {
      std::ofstream f(p);
      if (std::string(name) == "c.ply")
        f << "ply\nformat ascii 1.0\nelement vertex 3\nproperty double x\nproperty double y\nproperty double z\nend_header\n"
             "0 0 0\n1 0 0\n0 -1e40 1\n";
      else if (std::string(name) == "c.obj")
        f << "v 0 0 0\nv 1 0 0\nv 0 -1e40 1\n";
      else
        f << "OFF\n3 0 0\n0 0 0\n1 0 0\n0 -1e40 1\n";
    }
    try {
      read_cloud_normals(p);
      ADD_FAILURE() << name;
    } catch (const FileError& e) {
      const std::string m = e.what();
      EXPECT_NE(m.find(p), std::string::npos) << m;
      EXPECT_NE(m.find("vertex 2 has y = -1e+40"), std::string::npos) << m;
      EXPECT_NE(m.find("single precision"), std::string::npos) << m;
    }
  }
  {
    std::ofstream f((dir / "ok.ply").string());
    f << "ply\nformat ascii 1.0\nelement vertex 2\nproperty double x\nproperty double y\nproperty double z\nend_header\n"
         "0 0 0\n3e38 0 1\n";
  }
  EXPECT_FLOAT_EQ((*read_cloud_normals((dir / "ok.ply").string()))[1].x, 3e38f);
  std::filesystem::remove_all(dir);
}
