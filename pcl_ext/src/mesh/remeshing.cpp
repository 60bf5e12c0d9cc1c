#include "tbsp/mesh/remeshing.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <map>
#include <unordered_map>

#include <Eigen/SparseCholesky>

#include "tbsp/mesh/topology.h"

#include "tbsp/mesh/tri_mesh.h"

namespace tbsp {

namespace {
std::uint64_t edge_key(int a, int b) {
  if (a > b) std::swap(a, b);
  return (std::uint64_t(std::uint32_t(a)) << 32) | std::uint32_t(b);
}
}  // namespace

SubdivisionResult adaptive_subdivide(const Eigen::MatrixX3d& V, const Eigen::MatrixX3i& F, const std::vector<char>& marked) {
  const Eigen::Index nf = F.rows();
  std::vector<char> red(marked.begin(), marked.end());
  red.resize(std::size_t(nf), 0);
  // closure: split edges of red faces; faces with >= 2 split edges become red
  std::unordered_map<std::uint64_t, int> split;  // edge -> new vertex index (assigned later)
  bool changed = true;
  while (changed) {
    changed = false;
    split.clear();
    for (Eigen::Index f = 0; f < nf; ++f)
      if (red[std::size_t(f)])
        for (int k = 0; k < 3; ++k) split.emplace(edge_key(F(f, k), F(f, (k + 1) % 3)), -1);
    for (Eigen::Index f = 0; f < nf; ++f) {
      if (red[std::size_t(f)]) continue;
      int cnt = 0;
      for (int k = 0; k < 3; ++k) cnt += split.count(edge_key(F(f, k), F(f, (k + 1) % 3))) ? 1 : 0;
      if (cnt >= 2) { red[std::size_t(f)] = 1; changed = true; }
    }
  }
  SubdivisionResult out;
  std::vector<Eigen::RowVector3d> newv;
  int next = int(V.rows());
  // deterministic numbering: in face order
  for (Eigen::Index f = 0; f < nf; ++f)
    if (red[std::size_t(f)])
      for (int k = 0; k < 3; ++k) {
        const int a = F(f, k), b = F(f, (k + 1) % 3);
        auto& id = split[edge_key(a, b)];
        if (id < 0) {
          id = next++;
          newv.push_back(0.5 * (V.row(a) + V.row(b)));
          out.parents.emplace_back(std::min(a, b), std::max(a, b));
        }
      }
  std::vector<Eigen::RowVector3i> faces;
  faces.reserve(std::size_t(nf) + 3 * split.size());
  for (Eigen::Index f = 0; f < nf; ++f) {
    const int v[3] = {F(f, 0), F(f, 1), F(f, 2)};
    int m[3];
    for (int k = 0; k < 3; ++k) {
      auto it = split.find(edge_key(v[k], v[(k + 1) % 3]));
      m[k] = it == split.end() ? -1 : it->second;
    }
    if (red[std::size_t(f)]) {
      faces.emplace_back(v[0], m[0], m[2]);
      faces.emplace_back(v[1], m[1], m[0]);
      faces.emplace_back(v[2], m[2], m[1]);
      faces.emplace_back(m[0], m[1], m[2]);
      ++out.red_faces;
      continue;
    }
    int k = -1;
    for (int j = 0; j < 3; ++j)
      if (m[j] >= 0) k = j;
    if (k < 0) { faces.emplace_back(v[0], v[1], v[2]); continue; }
    // edge (v[k], v[k+1]) is split at m[k]: bisect towards the opposite vertex
    faces.emplace_back(v[k], m[k], v[(k + 2) % 3]);
    faces.emplace_back(m[k], v[(k + 1) % 3], v[(k + 2) % 3]);
    ++out.green_faces;
  }
  out.V.resize(V.rows() + Eigen::Index(newv.size()), 3);
  out.V.topRows(V.rows()) = V;
  for (std::size_t i = 0; i < newv.size(); ++i) out.V.row(V.rows() + Eigen::Index(i)) = newv[i];
  out.F.resize(Eigen::Index(faces.size()), 3);
  for (std::size_t i = 0; i < faces.size(); ++i) out.F.row(Eigen::Index(i)) = faces[i];
  return out;
}

int valence_edge_flips(const Eigen::MatrixX3d& V, Eigen::MatrixX3i& F, int sweeps, double max_normal_change_deg) {
  const double cos_max = std::cos(max_normal_change_deg * M_PI / 180.0);
  int flips = 0;
  auto normal = [&](int a, int b, int c) {
    return Eigen::Vector3d((V.row(b) - V.row(a)).cross(V.row(c) - V.row(a)).transpose());
  };
  for (int s = 0; s < sweeps; ++s) {
    // edge -> faces, valences, boundary flags
    std::unordered_map<std::uint64_t, std::vector<int>> ef;
    for (Eigen::Index f = 0; f < F.rows(); ++f)
      for (int k = 0; k < 3; ++k) ef[edge_key(F(f, k), F(f, (k + 1) % 3))].push_back(int(f));
    std::vector<int> val(std::size_t(V.rows()), 0);
    std::vector<char> boundary(std::size_t(V.rows()), 0);
    for (auto& kv : ef) {
      const int a = int(kv.first >> 32), b = int(kv.first & 0xffffffffu);
      ++val[std::size_t(a)];
      ++val[std::size_t(b)];
      if (kv.second.size() == 1) boundary[std::size_t(a)] = boundary[std::size_t(b)] = 1;
    }
    auto target = [&](int v) { return boundary[std::size_t(v)] ? 4 : 6; };
    std::vector<char> touched(std::size_t(F.rows()), 0);
    std::vector<std::uint64_t> keys;
    keys.reserve(ef.size());
    for (auto& kv : ef) keys.push_back(kv.first);
    std::sort(keys.begin(), keys.end());  // deterministic order
    int this_sweep = 0;
    for (std::uint64_t key : keys) {
      auto it = ef.find(key);
      if (it == ef.end()) continue;
      const std::vector<int> fs = it->second;
      if (fs.size() != 2 || touched[std::size_t(fs[0])] || touched[std::size_t(fs[1])]) continue;
      const int a = int(key >> 32), b = int(key & 0xffffffffu);
      const int f0 = fs[0], f1 = fs[1];
      auto opposite = [&](int f) {
        for (int k = 0; k < 3; ++k)
          if (F(f, k) != a && F(f, k) != b) return F(f, k);
        return -1;
      };
      const int c = opposite(f0), d = opposite(f1);
      if (c < 0 || d < 0 || c == d || ef.count(edge_key(c, d))) continue;
      if (val[std::size_t(a)] <= 3 || val[std::size_t(b)] <= 3) continue;
      auto dev = [&](int v, int delta) { const int x = val[std::size_t(v)] + delta - target(v); return x * x; };
      const int before = dev(a, 0) + dev(b, 0) + dev(c, 0) + dev(d, 0);
      const int after = dev(a, -1) + dev(b, -1) + dev(c, 1) + dev(d, 1);
      if (after >= before) continue;
      // orientation: f0 = (a, b, c) in some rotation; keep the winding of f0
      int ia = 0;
      while (F(f0, ia) != a) ++ia;
      const bool ab = F(f0, (ia + 1) % 3) == b;  // f0 traverses a->b
      const int p = ab ? a : b, q = ab ? b : a;   // f0 = (p, q, c), f1 = (q, p, d)
      const Eigen::Vector3d n0 = normal(p, q, c), n1 = normal(q, p, d);
      const Eigen::Vector3d m0 = normal(p, d, c), m1 = normal(q, c, d);
      const Eigen::Vector3d avg = (n0.normalized() + n1.normalized()).normalized();
      if (m0.norm() <= 0 || m1.norm() <= 0) continue;
      if (m0.normalized().dot(avg) < cos_max || m1.normalized().dot(avg) < cos_max) continue;
      F.row(f0) << p, d, c;
      F.row(f1) << q, c, d;
      ef.erase(key);
      ef[edge_key(c, d)] = {f0, f1};
      touched[std::size_t(f0)] = touched[std::size_t(f1)] = 1;
      --val[std::size_t(a)]; --val[std::size_t(b)]; ++val[std::size_t(c)]; ++val[std::size_t(d)];
      ++this_sweep;
    }
    flips += this_sweep;
    if (this_sweep == 0) break;
  }
  return flips;
}

int count_flipped_faces(const Eigen::MatrixX3d& V, const Eigen::MatrixX3i& F, const Eigen::MatrixX3d& ref) {
  const Eigen::MatrixX3d N = face_normals(V, F);
  int n = 0;
  for (Eigen::Index f = 0; f < F.rows() && f < ref.rows(); ++f)
    if (ref.row(f).norm() > 0 && N.row(f).dot(ref.row(f)) < 0) ++n;
  return n;
}

int count_local_folds(const Eigen::MatrixX3d& V, const Eigen::MatrixX3i& F, std::vector<char>* face_mark) {
  const Eigen::Index nv = V.rows(), nf = F.rows();
  // area vectors per face, summed per vertex (S1), then over each vertex's closed one-ring (S2)
  Eigen::MatrixX3d A(nf, 3);
  for (Eigen::Index f = 0; f < nf; ++f) {
    const Eigen::Vector3d a = V.row(F(f, 0)).transpose(), b = V.row(F(f, 1)).transpose(), c = V.row(F(f, 2)).transpose();
    A.row(f) = (b - a).cross(c - a).transpose();
  }
  // faces per vertex, compressed (offsets + indices)
  std::vector<int> off(std::size_t(nv) + 1, 0), vf(std::size_t(nf) * 3);
  for (Eigen::Index f = 0; f < nf; ++f)
    for (int q = 0; q < 3; ++q) ++off[std::size_t(F(f, q)) + 1];
  for (Eigen::Index v = 0; v < nv; ++v) off[std::size_t(v) + 1] += off[std::size_t(v)];
  {
    std::vector<int> fill(off.begin(), off.end() - 1);
    for (Eigen::Index f = 0; f < nf; ++f)
      for (int q = 0; q < 3; ++q) vf[std::size_t(fill[std::size_t(F(f, q))]++)] = int(f);
  }
  // per face: the area vectors of the distinct faces at the vertices within two rings of its
  // corners, summed
  std::vector<char> folded(std::size_t(nf), 0);
#pragma omp parallel
  {
    std::vector<int> vstamp(std::size_t(nv), -1), fstamp(std::size_t(nf), -1);
    std::vector<int> verts;
#pragma omp for schedule(dynamic, 1024)
    for (Eigen::Index f = 0; f < nf; ++f) {
      const int tag = int(f);
      verts.clear();
      for (int q = 0; q < 3; ++q) {
        const int v = F(f, q);
        if (vstamp[std::size_t(v)] != tag) { vstamp[std::size_t(v)] = tag; verts.push_back(v); }
      }
      for (int ring = 0; ring < 2; ++ring) {  // neighbours = the other corners of incident faces
        const std::size_t end = verts.size();
        for (std::size_t k = 0; k < end; ++k) {
          const int v = verts[k];
          for (int i = off[std::size_t(v)]; i < off[std::size_t(v) + 1]; ++i)
            for (int q = 0; q < 3; ++q) {
              const int w = F(vf[std::size_t(i)], q);
              if (vstamp[std::size_t(w)] != tag) { vstamp[std::size_t(w)] = tag; verts.push_back(w); }
            }
        }
      }
      double mx = 0, my = 0, mz = 0;
      for (int v : verts)
        for (int i = off[std::size_t(v)]; i < off[std::size_t(v) + 1]; ++i) {
          const int g = vf[std::size_t(i)];
          if (fstamp[std::size_t(g)] == tag) continue;
          fstamp[std::size_t(g)] = tag;
          mx += A(g, 0);
          my += A(g, 1);
          mz += A(g, 2);
        }
      folded[std::size_t(f)] = A(f, 0) * mx + A(f, 1) * my + A(f, 2) * mz < 0;
    }
  }
  if (face_mark) *face_mark = folded;
  return int(std::count(folded.begin(), folded.end(), 1));
}

UntangleResult untangle_local_folds(Eigen::MatrixX3d& V, const Eigen::MatrixX3i& F, int rings, int max_rounds, int max_rings) {
  UntangleResult res;
  const Eigen::Index nv = V.rows();
  std::vector<char> fmark;
  res.folds_before = res.folds_after = count_local_folds(V, F, &fmark);
  if (res.folds_before == 0) return res;
  const auto adj = vertex_adjacency(F, nv);
  // vertices on a mesh boundary (an edge with one face) never move
  std::vector<char> on_boundary(std::size_t(nv), 0);
  {
    std::unordered_map<std::uint64_t, int> edge_faces;
    edge_faces.reserve(std::size_t(F.rows()) * 3);
    for (Eigen::Index f = 0; f < F.rows(); ++f)
      for (int k = 0; k < 3; ++k) ++edge_faces[edge_key(F(f, k), F(f, (k + 1) % 3))];
    for (const auto& [key, n] : edge_faces)
      if (n != 2) {
        on_boundary[std::size_t(key >> 32)] = 1;
        on_boundary[std::size_t(key & 0xffffffffu)] = 1;
      }
  }
  std::vector<char> moved(std::size_t(nv), 0);
  int cur_rings = std::max(0, rings);
  for (int round = 0; round < max_rounds && res.folds_after > 0; ++round) {
    ++res.rounds;
    std::vector<char> region(std::size_t(nv), 0);
    for (Eigen::Index f = 0; f < F.rows(); ++f)
      if (fmark[std::size_t(f)])
        for (int q = 0; q < 3; ++q) region[std::size_t(F(f, q))] = 1;
    for (int ring = 0; ring < cur_rings; ++ring) {
      const std::vector<char> prev = region;
      for (Eigen::Index i = 0; i < nv; ++i)
        if (prev[std::size_t(i)])
          for (int j : adj[std::size_t(i)]) region[std::size_t(j)] = 1;
    }
    // interior unknowns: region vertices off the mesh boundary
    std::vector<int> index(std::size_t(nv), -1);
    std::vector<int> unknowns;
    for (Eigen::Index i = 0; i < nv; ++i)
      if (region[std::size_t(i)] && !on_boundary[std::size_t(i)] && !adj[std::size_t(i)].empty()) {
        index[std::size_t(i)] = int(unknowns.size());
        unknowns.push_back(int(i));
      }
    if (unknowns.empty()) break;
    // uniform Laplacian, Dirichlet on everything outside the unknowns: deg x_i - sum_{j unknown} x_j
    // = sum_{j fixed} x_j (symmetric positive definite: every component touches a fixed vertex,
    // or is a whole closed component — then the first vertex is pinned)
    const Eigen::Index n = Eigen::Index(unknowns.size());
    std::vector<Eigen::Triplet<double>> T;
    Eigen::MatrixX3d B = Eigen::MatrixX3d::Zero(n, 3);
    std::vector<char> touches_fixed(std::size_t(n), 0);
    for (Eigen::Index r = 0; r < n; ++r) {
      const int i = unknowns[std::size_t(r)];
      T.emplace_back(r, r, double(adj[std::size_t(i)].size()));
      for (int j : adj[std::size_t(i)]) {
        if (index[std::size_t(j)] >= 0) T.emplace_back(r, index[std::size_t(j)], -1.0);
        else { B.row(r) += V.row(j); touches_fixed[std::size_t(r)] = 1; }
      }
    }
    // a closed component entirely inside the region (the whole mesh folded): pin one vertex per
    // component so the system stays definite
    {
      std::vector<int> comp(std::size_t(n), -1);
      for (Eigen::Index s = 0; s < n; ++s) {
        if (comp[std::size_t(s)] >= 0) continue;
        std::vector<int> stack{int(s)}, members;
        comp[std::size_t(s)] = int(s);
        bool fixed = false;
        while (!stack.empty()) {
          const int r = stack.back();
          stack.pop_back();
          members.push_back(r);
          fixed = fixed || touches_fixed[std::size_t(r)];
          for (int j : adj[std::size_t(unknowns[std::size_t(r)])]) {
            const int q = index[std::size_t(j)];
            if (q >= 0 && comp[std::size_t(q)] < 0) { comp[std::size_t(q)] = int(s); stack.push_back(q); }
          }
        }
        if (!fixed) { T.emplace_back(members[0], members[0], 1.0); B.row(members[0]) += V.row(unknowns[std::size_t(members[0])]); }
      }
    }
    Eigen::SparseMatrix<double> M(n, n);
    M.setFromTriplets(T.begin(), T.end());
    Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>> solver(M);
    if (solver.info() != Eigen::Success) break;
    const Eigen::MatrixX3d X = solver.solve(B);
    if (solver.info() != Eigen::Success || !X.allFinite()) break;
    for (Eigen::Index r = 0; r < n; ++r) {
      V.row(unknowns[std::size_t(r)]) = X.row(r);
      moved[std::size_t(unknowns[std::size_t(r)])] = 1;
    }
    const int before = res.folds_after;
    res.folds_after = count_local_folds(V, F, &fmark);
    // the smallest region that works: grow it only while a round makes no progress
    if (res.folds_after >= before) cur_rings = std::min(cur_rings + 1, std::max(0, max_rings));
  }
  res.vertices_moved = int(std::count(moved.begin(), moved.end(), 1));
  return res;
}

}  // namespace tbsp
