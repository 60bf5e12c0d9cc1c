#include "tbsp/multiview/range_scanner.h"

#include <cmath>
#include <limits>
#include <random>

#include "tbsp/core/error.h"

namespace tbsp {

pcl::PointCloud<pcl::PointNormal> range_scan(const TriMesh& mesh, const Camera& cam, const RangeScanOptions& opt) {
  if (opt.stride < 1) throw InvalidInput("[tbsp::range_scan] stride must be >= 1 (got " + std::to_string(opt.stride) + ")");
  if (!(opt.noise_sigma >= 0)) throw InvalidInput("[tbsp::range_scan] noise_sigma must be >= 0");
  RasterOptions ro;
  ro.barycentrics = false;
  RenderBuffers buf;
  Rasterizer(ro).render(mesh, cam, buf);
  const Eigen::MatrixX3d FN = face_normals(mesh.V, mesh.F);
  const int W = cam.width(), H = cam.height(), s = opt.stride;
  pcl::PointCloud<pcl::PointNormal> cloud;
  cloud.width = static_cast<std::uint32_t>((W + s - 1) / s);
  cloud.height = static_cast<std::uint32_t>((H + s - 1) / s);
  cloud.is_dense = false;
  const float nan = std::numeric_limits<float>::quiet_NaN();
  pcl::PointNormal empty;
  empty.x = empty.y = empty.z = nan;
  empty.normal_x = empty.normal_y = empty.normal_z = nan;
  empty.curvature = 0;
  cloud.points.assign(static_cast<std::size_t>(cloud.width) * cloud.height, empty);
  std::mt19937_64 rng(opt.seed);
  std::normal_distribution<double> gauss(0.0, 1.0);
  const double cos_max = std::cos(opt.max_incidence_deg * M_PI / 180.0);
  const Eigen::Vector3d c = cam.center();
  for (int y = 0, oy = 0; y < H; y += s, ++oy) {
    for (int x = 0, ox = 0; x < W; x += s, ++ox) {
      const std::size_t idx = static_cast<std::size_t>(y) * W + x;
      const int f = buf.face[idx];
      const double noise = opt.noise_sigma > 0 ? opt.noise_sigma * gauss(rng) : 0.0;  // drawn for every pixel: stable
      if (f < 0) continue;
      const Eigen::Vector3d Xs = cam.backProject({double(x), double(y)}, buf.depth[idx]);
      const Eigen::Vector3d dir = (Xs - c).normalized();
      Eigen::Vector3d nrm = FN.row(f).transpose();
      if (nrm.dot(dir) > 0) nrm = -nrm;
      if (-nrm.dot(dir) < cos_max) continue;
      const Eigen::Vector3d X = Xs + noise * dir;
      pcl::PointNormal& p = cloud.at(ox, oy);
      p.x = float(X.x()); p.y = float(X.y()); p.z = float(X.z());
      p.normal_x = float(nrm.x()); p.normal_y = float(nrm.y()); p.normal_z = float(nrm.z());
    }
  }
  return cloud;
}

}  // namespace tbsp
