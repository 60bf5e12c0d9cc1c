#include "tbsp/mesh/point_mesh_distance.h"

#include <CGAL/AABB_traits.h>
#include <CGAL/AABB_tree.h>
#include <CGAL/AABB_triangle_primitive.h>
#include <CGAL/Simple_cartesian.h>

#include <algorithm>
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

Eigen::Vector3d closest_point_barycentric(const Eigen::Vector3d& p, const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                                          const Eigen::Vector3d& c) {
  const Eigen::Vector3d ab = b - a, ac = c - a, ap = p - a;
  const double d1 = ab.dot(ap), d2 = ac.dot(ap);
  if (d1 <= 0 && d2 <= 0) return Eigen::Vector3d(1, 0, 0);
  const Eigen::Vector3d bp = p - b;
  const double d3 = ab.dot(bp), d4 = ac.dot(bp);
  if (d3 >= 0 && d4 <= d3) return Eigen::Vector3d(0, 1, 0);
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0 && d1 >= 0 && d3 <= 0 && d1 - d3 > 0) {
    const double v = d1 / (d1 - d3);
    return Eigen::Vector3d(1 - v, v, 0);
  }
  const Eigen::Vector3d cp = p - c;
  const double d5 = ab.dot(cp), d6 = ac.dot(cp);
  if (d6 >= 0 && d5 <= d6) return Eigen::Vector3d(0, 0, 1);
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0 && d2 >= 0 && d6 <= 0 && d2 - d6 > 0) {
    const double w = d2 / (d2 - d6);
    return Eigen::Vector3d(1 - w, 0, w);
  }
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0 && d4 - d3 >= 0 && d5 - d6 >= 0 && (d4 - d3) + (d5 - d6) > 0) {
    const double w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
    return Eigen::Vector3d(0, 1 - w, w);
  }
  const double denom = va + vb + vc;
  if (denom > 0) {
    const double v = vb / denom, w = vc / denom;
    return Eigen::Vector3d(1 - v - w, v, w);
  }
  // degenerate triangle: the closest point of its longest edge
  const Eigen::Vector3d e[3][2] = {{a, b}, {b, c}, {a, c}};
  int longest = 0;
  for (int k = 1; k < 3; ++k)
    if ((e[k][1] - e[k][0]).squaredNorm() > (e[longest][1] - e[longest][0]).squaredNorm()) longest = k;
  const Eigen::Vector3d s0 = e[longest][0], s1 = e[longest][1];
  const double len2 = (s1 - s0).squaredNorm();
  const double t = len2 > 0 ? std::clamp((p - s0).dot(s1 - s0) / len2, 0.0, 1.0) : 0.0;
  if (longest == 0) return Eigen::Vector3d(1 - t, t, 0);
  if (longest == 1) return Eigen::Vector3d(0, 1 - t, t);
  return Eigen::Vector3d(1 - t, 0, t);
}

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
