// Built-in stage pcl.organized-fast-mesh: pcl::OrganizedFastMesh triangulates the pixel grid of a
// depth image (read-depth's `grid` output), e.g. to make a template from a recording's first
// frame. The triangulation is PCL's; this file maps parameters, drops the pixels no triangle
// uses and the small pieces, and converts to tbsp::TriMesh.
#include <pcl/common/io.h>
#include <pcl/surface/organized_fast_mesh.h>

#include <sstream>

#include "stage_util.h"
#include "tbsp/mesh/topology.h"

namespace tbsp::pipeline::builtin {
namespace {

class OrganizedMesh : public Stage {
public:
  explicit OrganizedMesh(const Params& p)
      : step_(int(p.integer("pixel_step"))), max_edge_(float(p.real("max_edge"))), min_faces_(int(p.integer("min_faces"))) {}

  Ports process(FrameContext&, const Ports& in) override {
    const Data& d = in.at("cloud");
    if (d.cloud->height < 2 || d.cloud->width < 2)
      throw InvalidInput("the cloud is not organized (" + std::to_string(d.cloud->width) + " x " + std::to_string(d.cloud->height) +
                         "): connect read-depth's 'grid' output directly (filters drop the image layout)");
    // PCL's library instantiates OrganizedFastMesh for the XYZ types only
    pcl::PointCloud<pcl::PointXYZ>::Ptr xyz(new pcl::PointCloud<pcl::PointXYZ>);
    pcl::copyPointCloud(*d.cloud, *xyz);
    pcl::OrganizedFastMesh<pcl::PointXYZ> ofm;
    ofm.setInputCloud(xyz);
    ofm.setTrianglePixelSize(step_);
    ofm.setTriangulationType(pcl::OrganizedFastMesh<pcl::PointXYZ>::TRIANGLE_ADAPTIVE_CUT);
    ofm.setViewpoint(d.cloud->sensor_origin_.head<3>());
    if (max_edge_ > 0) ofm.setMaxEdgeLength(0.0f, max_edge_ * float(step_), 0.0f);  // grows with the distance to the sensor
    std::vector<pcl::Vertices> polys;
    ofm.reconstruct(polys);

    // faces on the pixels, then keep the components with at least min_faces faces
    Eigen::MatrixX3i F(Eigen::Index(polys.size()), 3);
    Eigen::Index nf = 0;
    for (const auto& poly : polys)
      if (poly.vertices.size() == 3) F.row(nf++) << int(poly.vertices[0]), int(poly.vertices[1]), int(poly.vertices[2]);
    F.conservativeResize(nf, 3);
    const Eigen::Index np = Eigen::Index(d.cloud->size());
    Eigen::VectorXi label;
    const int k = connected_components(F, np, label);
    std::vector<int> faces_of(std::size_t(k), 0);
    for (Eigen::Index f = 0; f < nf; ++f) ++faces_of[std::size_t(label(F(f, 0)))];
    std::vector<int> index(std::size_t(np), -1);
    auto mesh = std::make_shared<TriMesh>();
    mesh->F.resize(nf, 3);
    Eigen::Index kept = 0, nv = 0;
    std::vector<Eigen::Index> pixel_of;
    for (Eigen::Index f = 0; f < nf; ++f) {
      if (faces_of[std::size_t(label(F(f, 0)))] < min_faces_) continue;
      for (int c = 0; c < 3; ++c) {
        int& v = index[std::size_t(F(f, c))];
        if (v < 0) {
          v = int(nv++);
          pixel_of.push_back(F(f, c));
        }
        mesh->F(kept, c) = v;
      }
      ++kept;
    }
    mesh->F.conservativeResize(kept, 3);
    if (kept == 0) {
      std::ostringstream os;
      os << "the depth grid gave no piece of " << min_faces_ << " or more triangles (" << nf
         << " triangles in all): raise 'max_edge', lower 'pixel_step' or 'min_faces'";
      throw InvalidInput(os.str());
    }
    mesh->V.resize(nv, 3);
    for (Eigen::Index i = 0; i < nv; ++i) {
      const auto& q = (*d.cloud)[std::size_t(pixel_of[std::size_t(i)])];
      mesh->V.row(i) << q.x, q.y, q.z;
    }
    return {{"mesh", Data::of(std::shared_ptr<const TriMesh>(mesh))}};
  }

private:
  int step_;
  float max_edge_;
  int min_faces_;
};

}  // namespace

void register_mesh_stages(Registry& r) {
  StageInfo s{"pcl.organized-fast-mesh",
              "pcl::OrganizedFastMesh: triangulates a depth image's pixel grid (read-depth 'grid'), e.g. a template from the first frame"};
  s.params = {ParamSpec::integer("pixel_step", "4", "triangle size in pixels (every pixel_step-th row and column)", 1, 256),
              ParamSpec::real("max_edge", "0.01", "longest edge kept, per metre of distance to the sensor and per pixel step "
                                                  "(cuts the mesh at depth jumps; 0: no limit)", 0, 1e6),
              ParamSpec::integer("min_faces", "100", "pieces with fewer triangles are dropped", 1, 100000000)};
  s.inputs = {{"cloud", DataType::Cloud, "an organized cloud (width x height, NaN where no depth)"}};
  s.outputs = {{"mesh", DataType::Mesh, "the triangles between valid pixels (pixels no triangle uses are dropped)"}};
  r.add(s, [](const Params& p) { return std::make_unique<OrganizedMesh>(p); });
}

}  // namespace tbsp::pipeline::builtin
