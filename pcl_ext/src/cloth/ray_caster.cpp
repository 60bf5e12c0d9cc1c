#include "ray_caster.h"

#include "../mesh/embree_device.h"

#include <embree3/rtcore.h>

#include <Eigen/Geometry>

#include <cmath>
#include <limits>
#include <string>

#include "tbsp/core/error.h"

namespace tbsp {
namespace detail {

namespace {

// Möller–Trumbore in double; returns false when the ray misses the (closed) triangle.
bool intersect(const Eigen::Vector3d& o, const Eigen::Vector3d& d, const Eigen::Vector3d& a, const Eigen::Vector3d& b,
               const Eigen::Vector3d& c, double& t, double& u, double& v) {
  const Eigen::Vector3d e1 = b - a, e2 = c - a;
  const Eigen::Vector3d p = d.cross(e2);
  const double det = e1.dot(p);
  if (std::abs(det) < 1e-300) return false;
  const double inv = 1.0 / det;
  const Eigen::Vector3d s = o - a;
  u = s.dot(p) * inv;
  const Eigen::Vector3d q = s.cross(e1);
  v = d.dot(q) * inv;
  t = e2.dot(q) * inv;
  const double tol = 1e-9;
  return u >= -tol && v >= -tol && u + v <= 1 + tol;
}

struct FilterData {
  const Eigen::MatrixX3i* F;
  int skip_vertex;
};

// The intersect context with our data after it; Embree hands the context pointer to the filter.
struct ContextWithData {
  RTCIntersectContext ctx;
  FilterData data;
};

void skip_filter(const RTCFilterFunctionNArguments* args) {
  // N = 1 for rtcIntersect1 / rtcOccluded1
  const auto* data = &reinterpret_cast<const ContextWithData*>(args->context)->data;
  const unsigned prim = RTCHitN_primID(args->hit, args->N, 0);
  const auto& F = *data->F;
  for (int k = 0; k < 3; ++k)
    if (F(prim, k) == data->skip_vertex) {
      args->valid[0] = 0;
      return;
    }
}

}  // namespace

struct RayCaster::Impl {
  Eigen::MatrixX3d V;
  Eigen::MatrixX3i F;
  RTCScene scene = nullptr;
};

RayCaster::RayCaster(const Eigen::MatrixX3d& V, const Eigen::MatrixX3i& F) : impl_(new Impl) {
  impl_->V = V;
  impl_->F = F;
  RTCDevice device = embree_device();
  impl_->scene = rtcNewScene(device);
  RTCGeometry g = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_TRIANGLE);
  auto* vb = static_cast<float*>(
      rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, 3 * sizeof(float), std::size_t(V.rows())));
  auto* ib = static_cast<unsigned*>(
      rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, 3 * sizeof(unsigned), std::size_t(F.rows())));
  if (!vb || !ib) {
    rtcReleaseGeometry(g);
    rtcReleaseScene(impl_->scene);
    throw NumericalFailure("[tbsp::cloth] Embree could not allocate the ray-casting buffers");
  }
  for (Eigen::Index i = 0; i < V.rows(); ++i)
    for (int k = 0; k < 3; ++k) vb[3 * i + k] = float(V(i, k));
  for (Eigen::Index f = 0; f < F.rows(); ++f)
    for (int k = 0; k < 3; ++k) ib[3 * f + k] = unsigned(F(f, k));
  rtcSetGeometryIntersectFilterFunction(g, skip_filter);
  rtcSetGeometryOccludedFilterFunction(g, skip_filter);
  rtcCommitGeometry(g);
  rtcAttachGeometry(impl_->scene, g);
  rtcReleaseGeometry(g);
  rtcCommitScene(impl_->scene);
  if (rtcGetDeviceError(device) != RTC_ERROR_NONE) {
    rtcReleaseScene(impl_->scene);
    throw NumericalFailure("[tbsp::cloth] Embree could not build the ray-casting tree");
  }
}

RayCaster::~RayCaster() {
  if (impl_ && impl_->scene) rtcReleaseScene(impl_->scene);
}

RayHit RayCaster::cast(const Eigen::Vector3d& origin, const Eigen::Vector3d& dir_in, double t_near, double t_far,
                       int skip_vertex) const {
  RayHit out;
  const double len = dir_in.norm();
  if (!(len > 0) || !origin.allFinite()) return out;
  const Eigen::Vector3d dir = dir_in / len;
  ContextWithData c;
  rtcInitIntersectContext(&c.ctx);
  c.data = {&impl_->F, skip_vertex};
  RTCRayHit rh;
  rh.ray.org_x = float(origin.x());
  rh.ray.org_y = float(origin.y());
  rh.ray.org_z = float(origin.z());
  rh.ray.dir_x = float(dir.x());
  rh.ray.dir_y = float(dir.y());
  rh.ray.dir_z = float(dir.z());
  rh.ray.tnear = float(t_near);
  rh.ray.tfar = float(std::min(t_far, double(std::numeric_limits<float>::max())));
  rh.ray.mask = 0xFFFFFFFFu;
  rh.ray.flags = 0;
  rh.ray.time = 0;
  rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
  rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
  rtcIntersect1(impl_->scene, &c.ctx, &rh);
  if (rh.hit.geomID == RTC_INVALID_GEOMETRY_ID) return out;
  const int f = int(rh.hit.primID);
  const auto& V = impl_->V;
  const auto& F = impl_->F;
  const Eigen::Vector3d a = V.row(F(f, 0)).transpose(), b = V.row(F(f, 1)).transpose(), cc = V.row(F(f, 2)).transpose();
  double t, u, v;
  out.face = f;
  if (intersect(origin, dir, a, b, cc, t, u, v)) {
    u = std::min(std::max(u, 0.0), 1.0);
    v = std::min(std::max(v, 0.0), 1.0 - u);
    out.t = t;
    out.bary = Eigen::Vector3d(1 - u - v, u, v);
  } else {  // a grazing hit Embree accepted in single precision: keep its coordinates
    const double uu = rh.hit.u, vv = rh.hit.v;
    out.t = rh.ray.tfar;
    out.bary = Eigen::Vector3d(1 - uu - vv, uu, vv);
  }
  return out;
}

bool RayCaster::blocked(const Eigen::Vector3d& a, const Eigen::Vector3d& b, double margin) const {
  const Eigen::Vector3d d = b - a;
  const double len = d.norm();
  if (len <= 2 * margin) return false;
  ContextWithData c;
  rtcInitIntersectContext(&c.ctx);
  c.data = {&impl_->F, -1};
  RTCRay ray;
  const Eigen::Vector3d u = d / len;
  ray.org_x = float(a.x());
  ray.org_y = float(a.y());
  ray.org_z = float(a.z());
  ray.dir_x = float(u.x());
  ray.dir_y = float(u.y());
  ray.dir_z = float(u.z());
  ray.tnear = float(margin);
  ray.tfar = float(len - margin);
  ray.mask = 0xFFFFFFFFu;
  ray.flags = 0;
  ray.time = 0;
  rtcOccluded1(impl_->scene, &c.ctx, &ray);
  return ray.tfar < 0;  // Embree sets tfar = -inf on a hit
}

}  // namespace detail
}  // namespace tbsp
