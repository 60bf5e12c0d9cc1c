// Self-intersection test of a triangle mesh with CGAL (exact predicates).
#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/Polygon_mesh_processing/self_intersections.h>
#include <CGAL/Surface_mesh.h>

#include <algorithm>
#include <string>
#include <vector>

#include "tbsp/core/error.h"
#include "tbsp/mesh/mesh_validation.h"

namespace tbsp {

int count_self_intersections(const Eigen::MatrixX3d& V, const Eigen::MatrixX3i& F, std::vector<std::pair<int, int>>* pairs,
                             int* degenerate_faces) {
  using K = CGAL::Exact_predicates_inexact_constructions_kernel;
  using Mesh = CGAL::Surface_mesh<K::Point_3>;
  const std::string who = "[tbsp::count_self_intersections] ";
  if (pairs) pairs->clear();
  if (degenerate_faces) *degenerate_faces = 0;
  if (!V.allFinite()) throw InvalidInput(who + "the mesh has non-finite vertex coordinates; remove or repair those vertices");
  Mesh sm;
  std::vector<Mesh::Vertex_index> vi(static_cast<std::size_t>(V.rows()));
  for (Eigen::Index i = 0; i < V.rows(); ++i) vi[std::size_t(i)] = sm.add_vertex(K::Point_3(V(i, 0), V(i, 1), V(i, 2)));
  std::vector<int> face_of;  // Surface_mesh face index -> row of F
  face_of.reserve(std::size_t(F.rows()));
  for (Eigen::Index f = 0; f < F.rows(); ++f) {
    for (int k = 0; k < 3; ++k)
      if (F(f, k) < 0 || F(f, k) >= V.rows())
        throw InvalidInput(who + "face " + std::to_string(f) + " has vertex index " + std::to_string(F(f, k)) +
                           " outside 0.." + std::to_string(V.rows() - 1));
    const Mesh::Face_index fi = sm.add_face(vi[std::size_t(F(f, 0))], vi[std::size_t(F(f, 1))], vi[std::size_t(F(f, 2))]);
    if (fi == Mesh::null_face())
      throw InvalidInput(who + "face " + std::to_string(f) +
                         " cannot be added: the faces do not form a consistently oriented manifold triangle mesh (a repeated "
                         "vertex, an edge used by more than two faces or twice in the same direction); check the mesh "
                         "with validate_mesh()");
    face_of.push_back(int(f));
  }
  std::vector<std::pair<Mesh::Face_index, Mesh::Face_index>> found;
  CGAL::Polygon_mesh_processing::self_intersections<CGAL::Parallel_if_available_tag>(sm, std::back_inserter(found));
  int count = 0;
  for (const auto& [a, b] : found) {
    const int fa = face_of[std::size_t(a)], fb = face_of[std::size_t(b)];
    if (fa == fb) {  // CGAL reports a degenerate face as (f, f)
      if (degenerate_faces) ++*degenerate_faces;
      continue;
    }
    ++count;
    if (pairs) pairs->emplace_back(std::min(fa, fb), std::max(fa, fb));
  }
  if (pairs) std::sort(pairs->begin(), pairs->end());
  return count;
}

}  // namespace tbsp
