// Built-in PCL filters wrapped as stages: pcl.voxel-grid, pcl.statistical-outlier-removal,
// pcl.pass-through. The filtering is PCL's own (pcl::VoxelGrid, pcl::StatisticalOutlierRemoval,
// pcl::PassThrough on pcl::PointNormal); these classes only map parameters and check inputs.
#include <pcl/common/common.h>
#include <pcl/filters/passthrough.h>
#include <pcl/filters/statistical_outlier_removal.h>
#include <pcl/filters/voxel_grid.h>

#include <cmath>
#include <limits>
#include <sstream>

#include "stage_util.h"

namespace tbsp::pipeline::builtin {
namespace {

Ports cloud_out(CloudN::Ptr c, bool normals, const std::string& what) {
  if (c->empty()) throw InvalidInput(what + " removed every point (loosen its parameters)");
  return {{"cloud", Data::of(c, normals)}};
}

class VoxelGrid : public Stage {
public:
  explicit VoxelGrid(const Params& p) : leaf_(float(p.real("leaf"))) {}
  Ports process(FrameContext&, const Ports& in) override {
    const Data& d = in.at("cloud");
    // PCL silently returns the input when the voxel indices would overflow: say so instead.
    pcl::PointNormal lo, hi;
    pcl::getMinMax3D(*d.cloud, lo, hi);
    const double cells = (double(hi.x - lo.x) / leaf_ + 1) * (double(hi.y - lo.y) / leaf_ + 1) * (double(hi.z - lo.z) / leaf_ + 1);
    if (cells > double(std::numeric_limits<std::int32_t>::max()))
    {
      std::ostringstream os;
      os << "leaf " << leaf_ << " is too small for a cloud this large (" << cells << " voxels; PCL's limit is 2^31): raise 'leaf'";
      throw InvalidInput(os.str());
    }
    pcl::VoxelGrid<pcl::PointNormal> f;
    f.setInputCloud(d.cloud);
    f.setLeafSize(leaf_, leaf_, leaf_);
    CloudN::Ptr out(new CloudN);
    f.filter(*out);
    if (d.has_normals)  // voxel centroids average the normals: make them unit again
      for (auto& q : *out) {
        const float n = std::sqrt(q.normal_x * q.normal_x + q.normal_y * q.normal_y + q.normal_z * q.normal_z);
        if (n > 0) { q.normal_x /= n; q.normal_y /= n; q.normal_z /= n; }
      }
    return cloud_out(out, d.has_normals, "pcl.voxel-grid");
  }

private:
  float leaf_;
};

class OutlierRemoval : public Stage {
public:
  explicit OutlierRemoval(const Params& p) : k_(int(p.integer("mean_k"))), stddev_(p.real("stddev")) {}
  Ports process(FrameContext&, const Ports& in) override {
    const Data& d = in.at("cloud");
    pcl::StatisticalOutlierRemoval<pcl::PointNormal> f;
    f.setInputCloud(d.cloud);
    f.setMeanK(k_);
    f.setStddevMulThresh(stddev_);
    CloudN::Ptr out(new CloudN);
    f.filter(*out);
    return cloud_out(out, d.has_normals, "pcl.statistical-outlier-removal");
  }

private:
  int k_;
  double stddev_;
};

class PassThrough : public Stage {
public:
  explicit PassThrough(const Params& p)
      : field_(p.text("field")), lo_(float(p.real("min"))), hi_(float(p.real("max"))), negative_(p.boolean("negative")) {
    if (lo_ > hi_) throw InvalidInput("'min' (" + std::to_string(lo_) + ") is above 'max' (" + std::to_string(hi_) + ")");
  }
  Ports process(FrameContext&, const Ports& in) override {
    const Data& d = in.at("cloud");
    pcl::PassThrough<pcl::PointNormal> f(true);  // removed indices kept: needed for keep-organized, and no warning
    f.setInputCloud(d.cloud);
    f.setFilterFieldName(field_);
    f.setFilterLimits(lo_, hi_);
    f.setNegative(negative_);
    f.setKeepOrganized(d.cloud->height > 1);  // a depth grid stays a grid (removed pixels become NaN)
    CloudN::Ptr out(new CloudN);
    f.filter(*out);
    return cloud_out(out, d.has_normals, "pcl.pass-through");
  }

private:
  std::string field_;
  float lo_, hi_;
  bool negative_;
};

// Concatenates up to eight clouds (e.g. the range scans of several cameras of one frame).
class Merge : public Stage {
public:
  Ports process(FrameContext&, const Ports& in) override {
    CloudN::Ptr out(new CloudN);
    bool normals = true;
    for (const auto& [port, d] : in) {
      *out += *d.cloud;
      normals = normals && d.has_normals;
    }
    return cloud_out(out, normals, "merge-clouds");
  }
};

}  // namespace

void register_pcl_stages(Registry& r) {
  const PortSpec in{"cloud", DataType::Cloud, "input cloud"};
  const PortSpec out{"cloud", DataType::Cloud, "filtered cloud"};
  {
    StageInfo s{"pcl.voxel-grid", "pcl::VoxelGrid: one point (the centroid) per occupied voxel"};
    s.params = {ParamSpec::real("leaf", "", "voxel edge length, in the cloud's units (metres for depth sensors)", 1e-9, 1e9)};
    s.params[0].required = true;
    s.inputs = {in};
    s.outputs = {out};
    r.add(s, [](const Params& p) { return std::make_unique<VoxelGrid>(p); });
  }
  {
    StageInfo s{"pcl.statistical-outlier-removal",
                "pcl::StatisticalOutlierRemoval: drops points whose mean distance to their k neighbours is far above the average"};
    s.params = {ParamSpec::integer("mean_k", "8", "neighbours per point", 1, 10000),
                ParamSpec::real("stddev", "1", "threshold in standard deviations of the mean distance", 0, 1e6)};
    s.inputs = {in};
    s.outputs = {out};
    r.add(s, [](const Params& p) { return std::make_unique<OutlierRemoval>(p); });
  }
  {
    StageInfo s{"pcl.pass-through", "pcl::PassThrough: keeps the points whose x, y or z lies in [min, max] (or outside, with negative); an organized cloud stays organized"};
    s.params = {ParamSpec::text("field", "z", "coordinate to test", {"x", "y", "z"}),
                ParamSpec::real("min", "-1e30", "lower limit (inclusive)", -1e30, 1e30),
                ParamSpec::real("max", "1e30", "upper limit (inclusive)", -1e30, 1e30),
                ParamSpec::boolean("negative", false, "keep the points outside the limits instead")};
    s.inputs = {in};
    s.outputs = {out};
    r.add(s, [](const Params& p) { return std::make_unique<PassThrough>(p); });
  }
  {
    StageInfo s{"merge-clouds", "concatenates up to eight clouds of the same frame (e.g. the range scans of several cameras)"};
    s.inputs = {{"a", DataType::Cloud, "first cloud"}};
    for (const char* n : {"b", "c", "d", "e", "f", "g", "h"}) s.inputs.push_back({n, DataType::Cloud, "another cloud", true});
    s.outputs = {{"cloud", DataType::Cloud, "all points (normals kept when every input has them)"}};
    r.add(s, [](const Params&) { return std::make_unique<Merge>(); });
  }
}

}  // namespace tbsp::pipeline::builtin
