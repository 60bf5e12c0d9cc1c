// tbsp::Visualizer from a PCL program, the way PCLVisualizer is used: a scan as a
// pcl::PointCloud<pcl::PointXYZ> coloured by its distance to a fitted mesh (a fit-error heatmap),
// the mesh beside it, written offscreen to a PNG.
//   tbsp_viz_example SCAN.(ply|pcd) FIT.(ply|obj|off) OUT.png
// Needs an X display (xvfb-run -a on a headless machine).
#include <iostream>
#include <pcl/point_cloud.h>
#include <pcl/point_types.h>

#include "tbsp/io/cloud_io.h"
#include "tbsp/io/mesh_io.h"
#include "tbsp/mesh/point_mesh_distance.h"
#include "tbsp/vtk/visualizer.h"

int main(int argc, char** argv) {
  if (argc != 4) {
    std::cerr << "usage: " << argv[0] << " SCAN FIT_MESH OUT.png\n";
    return 2;
  }
  try {
    pcl::PointCloud<pcl::PointXYZ> cloud;
    for (const auto& p : *tbsp::read_cloud_normals(argv[1])) cloud.push_back(pcl::PointXYZ(p.x, p.y, p.z));
    const tbsp::TriMesh fit = tbsp::read_mesh(argv[2]);
    Eigen::MatrixX3d P(Eigen::Index(cloud.size()), 3);
    for (std::size_t i = 0; i < cloud.size(); ++i) P.row(Eigen::Index(i)) << cloud[i].x, cloud[i].y, cloud[i].z;
    const Eigen::VectorXd d = tbsp::point_mesh_distances(fit.V, fit.F, P) * (100.0 / tbsp::bbox_diagonal(fit.V));

    tbsp::VisualizerOptions o;
    o.offscreen = true;
    tbsp::Visualizer viz(o);
    viz.addPointCloud("scan", cloud, 4.0);
    viz.setScalars("scan", d, {"scan -> fit (% of diagonal)", tbsp::ColorMap::Viridis, 0.0, 1.0});
    viz.addMesh("fit", fit);
    viz.setOpacity("fit", 0.5);
    viz.resetCamera();
    viz.saveScreenshot(argv[3]);
    std::cout << "points " << cloud.size() << " max " << d.maxCoeff() << " mean " << d.mean() << " -> " << argv[3] << "\n";
    return 0;
  } catch (const std::exception& e) {
    std::cerr << "tbsp_viz_example: error: " << e.what() << "\n";
    return 2;
  }
}
