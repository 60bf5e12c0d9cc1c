#include <gtest/gtest.h>

#include <pcl/conversions.h>

#include "test_util.h"
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
