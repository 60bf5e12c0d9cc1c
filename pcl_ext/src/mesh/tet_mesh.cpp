#include "tbsp/mesh/tet_mesh.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <array>
#include <numeric>
#include <sstream>

#include "tbsp/core/error.h"

namespace tbsp {

using TetIndices = Eigen::Matrix<int, Eigen::Dynamic, 4>;

namespace {
// Faces opposite each vertex, ordered so that they face outward for a positive tet.
constexpr int kFace[4][3] = {{1, 2, 3}, {0, 3, 2}, {0, 1, 3}, {0, 2, 1}};

struct FaceKey {
  std::array<int, 3> v;  // sorted
  int tet, local;
  bool operator<(const FaceKey& o) const { return v < o.v; }
};

std::vector<FaceKey> sorted_faces(const TetIndices& T) {
  std::vector<FaceKey> f;
  f.reserve(std::size_t(T.rows()) * 4);
  for (Eigen::Index t = 0; t < T.rows(); ++t)
    for (int k = 0; k < 4; ++k) {
      std::array<int, 3> v{T(t, kFace[k][0]), T(t, kFace[k][1]), T(t, kFace[k][2])};
      std::sort(v.begin(), v.end());
      f.push_back({v, int(t), k});
    }
  std::sort(f.begin(), f.end());
  return f;
}
}  // namespace

Eigen::VectorXd tet_signed_volumes(const Eigen::MatrixX3d& V, const TetIndices& T) {
  Eigen::VectorXd vol(T.rows());
  for (Eigen::Index t = 0; t < T.rows(); ++t) {
    const Eigen::Vector3d a = V.row(T(t, 0)), b = V.row(T(t, 1)), c = V.row(T(t, 2)), d = V.row(T(t, 3));
    vol(t) = (b - a).cross(c - a).dot(d - a) / 6.0;
  }
  return vol;
}

double tet_mesh_volume(const TetMesh& mesh) { return tet_signed_volumes(mesh.V, mesh.T).cwiseAbs().sum(); }

Eigen::Index orient_tets(TetMesh& mesh) {
  const Eigen::VectorXd vol = tet_signed_volumes(mesh.V, mesh.T);
  Eigen::Index flipped = 0;
  for (Eigen::Index t = 0; t < mesh.T.rows(); ++t)
    if (vol(t) < 0) {
      std::swap(mesh.T(t, 2), mesh.T(t, 3));
      ++flipped;
    }
  return flipped;
}

Eigen::MatrixX3i tet_boundary_faces(const TetIndices& T, std::vector<int>* face_tet) {
  const auto f = sorted_faces(T);
  std::vector<std::array<int, 3>> out;
  if (face_tet) face_tet->clear();
  for (std::size_t i = 0; i < f.size();) {
    std::size_t j = i + 1;
    while (j < f.size() && f[j].v == f[i].v) ++j;
    if (j - i == 1) {
      const int t = f[i].tet, k = f[i].local;
      out.push_back({T(t, kFace[k][0]), T(t, kFace[k][1]), T(t, kFace[k][2])});
      if (face_tet) face_tet->push_back(t);
    }
    i = j;
  }
  Eigen::MatrixX3i F(Eigen::Index(out.size()), 3);
  for (std::size_t i = 0; i < out.size(); ++i) F.row(Eigen::Index(i)) << out[i][0], out[i][1], out[i][2];
  return F;
}

TriMesh tet_boundary_mesh(const TetMesh& mesh) {
  TriMesh m;
  m.V = mesh.V;
  m.F = tet_boundary_faces(mesh.T);
  return m;
}

TriMesh tet_boundary_surface(const Eigen::MatrixX3d& X, const TetIndices& T, std::vector<int>* vertex_map) {
  const Eigen::MatrixX3i F = tet_boundary_faces(T);
  std::vector<int> id(static_cast<std::size_t>(X.rows()), -1);
  int n = 0;
  for (Eigen::Index f = 0; f < F.rows(); ++f)
    for (int k = 0; k < 3; ++k)
      if (id[std::size_t(F(f, k))] < 0) id[std::size_t(F(f, k))] = n++;
  TriMesh m;
  m.V.resize(n, 3);
  for (Eigen::Index i = 0; i < X.rows(); ++i)
    if (id[std::size_t(i)] >= 0) m.V.row(id[std::size_t(i)]) = X.row(i);
  m.F.resize(F.rows(), 3);
  for (Eigen::Index f = 0; f < F.rows(); ++f)
    for (int k = 0; k < 3; ++k) m.F(f, k) = id[std::size_t(F(f, k))];
  if (vertex_map) *vertex_map = std::move(id);
  return m;
}

TetIndices tet_face_neighbours(const TetIndices& T) {
  TetIndices N = TetIndices::Constant(T.rows(), 4, -1);
  const auto f = sorted_faces(T);
  for (std::size_t i = 0; i + 1 < f.size(); ++i)
    if (f[i].v == f[i + 1].v) {
      N(f[i].tet, f[i].local) = f[i + 1].tet;
      N(f[i + 1].tet, f[i + 1].local) = f[i].tet;
    }
  return N;
}

int tet_connected_components(const TetMesh& mesh, Eigen::VectorXi& labels) {
  const Eigen::Index n = mesh.V.rows();
  std::vector<int> parent(static_cast<std::size_t>(n));
  std::iota(parent.begin(), parent.end(), 0);
  auto find = [&](int x) {
    while (parent[std::size_t(x)] != x) x = parent[std::size_t(x)] = parent[std::size_t(parent[std::size_t(x)])];
    return x;
  };
  for (Eigen::Index t = 0; t < mesh.T.rows(); ++t)
    for (int k = 1; k < 4; ++k) {
      const int a = find(mesh.T(t, 0)), b = find(mesh.T(t, k));
      if (a != b) parent[std::size_t(std::max(a, b))] = std::min(a, b);
    }
  labels.resize(n);
  std::vector<int> id(std::size_t(n), -1);
  int count = 0;
  for (Eigen::Index i = 0; i < n; ++i) {
    const int r = find(int(i));
    if (id[std::size_t(r)] < 0) id[std::size_t(r)] = count++;
    labels(i) = id[std::size_t(r)];
  }
  return count;
}

void require_valid_tet_mesh(const TetMesh& mesh, const std::string& who) {
  const std::string pre = "[" + who + "] ";
  if (mesh.V.rows() == 0 || mesh.T.rows() == 0)
    throw InvalidInput(pre + "the tetrahedral mesh is empty (" + std::to_string(mesh.V.rows()) + " vertices, " +
                       std::to_string(mesh.T.rows()) + " tetrahedra)");
  for (Eigen::Index i = 0; i < mesh.V.rows(); ++i)
    if (!mesh.V.row(i).allFinite())
      throw InvalidInput(pre + "vertex " + std::to_string(i) + " has a non-finite coordinate; remove or fix it");
  for (Eigen::Index t = 0; t < mesh.T.rows(); ++t) {
    for (int k = 0; k < 4; ++k)
      if (mesh.T(t, k) < 0 || mesh.T(t, k) >= mesh.V.rows())
        throw InvalidInput(pre + "tetrahedron " + std::to_string(t) + " refers to vertex " + std::to_string(mesh.T(t, k)) +
                           ", but the mesh has " + std::to_string(mesh.V.rows()) + " vertices");
    for (int a = 0; a < 4; ++a)
      for (int b = a + 1; b < 4; ++b)
        if (mesh.T(t, a) == mesh.T(t, b))
          throw InvalidInput(pre + "tetrahedron " + std::to_string(t) + " repeats vertex " + std::to_string(mesh.T(t, a)));
  }
  const Eigen::VectorXd vol = tet_signed_volumes(mesh.V, mesh.T).cwiseAbs();
  const double tol = 1e-12 * vol.mean();
  std::vector<Eigen::Index> bad;
  for (Eigen::Index t = 0; t < vol.size(); ++t)
    if (!(vol(t) > tol)) bad.push_back(t);
  if (!bad.empty()) {
    std::ostringstream os;
    os << pre << bad.size() << " degenerate (zero-volume) tetrahedra, e.g. tet " << bad[0];
    for (std::size_t i = 1; i < std::min<std::size_t>(bad.size(), 5); ++i) os << ", " << bad[i];
    os << "; their gradients are undefined. Re-tetrahedralize with a quality bound (tetgen -q) or remove them";
    throw InvalidInput(os.str());
  }
}

TetMesh surface_to_tets(const TriMesh& surface, double offset) {
  const Eigen::Index nv = surface.V.rows(), nf = surface.F.rows();
  if (nv == 0 || nf == 0) throw InvalidInput("[tbsp::surface_to_tets] the surface is empty");
  for (Eigen::Index f = 0; f < nf; ++f)
    for (int k = 0; k < 3; ++k)
      if (surface.F(f, k) < 0 || surface.F(f, k) >= nv)
        throw InvalidInput("[tbsp::surface_to_tets] face " + std::to_string(f) + " refers to vertex " +
                           std::to_string(surface.F(f, k)) + " of " + std::to_string(nv));
  if (!(offset > 0)) {
    double sum = 0;
    for (Eigen::Index f = 0; f < nf; ++f)
      for (int k = 0; k < 3; ++k) sum += (surface.V.row(surface.F(f, k)) - surface.V.row(surface.F(f, (k + 1) % 3))).norm();
    offset = 0.5 * sum / double(3 * nf);
  }
  TetMesh out;
  out.V.resize(nv + nf, 3);
  out.V.topRows(nv) = surface.V;
  std::vector<std::array<int, 4>> tets;
  tets.reserve(std::size_t(nf));
  const double diag = bbox_diagonal(surface.V);
  for (Eigen::Index f = 0; f < nf; ++f) {
    const Eigen::Vector3d a = surface.V.row(surface.F(f, 0)), b = surface.V.row(surface.F(f, 1)),
                          c = surface.V.row(surface.F(f, 2));
    const Eigen::Vector3d n = (b - a).cross(c - a);
    const Eigen::Vector3d centroid = (a + b + c) / 3.0;
    const double len = n.norm();
    if (!(len > 1e-14 * diag * diag)) {
      out.V.row(nv + f) = centroid;
      continue;
    }
    out.V.row(nv + f) = centroid + offset * n / len;
    tets.push_back({surface.F(f, 0), surface.F(f, 1), surface.F(f, 2), int(nv + f)});
  }
  out.T.resize(Eigen::Index(tets.size()), 4);
  for (std::size_t i = 0; i < tets.size(); ++i)
    out.T.row(Eigen::Index(i)) << tets[i][0], tets[i][1], tets[i][2], tets[i][3];
  return out;
}

}  // namespace tbsp
