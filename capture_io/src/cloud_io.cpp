#include "tbsp/io/cloud_io.h"

#include <pcl/conversions.h>
#include <pcl/io/pcd_io.h>

#include <algorithm>
#include <cctype>
#include <filesystem>
#include <limits>

#include "tbsp/core/error.h"
#include "tbsp/io/atomic_file.h"
#include "tbsp/io/mesh_io.h"

namespace tbsp {

namespace {
std::string ext_of(const std::string& path) {
  const auto dot = path.find_last_of('.');
  std::string e = dot == std::string::npos ? "" : path.substr(dot + 1);
  std::transform(e.begin(), e.end(), e.begin(), [](unsigned char c) { return char(std::tolower(c)); });
  return e;
}
bool has_field(const pcl::PCLPointCloud2& c, const std::string& n) {
  return std::any_of(c.fields.begin(), c.fields.end(), [&](const pcl::PCLPointField& f) { return f.name == n; });
}
}  // namespace

pcl::PCLPointCloud2 read_cloud(const std::string& path) {
  std::error_code ec;
  if (!std::filesystem::exists(path, ec)) throw FileError("'" + path + "': no such file; check the path");
  pcl::PCLPointCloud2 blob;
  if (ext_of(path) == "pcd") {
    if (std::filesystem::file_size(path, ec) == 0) throw FileError("'" + path + "': the file is empty");
    pcl::PCDReader reader;
    int rc = -1;
    try {
      Eigen::Vector4f origin;
      Eigen::Quaternionf orientation;
      int version = 0;
      rc = reader.read(path, blob, origin, orientation, version);
    } catch (const std::exception& e) {
      throw FileError("'" + path + "': malformed PCD file (" + e.what() + ")");
    }
    if (rc < 0)
      throw FileError("'" + path + "': malformed or truncated PCD file (PCL's reader failed with code " +
                      std::to_string(rc) + "; see its message above)");
  } else {
    const TriMesh m = read_mesh(path);
    if (m.N.rows() == m.V.rows() && m.V.rows() > 0) {
      pcl::PointCloud<pcl::PointNormal> c;
      c.resize(std::size_t(m.V.rows()));
      for (Eigen::Index i = 0; i < m.V.rows(); ++i) {
        auto& p = c[std::size_t(i)];
        p.x = float(m.V(i, 0)); p.y = float(m.V(i, 1)); p.z = float(m.V(i, 2));
        p.normal_x = float(m.N(i, 0)); p.normal_y = float(m.N(i, 1)); p.normal_z = float(m.N(i, 2));
      }
      pcl::toPCLPointCloud2(c, blob);
    } else {
      pcl::PointCloud<pcl::PointXYZ> c;
      c.resize(std::size_t(m.V.rows()));
      for (Eigen::Index i = 0; i < m.V.rows(); ++i)
        c[std::size_t(i)] = pcl::PointXYZ(float(m.V(i, 0)), float(m.V(i, 1)), float(m.V(i, 2)));
      pcl::toPCLPointCloud2(c, blob);
    }
  }
  if (!has_field(blob, "x") || !has_field(blob, "y") || !has_field(blob, "z"))
    throw FileError("'" + path + "': the cloud has no x/y/z fields");
  return blob;
}

pcl::PointCloud<pcl::PointNormal>::Ptr read_cloud_normals(const std::string& path, bool* has_normals) {
  const pcl::PCLPointCloud2 blob = read_cloud(path);
  auto out = pcl::PointCloud<pcl::PointNormal>::Ptr(new pcl::PointCloud<pcl::PointNormal>);
  const bool hn = has_field(blob, "normal_x") && has_field(blob, "normal_y") && has_field(blob, "normal_z");
  pcl::PointCloud<pcl::PointXYZ> xyz;
  pcl::fromPCLPointCloud2(blob, xyz);
  out->resize(xyz.size());
  out->width = xyz.width;
  out->height = xyz.height;
  out->is_dense = xyz.is_dense;
  pcl::PointCloud<pcl::Normal> n;
  if (hn) pcl::fromPCLPointCloud2(blob, n);
  const float nan = std::numeric_limits<float>::quiet_NaN();
  for (std::size_t i = 0; i < xyz.size(); ++i) {
    auto& p = (*out)[i];
    p.x = xyz[i].x; p.y = xyz[i].y; p.z = xyz[i].z;
    p.normal_x = hn ? n[i].normal_x : nan;
    p.normal_y = hn ? n[i].normal_y : nan;
    p.normal_z = hn ? n[i].normal_z : nan;
    p.curvature = hn ? n[i].curvature : nan;
  }
  if (has_normals) *has_normals = hn;
  return out;
}

void write_cloud(const std::string& path, const pcl::PCLPointCloud2& cloud, bool binary) {
  const std::string e = ext_of(path);
  if (e == "pcd") {
    atomic_write_with(path, [&](const std::string& tmp) {
      pcl::PCDWriter w;
      return (binary ? w.writeBinary(tmp, cloud) : w.writeASCII(tmp, cloud)) == 0;
    });
    return;
  }
  if (e != "ply") throw FileError("cannot write cloud '" + path + "': use .pcd or .ply");
  TriMesh m;
  pcl::PointCloud<pcl::PointXYZ> xyz;
  pcl::fromPCLPointCloud2(cloud, xyz);
  m.V.resize(Eigen::Index(xyz.size()), 3);
  for (std::size_t i = 0; i < xyz.size(); ++i) m.V.row(Eigen::Index(i)) << xyz[i].x, xyz[i].y, xyz[i].z;
  if (has_field(cloud, "normal_x")) {
    pcl::PointCloud<pcl::Normal> n;
    pcl::fromPCLPointCloud2(cloud, n);
    m.N.resize(m.V.rows(), 3);
    for (std::size_t i = 0; i < n.size(); ++i) m.N.row(Eigen::Index(i)) << n[i].normal_x, n[i].normal_y, n[i].normal_z;
  }
  MeshWriteOptions o;
  o.binary = binary;
  write_mesh(path, m, o, MeshFormat::PLY);
}

}  // namespace tbsp
