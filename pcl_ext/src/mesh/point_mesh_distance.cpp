#include "tbsp/mesh/point_mesh_distance.h"

#include <CGAL/AABB_traits.h>
#include <CGAL/AABB_tree.h>
#include <CGAL/AABB_triangle_primitive.h>
#include <CGAL/Simple_cartesian.h>

#include <vector>

#include "tbsp/core/error.h"

namespace tbsp {

namespace {
using K = CGAL::Simple_cartesian<double>;
using Triangle = K::Triangle_3;
using Iterator = std::vector<Triangle>::const_iterator;
using Primitive = CGAL::AABB_triangle_primitive<K, Iterator>;
using Tree = CGAL::AABB_tree<CGAL::AABB_traits<K, Primitive>>;
}  // namespace

struct MeshDistance::Impl {
  std::vector<Triangle> tris;
  Tree tree;
};

MeshDistance::MeshDistance(const Eigen::MatrixX3d& V, const Eigen::MatrixX3i& F) : impl_(std::make_unique<Impl>()) {
  if (F.rows() == 0) throw InvalidInput("[tbsp::MeshDistance] the mesh has no faces");
  impl_->tris.reserve(std::size_t(F.rows()));
  for (Eigen::Index f = 0; f < F.rows(); ++f) {
    auto p = [&](int k) { return K::Point_3(V(F(f, k), 0), V(F(f, k), 1), V(F(f, k), 2)); };
    impl_->tris.emplace_back(p(0), p(1), p(2));
  }
  impl_->tree.insert(impl_->tris.cbegin(), impl_->tris.cend());
  impl_->tree.build();
  impl_->tree.accelerate_distance_queries();
  // force the lazy internal structures to be built now, so concurrent queries only read
  (void)impl_->tree.closest_point(K::Point_3(V(0, 0), V(0, 1), V(0, 2)));
}

MeshDistance::~MeshDistance() = default;

Eigen::Vector3d MeshDistance::closest(const Eigen::Vector3d& q, int* face) const {
  const auto r = impl_->tree.closest_point_and_primitive(K::Point_3(q.x(), q.y(), q.z()));
  if (face) *face = int(r.second - impl_->tris.cbegin());
  return Eigen::Vector3d(r.first.x(), r.first.y(), r.first.z());
}

Eigen::VectorXd MeshDistance::distances(const Eigen::MatrixX3d& P, Eigen::VectorXi* faces) const {
  Eigen::VectorXd d(P.rows());
  if (faces) faces->resize(P.rows());
#pragma omp parallel for schedule(dynamic, 256)
  for (Eigen::Index i = 0; i < P.rows(); ++i) {
    int f = -1;
    const Eigen::Vector3d c = closest(P.row(i).transpose(), &f);
    d(i) = (c - P.row(i).transpose()).norm();
    if (faces) (*faces)(i) = f;
  }
  return d;
}

}  // namespace tbsp
