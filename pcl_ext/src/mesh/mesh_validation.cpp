#include "tbsp/mesh/mesh_validation.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <functional>
#include <map>
#include <set>
#include <sstream>

#include "tbsp/core/error.h"
#include "tbsp/mesh/topology.h"

namespace tbsp {

namespace {

template <typename T>
std::string first_items(const std::vector<T>& v, std::size_t k = 5) {
  std::ostringstream s;
  for (std::size_t i = 0; i < std::min(k, v.size()); ++i) s << (i ? ", " : "") << v[i];
  if (v.size() > k) s << ", ... (" << v.size() << " in all)";
  return s.str();
}
std::string first_edges(const std::vector<std::pair<int, int>>& v, std::size_t k = 5) {
  std::ostringstream s;
  for (std::size_t i = 0; i < std::min(k, v.size()); ++i)
    s << (i ? ", " : "") << "(" << v[i].first << "," << v[i].second << ")";
  if (v.size() > k) s << ", ... (" << v.size() << " in all)";
  return s.str();
}

// What a mesh out of the solvers' range is told (the report's summary and require_valid_mesh).
std::string scale_problem(double extent, double diagonal) {
  char buf[320];
  std::snprintf(buf, sizeof buf,
                "the coordinates reach %.3g and the bounding box's diagonal is %.3g: outside [1e-50, 1e50] squared areas "
                "and the Laplacian's weights under- or overflow; scale the mesh to a sane unit (metres, millimetres)",
                extent, diagonal);
  return buf;
}

}  // namespace

bool MeshReport::isClean() const {
  return num_vertices > 0 && num_faces > 0 && !scale_out_of_range && nonfinite_vertices.empty() && bad_index_faces.empty() &&
         degenerate_faces.empty() && duplicate_faces.empty() && isolated_vertices.empty() &&
         nonmanifold_edges.empty() && inconsistent_edges.empty() && components <= 1;
}

std::string MeshReport::summary() const {
  std::ostringstream s;
  s << "vertices: " << num_vertices << ", faces: " << num_faces << ", components: " << components
    << ", boundary edges: " << boundary_edges << " in " << boundary_loops << " loop(s), Euler characteristic: "
    << euler_characteristic;
  if (genus >= 0) s << ", genus: " << genus;
  s << "\n";
  auto line = [&](const char* what, std::size_t n, const std::string& items) {
    if (n) s << "  " << what << ": " << n << " [" << items << "]\n";
  };
  if (scale_out_of_range) s << "  scale out of range: " << scale_problem(extent, diagonal) << "\n";
  line("non-finite vertices", nonfinite_vertices.size(), first_items(nonfinite_vertices));
  line("faces with out-of-range indices", bad_index_faces.size(), first_items(bad_index_faces));
  line("degenerate faces", degenerate_faces.size(), first_items(degenerate_faces));
  line("duplicate faces", duplicate_faces.size(), first_items(duplicate_faces));
  line("isolated vertices", isolated_vertices.size(), first_items(isolated_vertices));
  line("non-manifold edges", nonmanifold_edges.size(), first_edges(nonmanifold_edges));
  line("inconsistently oriented edges", inconsistent_edges.size(), first_edges(inconsistent_edges));
  return s.str();
}

MeshReport validate_mesh(const TriMesh& mesh) {
  MeshReport r;
  const auto& V = mesh.V;
  const auto& F = mesh.F;
  r.num_vertices = V.rows();
  r.num_faces = F.rows();
  for (Eigen::Index i = 0; i < V.rows(); ++i)
    if (!V.row(i).allFinite()) r.nonfinite_vertices.push_back(i);

  // Faces with bad indices are excluded from every further check.
  std::vector<Eigen::Index> good;
  good.reserve(std::size_t(F.rows()));
  for (Eigen::Index f = 0; f < F.rows(); ++f) {
    bool ok = true;
    for (int k = 0; k < 3; ++k) ok = ok && F(f, k) >= 0 && F(f, k) < V.rows();
    if (ok) good.push_back(f); else r.bad_index_faces.push_back(f);
  }
  const double diag = bbox_diagonal(V);
  for (Eigen::Index i = 0; i < V.rows(); ++i)
    if (V.row(i).allFinite()) r.extent = std::max(r.extent, V.row(i).cwiseAbs().maxCoeff());
  r.diagonal = diag;
  r.scale_out_of_range = r.extent > 1e50 || (diag > 0 && diag < 1e-50);  // (require_valid_mesh refuses it)
  const double area_eps = 1e-14 * diag * diag;
  std::vector<char> referenced(std::size_t(V.rows()), 0);
  // (sorted corners, face): sorted afterwards, every face after the first of an equal-corner
  // group is a duplicate (a sort instead of a std::map: no node allocation per face)
  std::vector<std::pair<std::array<int, 3>, Eigen::Index>> keyed;
  keyed.reserve(good.size());
  // directed half-edges (a,b) -> count; undirected -> count
  std::vector<std::pair<std::pair<int, int>, int>> half;  // ((min,max), +1 if a<b else -1)
  half.reserve(good.size() * 3);
  for (Eigen::Index f : good) {
    const int a = F(f, 0), b = F(f, 1), c = F(f, 2);
    referenced[std::size_t(a)] = referenced[std::size_t(b)] = referenced[std::size_t(c)] = 1;
    bool degenerate = a == b || b == c || a == c;
    // (areas are not measured at a scale out of range: they overflow or underflow, and every face
    // would be called degenerate; the report names the scale instead)
    if (!degenerate && !r.scale_out_of_range && V.row(a).allFinite() && V.row(b).allFinite() && V.row(c).allFinite()) {
      const Eigen::Vector3d pa = V.row(a), pb = V.row(b), pc = V.row(c);
      degenerate = 0.5 * (pb - pa).cross(pc - pa).norm() <= area_eps;
    }
    if (degenerate) r.degenerate_faces.push_back(f);
    std::array<int, 3> key{a, b, c};
    std::sort(key.begin(), key.end());
    keyed.push_back({key, f});
    for (int k = 0; k < 3; ++k) {
      int u = F(f, k), v = F(f, (k + 1) % 3);
      if (u == v) continue;
      half.push_back({{std::min(u, v), std::max(u, v)}, u < v ? 1 : -1});
    }
  }
  for (Eigen::Index i = 0; i < V.rows(); ++i)
    if (!referenced[std::size_t(i)]) r.isolated_vertices.push_back(i);
  std::sort(keyed.begin(), keyed.end());
  for (std::size_t i = 1; i < keyed.size(); ++i)
    if (keyed[i].first == keyed[i - 1].first) r.duplicate_faces.push_back(keyed[i].second);
  std::sort(r.duplicate_faces.begin(), r.duplicate_faces.end());  // in face order, as found

  // group the half-edges by undirected edge: bucketed by the smaller vertex (counting sort),
  // each bucket sorted by the larger one; edges are visited in (min, max) order
  std::vector<int> bucket_start(std::size_t(V.rows()) + 1, 0);
  for (const auto& h : half) ++bucket_start[std::size_t(h.first.first) + 1];
  for (std::size_t v = 0; v + 1 < bucket_start.size(); ++v) bucket_start[v + 1] += bucket_start[v];
  std::vector<std::pair<int, int>> by_min(half.size());  // (max, sign)
  {
    std::vector<int> fill(bucket_start.begin(), bucket_start.end() - 1);
    for (const auto& h : half) by_min[std::size_t(fill[std::size_t(h.first.first)]++)] = {h.first.second, h.second};
  }
  Eigen::Index num_edges = 0;
  std::vector<std::pair<int, int>> boundary;
  for (int a = 0; a + 1 < int(bucket_start.size()); ++a) {
    const auto first = by_min.begin() + bucket_start[std::size_t(a)], last = by_min.begin() + bucket_start[std::size_t(a) + 1];
    std::sort(first, last);
    for (auto i = first; i != last;) {
      auto j = i;
      int fwd = 0, bwd = 0;
      while (j != last && j->first == i->first) {
        (j->second > 0 ? fwd : bwd)++;
        ++j;
      }
      ++num_edges;
      const int n = fwd + bwd;
      const std::pair<int, int> e{a, i->first};
      if (n == 1) boundary.push_back(e);
      if (n > 2) r.nonmanifold_edges.push_back(e);
      if (n == 2 && (fwd == 2 || bwd == 2)) r.inconsistent_edges.push_back(e);
      i = j;
    }
  }
  r.boundary_edges = Eigen::Index(boundary.size());
  // Boundary loops: components of the boundary-edge graph.
  if (!boundary.empty()) {
    std::map<int, int> parent;
    std::function<int(int)> find = [&](int x) {
      auto it = parent.find(x);
      if (it == parent.end()) { parent[x] = x; return x; }
      if (it->second == x) return x;
      int root = find(it->second);
      parent[x] = root;
      return root;
    };
    for (auto& e : boundary) {
      int a = find(e.first), b = find(e.second);
      if (a != b) parent[a] = b;
    }
    std::set<int> roots;
    for (auto& kv : parent) roots.insert(find(kv.first));
    r.boundary_loops = Eigen::Index(roots.size());
  }
  Eigen::MatrixX3i G(Eigen::Index(good.size()), 3);
  for (std::size_t i = 0; i < good.size(); ++i) G.row(Eigen::Index(i)) = F.row(good[i]);
  Eigen::VectorXi labels;
  const int k = connected_components(G, V.rows(), labels);
  r.components = k - Eigen::Index(r.isolated_vertices.size());
  const Eigen::Index nv = V.rows() - Eigen::Index(r.isolated_vertices.size());
  r.euler_characteristic = int(nv - num_edges + Eigen::Index(good.size()));
  if (r.components == 1 && r.boundary_edges == 0 && r.nonmanifold_edges.empty() && r.bad_index_faces.empty())
    r.genus = (2 - r.euler_characteristic) / 2;
  return r;
}

MeshReport require_valid_mesh(const TriMesh& mesh, const MeshRequirements& req, const std::string& who) {
  MeshReport r = validate_mesh(mesh);
  auto fail = [&](const std::string& msg) { throw InvalidInput("[" + who + "] " + msg); };
  if (r.num_vertices == 0 || r.num_faces == 0)
    fail("the mesh is empty (" + std::to_string(r.num_vertices) + " vertices, " + std::to_string(r.num_faces) +
         " faces); load a triangle mesh with at least one face");
  if (!r.nonfinite_vertices.empty())
    fail("vertices with NaN/Inf coordinates: " + first_items(r.nonfinite_vertices) +
         "; fix or remove them before processing");
  if (!r.bad_index_faces.empty())
    fail("faces referencing missing vertices (index < 0 or >= " + std::to_string(r.num_vertices) +
         "): " + first_items(r.bad_index_faces) + "; the face list does not match the vertex list");
  if (!req.allow_nonmanifold && !r.nonmanifold_edges.empty())
    fail("non-manifold edges (shared by more than two faces): " + first_edges(r.nonmanifold_edges) +
         "; split them or remove the extra faces (`tbsp validate` lists all)");
  // lengths enter the systems to the fourth power (the squared norm of a cross product in the
  // cotangent weights and areas): beyond 1e50 they overflow, below 1e-50 they underflow (a
  // 1e150 mesh ended in "not positive definite", a 1e-100 one in "every face has zero area")
  if (r.scale_out_of_range) fail(scale_problem(r.extent, r.diagonal));
  if (r.degenerate_faces.size() == std::size_t(r.num_faces))
    fail("every face has zero area (the vertices coincide or lie on one line): there is no surface to process; check "
         "the vertex coordinates (units, a failed export)");
  if (!req.allow_degenerate && !r.degenerate_faces.empty())
    fail("degenerate faces (zero area): " + first_items(r.degenerate_faces) + "; remove them or collapse their short edge");
  if (!req.allow_duplicate_faces && !r.duplicate_faces.empty())
    fail("duplicate faces: " + first_items(r.duplicate_faces) + "; remove the repeated faces");
  if (!req.allow_isolated_vertices && !r.isolated_vertices.empty())
    fail("isolated (unreferenced) vertices: " + first_items(r.isolated_vertices) + "; remove unreferenced vertices");
  if (!req.allow_boundary && r.boundary_edges > 0)
    fail("the surface is open: " + std::to_string(r.boundary_edges) + " boundary edges in " +
         std::to_string(r.boundary_loops) + " loop(s); close the holes first");
  if (!req.allow_multiple_components && r.components > 1)
    fail("the mesh has " + std::to_string(r.components) + " components; keep one or process them separately");
  if (!req.allow_inconsistent_orientation && !r.inconsistent_edges.empty())
    fail("inconsistently oriented faces across edges " + first_edges(r.inconsistent_edges) + "; reorient the faces");
  return r;
}

}  // namespace tbsp
