#pragma once
// Shared by the built-in stages (not installed): cloud conversions and the registration entry
// points of each stage group.
#include <pcl/point_cloud.h>
#include <pcl/point_types.h>

#include <cmath>

#include "tbsp/plugins/stage.h"

namespace tbsp::pipeline::builtin {

using CloudN = pcl::PointCloud<pcl::PointNormal>;

/// Unorganized copy of the finite points of `in` with zero normals.
template <class PointT>
CloudN::Ptr finite_points(const pcl::PointCloud<PointT>& in) {
  CloudN::Ptr out(new CloudN);
  out->reserve(in.size());
  for (const auto& q : in)
    if (std::isfinite(q.x) && std::isfinite(q.y) && std::isfinite(q.z)) {
      pcl::PointNormal p;
      p.x = q.x;
      p.y = q.y;
      p.z = q.z;
      p.normal_x = p.normal_y = p.normal_z = 0.f;
      p.curvature = 0.f;
      out->push_back(p);
    }
  out->width = std::uint32_t(out->size());
  out->height = 1;
  out->is_dense = true;
  return out;
}

/// The points of `in` with finite coordinates and finite normals.
inline CloudN::Ptr finite_normals(const CloudN& in) {
  CloudN::Ptr out(new CloudN);
  out->reserve(in.size());
  for (const auto& q : in)
    if (std::isfinite(q.x) && std::isfinite(q.normal_x) && std::isfinite(q.normal_y) && std::isfinite(q.normal_z)) out->push_back(q);
  out->width = std::uint32_t(out->size());
  out->height = 1;
  out->is_dense = true;
  return out;
}

void register_io_stages(Registry& r);
void register_pcl_stages(Registry& r);
void register_fit_stages(Registry& r);
void register_deform_stages(Registry& r);
void register_mesh_stages(Registry& r);
void register_texture_stages(Registry& r);

}  // namespace tbsp::pipeline::builtin
