#include "tbsp/mesh/pcl_conversions.h"

#include <pcl/conversions.h>
#include <pcl/point_types.h>

#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

#include "tbsp/core/error.h"

namespace tbsp {

namespace {
bool has_field(const pcl::PCLPointCloud2& c, const std::string& name) {
  for (const auto& f : c.fields)
    if (f.name == name) return true;
  return false;
}
}  // namespace

pcl::PolygonMesh to_pcl(const TriMesh& mesh) {
  pcl::PolygonMesh out;
  const bool normals = mesh.N.rows() == mesh.V.rows() && mesh.V.rows() > 0;
  const bool colors = mesh.C.rows() == mesh.V.rows() && mesh.V.rows() > 0;
  if (normals || colors) {
    pcl::PointCloud<pcl::PointXYZRGBNormal> cloud;
    cloud.resize(mesh.V.rows());
    for (Eigen::Index i = 0; i < mesh.V.rows(); ++i) {
      auto& p = cloud[i];
      p.x = float(mesh.V(i, 0)); p.y = float(mesh.V(i, 1)); p.z = float(mesh.V(i, 2));
      if (normals) { p.normal_x = float(mesh.N(i, 0)); p.normal_y = float(mesh.N(i, 1)); p.normal_z = float(mesh.N(i, 2)); }
      if (colors) {
        auto c8 = [](double v) { return std::uint8_t(std::lround(std::clamp(v, 0.0, 1.0) * 255.0)); };
        p.r = c8(mesh.C(i, 0)); p.g = c8(mesh.C(i, 1)); p.b = c8(mesh.C(i, 2));
      }
    }
    pcl::toPCLPointCloud2(cloud, out.cloud);
  } else {
    pcl::PointCloud<pcl::PointXYZ> cloud;
    cloud.resize(mesh.V.rows());
    for (Eigen::Index i = 0; i < mesh.V.rows(); ++i)
      cloud[i] = pcl::PointXYZ(float(mesh.V(i, 0)), float(mesh.V(i, 1)), float(mesh.V(i, 2)));
    pcl::toPCLPointCloud2(cloud, out.cloud);
  }
  out.polygons.resize(mesh.F.rows());
  for (Eigen::Index f = 0; f < mesh.F.rows(); ++f)
    out.polygons[f].vertices = {static_cast<pcl::index_t>(mesh.F(f, 0)), static_cast<pcl::index_t>(mesh.F(f, 1)), static_cast<pcl::index_t>(mesh.F(f, 2))};
  return out;
}

TriMesh from_pcl(const pcl::PolygonMesh& mesh) {
  const auto& c = mesh.cloud;
  if (!has_field(c, "x") || !has_field(c, "y") || !has_field(c, "z"))
    throw InvalidInput("[tbsp::from_pcl] the PolygonMesh cloud has no x/y/z fields");
  TriMesh out;
  pcl::PointCloud<pcl::PointXYZ> xyz;
  pcl::fromPCLPointCloud2(c, xyz);
  const Eigen::Index n = Eigen::Index(xyz.size());
  out.V.resize(n, 3);
  for (Eigen::Index i = 0; i < n; ++i) out.V.row(i) << xyz[i].x, xyz[i].y, xyz[i].z;
  if (has_field(c, "normal_x")) {
    pcl::PointCloud<pcl::Normal> nrm;
    pcl::fromPCLPointCloud2(c, nrm);
    out.N.resize(n, 3);
    for (Eigen::Index i = 0; i < n; ++i) out.N.row(i) << nrm[i].normal_x, nrm[i].normal_y, nrm[i].normal_z;
  }
  if (has_field(c, "rgb") || has_field(c, "rgba")) {
    pcl::PointCloud<pcl::PointXYZRGB> rgb;
    pcl::fromPCLPointCloud2(c, rgb);
    out.C.resize(n, 3);
    for (Eigen::Index i = 0; i < n; ++i) out.C.row(i) << rgb[i].r / 255.0, rgb[i].g / 255.0, rgb[i].b / 255.0;
  }
  std::vector<Eigen::Vector3i> tris;
  tris.reserve(mesh.polygons.size());
  for (std::size_t p = 0; p < mesh.polygons.size(); ++p) {
    const auto& v = mesh.polygons[p].vertices;
    if (v.size() < 3)
      throw InvalidInput("[tbsp::from_pcl] polygon " + std::to_string(p) + " has " + std::to_string(v.size()) +
                         " vertices; at least 3 are needed");
    for (auto idx : v)
      if (Eigen::Index(idx) >= n)
        throw InvalidInput("[tbsp::from_pcl] polygon " + std::to_string(p) + " references vertex " + std::to_string(idx) +
                           " but the cloud has " + std::to_string(n) + " points");
    for (std::size_t k = 1; k + 1 < v.size(); ++k) tris.emplace_back(int(v[0]), int(v[k]), int(v[k + 1]));
  }
  out.F.resize(Eigen::Index(tris.size()), 3);
  for (std::size_t f = 0; f < tris.size(); ++f) out.F.row(Eigen::Index(f)) = tris[f].transpose();
  return out;
}

}  // namespace tbsp
