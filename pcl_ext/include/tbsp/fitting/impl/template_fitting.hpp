#pragma once
// Template bodies of tbsp::TemplateFitting<PointT>: a thin layer over fit_template().
#include <pcl/common/point_tests.h>
#include <pcl/features/normal_3d_omp.h>
#include <pcl/search/kdtree.h>

#include <type_traits>

#include "tbsp/core/error.h"
#include "tbsp/fitting/template_fitting.h"
#include "tbsp/mesh/pcl_conversions.h"

namespace tbsp {

template <typename PointT>
void TemplateFitting<PointT>::setInputTemplate(const pcl::PolygonMesh& mesh) {
  template_ = from_pcl(mesh);
}

template <typename PointT>
void TemplateFitting<PointT>::setParameters(const FitParameters& p) {
  std::string why;
  if (!p.isValid(&why)) throw InvalidInput("[tbsp::TemplateFitting::setParameters] " + why);
  params_ = p;
}

template <typename PointT>
FitReport TemplateFitting<PointT>::reconstruct(TriMesh& output) {
  if (!input_ || input_->empty())
    throw InvalidInput("[tbsp::TemplateFitting::reconstruct] no input cloud, or it is empty; call setInputCloud()");
  if (!this->initCompute()) throw InvalidInput("[tbsp::TemplateFitting::reconstruct] invalid input indices");
  // The kernel works on the whole cloud (marker indices refer to it); points outside the
  // indices subset are excluded from matching through the region of interest.
  const auto& cloud = *input_;
  const Eigen::Index n = Eigen::Index(cloud.size());
  Eigen::MatrixX3d P(n, 3), N;
  for (Eigen::Index i = 0; i < n; ++i) P.row(i) << cloud[std::size_t(i)].x, cloud[std::size_t(i)].y, cloud[std::size_t(i)].z;
  RegionOfInterest roi = roi_;
  if (this->use_indices_ && indices_->size() != cloud.size()) {
    std::vector<char> in(cloud.size(), 0);
    for (auto i : *indices_) in[std::size_t(i)] = 1;
    for (std::size_t i = 0; i < cloud.size(); ++i)
      if (!in[i]) roi.exclude_cloud_points.push_back(Eigen::Index(i));
  }
  if constexpr (pcl::traits::has_normal_v<PointT>) {
    N.resize(n, 3);
    for (Eigen::Index i = 0; i < n; ++i)
      N.row(i) << cloud[std::size_t(i)].normal_x, cloud[std::size_t(i)].normal_y, cloud[std::size_t(i)].normal_z;
  } else {
    // PCL normal estimation on the finite points; the kernel orients them by the posed template
    typename pcl::PointCloud<PointT>::Ptr finite(new pcl::PointCloud<PointT>);
    std::vector<Eigen::Index> map;
    for (Eigen::Index i = 0; i < n; ++i)
      if (pcl::isFinite(cloud[std::size_t(i)])) { finite->push_back(cloud[std::size_t(i)]); map.push_back(i); }
    if (finite->size() >= 3) {
      pcl::NormalEstimationOMP<PointT, pcl::Normal> ne;
      ne.setInputCloud(finite);
      ne.setSearchMethod(typename pcl::search::KdTree<PointT>::Ptr(new pcl::search::KdTree<PointT>));
      ne.setKSearch(params_.normal_neighbours);
      pcl::PointCloud<pcl::Normal> normals;
      ne.compute(normals);
      N = Eigen::MatrixX3d::Constant(n, 3, std::numeric_limits<double>::quiet_NaN());
      for (std::size_t k = 0; k < map.size(); ++k)
        N.row(map[k]) << normals[k].normal_x, normals[k].normal_y, normals[k].normal_z;
    }
  }
  TriMesh result;
  std::vector<VertexStatus> status;
  FitReport r = fit_template(template_, P, N, markers_, roi, params_, result, status, progress_,
                             /*orient_normals=*/!pcl::traits::has_normal_v<PointT>);
  if constexpr (!pcl::traits::has_normal_v<PointT>) r.normals_estimated = true;
  output = std::move(result);
  status_ = std::move(status);
  report_ = r;
  this->deinitCompute();
  return r;
}

template <typename PointT>
FitReport TemplateFitting<PointT>::reconstruct(pcl::PolygonMesh& output) {
  TriMesh m;
  FitReport r = reconstruct(m);
  output = to_pcl(m);
  return r;
}

}  // namespace tbsp

#define TBSP_INSTANTIATE_TemplateFitting(T) template class tbsp::TemplateFitting<T>;
