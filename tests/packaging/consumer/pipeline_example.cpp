// A PCL pipeline with tbsp in the middle, as a user writes it against the installed package:
// tbsp::read_cloud_normals (PCL's PLY reader takes float coordinates only) -> pcl::VoxelGrid ->
// pcl::StatisticalOutlierRemoval -> tbsp::TemplateFitting -> pcl::io::savePLYFile.
//   pipeline_example SCAN.ply TEMPLATE.off MARKERS.json OUT.ply
#include <pcl/PolygonMesh.h>
#include <pcl/filters/statistical_outlier_removal.h>
#include <pcl/filters/voxel_grid.h>
#include <pcl/io/ply_io.h>
#include <pcl/point_types.h>

#include <iostream>

#include <tbsp/fitting/template_fitting.h>
#include <tbsp/io/cloud_io.h>
#include <tbsp/io/mesh_io.h>
#include <tbsp/plugins/fit_json.h>

int run(char** argv) {
  const pcl::PointCloud<pcl::PointNormal>::Ptr scan = tbsp::read_cloud_normals(argv[1]);
  // markers name points of the raw scan: keep their positions, the indices change when filtering
  std::vector<tbsp::FitMarker> markers = tbsp::load_markers_json(argv[3]);
  for (auto& m : markers) {
    const auto& p = scan->at(std::size_t(m.cloud_index));
    m.position = Eigen::Vector3d(p.x, p.y, p.z);
    m.cloud_index = -1;
  }
  pcl::PointCloud<pcl::PointNormal>::Ptr thinned(new pcl::PointCloud<pcl::PointNormal>);
  pcl::VoxelGrid<pcl::PointNormal> grid;
  grid.setInputCloud(scan);
  grid.setLeafSize(0.02f, 0.02f, 0.02f);
  grid.filter(*thinned);
  pcl::PointCloud<pcl::PointNormal>::Ptr clean(new pcl::PointCloud<pcl::PointNormal>);
  pcl::StatisticalOutlierRemoval<pcl::PointNormal> sor;  // the scan has 5 % uniform outliers
  sor.setInputCloud(thinned);
  sor.setMeanK(8);
  sor.setStddevMulThresh(1.0);
  sor.filter(*clean);

  tbsp::TemplateFitting<pcl::PointNormal> fit;
  fit.setInputCloud(clean);
  fit.setInputTemplate(tbsp::read_mesh(argv[2]));
  fit.setMarkers(markers);
  pcl::PolygonMesh out;
  const tbsp::FitReport rep = fit.reconstruct(out);
  if (pcl::io::savePLYFile(argv[4], out) != 0) return 1;
  std::cout << scan->size() << " -> " << thinned->size() << " -> " << clean->size() << " points; hausdorff_rel " << rep.hausdorff_rel << " rms_rel "
            << rep.rms / rep.bbox_diagonal << "\n";
  return 0;
}

int main(int argc, char** argv) {
  if (argc != 5) {
    std::cerr << "usage: pipeline_example SCAN TEMPLATE MARKERS.json OUT.ply\n";
    return 2;
  }
  try {
    return run(argv);
  } catch (const std::exception& e) {
    std::cerr << "pipeline_example: " << e.what() << "\n";
    return 1;
  }
}
