#include <tbsp/deform/laplacian_deformer.h>
#include <tbsp/mesh/primitives.h>
#include <iostream>
int main() {
  auto m = tbsp::make_icosphere(2);
  tbsp::LaplacianDeformer d; d.setMesh(m);
  d.addPositionConstraint(tbsp::SurfacePoint::atVertex(0), Eigen::Vector3d(0, 0, 2));
  std::cout << d.deform().row(0) << "\n";
}
