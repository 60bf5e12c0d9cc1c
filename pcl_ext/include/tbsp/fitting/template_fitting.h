#pragma once
/// \file template_fitting.h
/// \brief tbsp::TemplateFitting<PointT>: reconstruct an incomplete scan by deforming a template
/// (thesis ch. 5 + §5.5). PCL-style front end of fit_template() (template_fitter.h).
///
/// \code
/// tbsp::TemplateFitting<pcl::PointNormal> fit;
/// fit.setInputCloud(scan);                 // normals used as given (oriented)
/// fit.setInputTemplate(template_mesh);     // pcl::PolygonMesh or tbsp::TriMesh
/// fit.setMarkers({{120, 5031}, {877, 12}, ...});
/// pcl::PolygonMesh out;
/// tbsp::FitReport r = fit.reconstruct(out);   // r.hausdorff_rel, r.iterations, timings ...
/// \endcode
/// Point types without normals (e.g. pcl::PointXYZ) get normals from PCL's NormalEstimationOMP
/// (k nearest neighbours), oriented consistently with the posed template.
/// Instantiated for pcl::PointXYZ, pcl::PointNormal and pcl::PointXYZRGBNormal; other types:
/// include tbsp/fitting/impl/template_fitting.hpp.
///
/// Stopping: the largest vertex move of an iteration falls below `tolerance` (after the search
/// radius reached its final value), or `max_iterations`. Status NotConverged says which.
/// Errors (tbsp::InvalidInput, output untouched): empty cloud, no finite point, markers on missing
/// vertices or points, constraints that leave the system singular, invalid parameters.

#include <pcl/PolygonMesh.h>
#include <pcl/pcl_base.h>
#include <pcl/point_cloud.h>

#include <memory>
#include <vector>

#include "tbsp/fitting/template_fitter.h"

namespace tbsp {

template <typename PointT>
class TemplateFitting : public pcl::PCLBase<PointT> {
public:
  using Ptr = std::shared_ptr<TemplateFitting<PointT>>;
  using ConstPtr = std::shared_ptr<const TemplateFitting<PointT>>;
  using PointCloud = pcl::PointCloud<PointT>;
  using Options = FitParameters;
  using pcl::PCLBase<PointT>::input_;
  using pcl::PCLBase<PointT>::indices_;

  TemplateFitting() = default;

  /// Template mesh (validated at reconstruct()).
  void setInputTemplate(const TriMesh& mesh) { template_ = mesh; }
  void setInputTemplate(const pcl::PolygonMesh& mesh);
  const TriMesh& getInputTemplate() const { return template_; }

  /// Marker cloud indices refer to the input cloud (not to the indices subset).
  void setMarkers(const std::vector<FitMarker>& markers) { markers_ = markers; }
  const std::vector<FitMarker>& getMarkers() const { return markers_; }

  /// \throws InvalidInput when !p.isValid().
  void setParameters(const FitParameters& p);
  const FitParameters& getParameters() const { return params_; }
  /// The same under the names every tbsp class uses (docs/conventions.md).
  void setOptions(const FitParameters& p) { setParameters(p); }
  const FitParameters& options() const { return params_; }
  void setMaxMatchDistance(double r) { FitParameters p = params_; p.max_match_distance = r; setParameters(p); }
  void setMaxNormalAngle(double deg) { FitParameters p = params_; p.max_normal_angle_deg = deg; setParameters(p); }

  void setRegionOfInterest(const RegionOfInterest& roi) { roi_ = roi; }
  /// Called with (fraction, stage); return false to cancel (reconstruct throws tbsp::Cancelled).
  void setProgressCallback(ProgressCallback cb) { progress_ = std::move(cb); }

  /// \brief Runs the fit. On any exception `output` is left untouched.
  FitReport reconstruct(TriMesh& output);
  FitReport reconstruct(pcl::PolygonMesh& output);

  /// The report of the last successful reconstruct() (also its return value).
  const FitReport& report() const { return report_; }

  /// Per output vertex: matched / propagated / masked / unmatched (last reconstruct()).
  const std::vector<VertexStatus>& getVertexStatus() const { return status_; }

private:
  TriMesh template_;
  std::vector<FitMarker> markers_;
  FitParameters params_;
  RegionOfInterest roi_;
  ProgressCallback progress_;
  std::vector<VertexStatus> status_;
  FitReport report_;
};

}  // namespace tbsp

#ifdef PCL_NO_PRECOMPILE
#include "tbsp/fitting/impl/template_fitting.hpp"
#endif
