// Orientation of a mesh's faces against a reference surface: exact segment probes over CGAL's
// AABB tree (see check_orientation_against in mesh_validation.h).
#include <CGAL/AABB_traits.h>
#include <CGAL/AABB_tree.h>
#include <CGAL/AABB_triangle_primitive.h>
#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>

#include <algorithm>
#include <cmath>
#include <iterator>
#include <string>
#include <vector>

#include <Eigen/Geometry>

#include "tbsp/core/error.h"
#include "tbsp/mesh/mesh_validation.h"

namespace tbsp {

namespace {
using K = CGAL::Exact_predicates_inexact_constructions_kernel;
using Triangle = K::Triangle_3;
using Iterator = std::vector<Triangle>::const_iterator;
using Primitive = CGAL::AABB_triangle_primitive<K, Iterator>;
using Tree = CGAL::AABB_tree<CGAL::AABB_traits<K, Primitive>>;

void check_mesh(const Eigen::MatrixX3d& V, const Eigen::MatrixX3i& F, const std::string& who, const std::string& name) {
  if (F.rows() == 0) throw InvalidInput(who + "the " + name + " has no faces");
  if (!V.allFinite())
    throw InvalidInput(who + "the " + name + " has non-finite vertex coordinates; remove or repair those vertices");
  for (Eigen::Index f = 0; f < F.rows(); ++f)
    for (int k = 0; k < 3; ++k)
      if (F(f, k) < 0 || F(f, k) >= V.rows())
        throw InvalidInput(who + "face " + std::to_string(f) + " of the " + name + " has vertex index " +
                           std::to_string(F(f, k)) + " outside 0.." + std::to_string(V.rows() - 1));
}
}  // namespace

ReferenceOrientation check_orientation_against(const Eigen::MatrixX3d& V, const Eigen::MatrixX3i& F,
                                               const Eigen::MatrixX3d& refV, const Eigen::MatrixX3i& refF,
                                               double distance) {
  const std::string who = "[tbsp::check_orientation_against] ";
  check_mesh(V, F, who, "mesh");
  check_mesh(refV, refF, who, "reference");
  if (!(distance > 0) || !std::isfinite(distance))
    throw InvalidInput(who + "the probe distance must be positive and finite (got " + std::to_string(distance) +
                       "); 0.1 % of the reference's bounding-box diagonal suits a close fit");
  std::vector<Triangle> tris;
  std::vector<Eigen::Vector3d> ref_normals;  // unnormalised: only the sign of a dot product is used
  tris.reserve(std::size_t(refF.rows()));
  ref_normals.reserve(std::size_t(refF.rows()));
  for (Eigen::Index f = 0; f < refF.rows(); ++f) {
    const Eigen::Vector3d a = refV.row(refF(f, 0)), b = refV.row(refF(f, 1)), c = refV.row(refF(f, 2));
    tris.emplace_back(K::Point_3(a(0), a(1), a(2)), K::Point_3(b(0), b(1), b(2)), K::Point_3(c(0), c(1), c(2)));
    ref_normals.push_back((b - a).cross(c - a));
  }
  Tree tree(tris.cbegin(), tris.cend());
  tree.build();
  std::vector<signed char> verdict(std::size_t(F.rows()), 0);  // 1 consistent, -1 flipped, 0 unmatched, 2 degenerate
#pragma omp parallel for schedule(dynamic, 256)
  for (Eigen::Index f = 0; f < F.rows(); ++f) {
    const Eigen::Vector3d a = V.row(F(f, 0)), b = V.row(F(f, 1)), c = V.row(F(f, 2));
    Eigen::Vector3d n = (b - a).cross(c - a);
    const double len = n.norm();
    if (!(len > 0)) {
      verdict[std::size_t(f)] = 2;
      continue;
    }
    n /= len;
    const Eigen::Vector3d m = (a + b + c) / 3.0, p0 = m - distance * n, p1 = m + distance * n;
    const K::Segment_3 probe(K::Point_3(p0(0), p0(1), p0(2)), K::Point_3(p1(0), p1(1), p1(2)));
    std::vector<Primitive::Id> hits;
    tree.all_intersected_primitives(probe, std::back_inserter(hits));
    int sum = 0;
    for (const Primitive::Id& id : hits) {
      const double d = ref_normals[std::size_t(std::distance(tris.cbegin(), id))].dot(n);
      sum += d > 0 ? 1 : d < 0 ? -1 : 0;
    }
    verdict[std::size_t(f)] = sum > 0 ? 1 : sum < 0 ? -1 : 0;
  }
  ReferenceOrientation r;
  r.distance = distance;
  for (Eigen::Index f = 0; f < F.rows(); ++f) switch (verdict[std::size_t(f)]) {
      case 1: ++r.consistent; break;
      case -1: ++r.flipped; r.flipped_faces.push_back(int(f)); break;
      case 2: ++r.degenerate; break;
      default: ++r.unmatched;
    }
  return r;
}

}  // namespace tbsp
