#include "tbsp/mesh/remeshing.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <iterator>
#include <limits>
#include <map>
#include <unordered_map>

#include <Eigen/SparseCholesky>

#include "tbsp/mesh/mesh_validation.h"
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
  std::vector<int> off, vf;
  vertex_faces(F, nv, off, vf);
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

namespace tbsp {

PleatCollapseResult collapse_pleats(Eigen::MatrixX3d& V, Eigen::MatrixX3i& F,
                                    const std::function<Eigen::Vector3d(const Eigen::Vector3d&)>& reference_normal,
                                    std::vector<int>* old_to_new, int max_passes, double min_cosine) {
  PleatCollapseResult res;
  const Eigen::Index nv0 = V.rows();
  std::vector<int> map(static_cast<std::size_t>(nv0));
  for (Eigen::Index i = 0; i < nv0; ++i) map[std::size_t(i)] = int(i);
  auto finish = [&]() {
    if (old_to_new) *old_to_new = map;
  };
  if (F.rows() == 0) {
    finish();
    return res;
  }
  // unit normal (zero when degenerate), centroid and doubled area of a triangle
  auto tri = [&](int a, int b, int c, Eigen::Vector3d& centroid, double& area2) {
    const Eigen::Vector3d A = V.row(a), B = V.row(b), C = V.row(c);
    centroid = (A + B + C) / 3.0;
    const Eigen::Vector3d n = (B - A).cross(C - A);
    area2 = n.norm();
    return area2 > 0 ? Eigen::Vector3d(n / area2) : Eigen::Vector3d::Zero();
  };
  auto against = [&](int a, int b, int c) {
    Eigen::Vector3d cen;
    double ar;
    const Eigen::Vector3d n = tri(a, b, c, cen, ar);
    const Eigen::Vector3d r = reference_normal(cen);
    return r.squaredNorm() > 0 && n.dot(r) < min_cosine;
  };
  double min_area2 = 0;
  {
    std::vector<double> len;
    len.reserve(std::size_t(F.rows()));
    for (Eigen::Index f = 0; f < F.rows(); ++f) len.push_back((V.row(F(f, 0)) - V.row(F(f, 1))).norm());
    std::nth_element(len.begin(), len.begin() + long(len.size() / 2), len.end());
    const double med = len[len.size() / 2];
    min_area2 = 2e-3 * med * med;  // doubled area
  }
  for (int pass = 0; pass < max_passes; ++pass) {
    const Eigen::Index nv = V.rows(), nf = F.rows();
    std::vector<char> bad(std::size_t(nf), 0);
#pragma omp parallel for schedule(dynamic, 1024)
    for (Eigen::Index f = 0; f < nf; ++f) bad[std::size_t(f)] = against(F(f, 0), F(f, 1), F(f, 2));
    int nbad = 0;
    for (char b : bad) nbad += b;
    if (pass == 0) res.faces_before = nbad;
    res.faces_after = nbad;
    if (nbad == 0) break;
    // pleats are rare; a large share of faces against the reference is a reference oriented the
    // other way (or a template inside out), which collapsing would only decimate
    if (pass == 0 && double(nbad) > 0.05 * double(nf)) break;
    ++res.passes;
    std::vector<std::vector<int>> vf(static_cast<std::size_t>(nv));
    for (Eigen::Index f = 0; f < nf; ++f)
      for (int k = 0; k < 3; ++k) vf[std::size_t(F(f, k))].push_back(int(f));
    std::vector<std::pair<double, std::pair<int, int>>> cand;
    for (Eigen::Index f = 0; f < nf; ++f)
      if (bad[std::size_t(f)])
        for (int k = 0; k < 3; ++k) {
          const int a = F(f, k), b = F(f, (k + 1) % 3);
          cand.push_back({(V.row(a) - V.row(b)).norm(), {std::min(a, b), std::max(a, b)}});
        }
    std::sort(cand.begin(), cand.end());
    cand.erase(std::unique(cand.begin(), cand.end()), cand.end());
    std::vector<char> lock(static_cast<std::size_t>(nv), 0), gone(static_cast<std::size_t>(nv), 0),
        dead(static_cast<std::size_t>(nf), 0);
    int collapses = 0;
    std::vector<int> star, ring_a, ring_b;
    std::vector<Eigen::Vector3d> normals;
    std::vector<int> kept;
    for (const auto& [len, e] : cand) {
      (void)len;
      const int a = e.first, b = e.second;
      if (lock[std::size_t(a)] || lock[std::size_t(b)]) continue;
      auto ring = [&](int v, std::vector<int>& out) {
        out.clear();
        for (int f : vf[std::size_t(v)])
          for (int k = 0; k < 3; ++k)
            if (F(f, k) != v) out.push_back(F(f, k));
        std::sort(out.begin(), out.end());
        out.erase(std::unique(out.begin(), out.end()), out.end());
      };
      ring(a, ring_a);
      ring(b, ring_b);
      int shared_faces = 0;
      for (int f : vf[std::size_t(a)])
        shared_faces += F(f, 0) == b || F(f, 1) == b || F(f, 2) == b;
      std::vector<int> common;
      std::set_intersection(ring_a.begin(), ring_a.end(), ring_b.begin(), ring_b.end(), std::back_inserter(common));
      if (shared_faces != 2 || common.size() != 2) continue;  // boundary edge or link condition fails
      star.assign(vf[std::size_t(a)].begin(), vf[std::size_t(a)].end());
      star.insert(star.end(), vf[std::size_t(b)].begin(), vf[std::size_t(b)].end());
      std::sort(star.begin(), star.end());
      star.erase(std::unique(star.begin(), star.end()), star.end());
      int before = 0;
      for (int f : star) before += bad[std::size_t(f)];
      const Eigen::RowVector3d pa = V.row(a), pb = V.row(b);
      int best_count = std::numeric_limits<int>::max();
      double best_area = -1;
      Eigen::RowVector3d best_pos = pa;
      for (double t : {0.5, 0.0, 1.0, 0.25, 0.75}) {
        const Eigen::RowVector3d x = (1 - t) * pa + t * pb;
        V.row(a) = x;
        V.row(b) = x;
        int after = 0;
        double min_area = std::numeric_limits<double>::max();
        bool ok = true;
        Eigen::Vector3d mean_n = Eigen::Vector3d::Zero();
        normals.clear();
        kept.clear();
        for (int f : star) {
          const bool ha = F(f, 0) == a || F(f, 1) == a || F(f, 2) == a, hb = F(f, 0) == b || F(f, 1) == b || F(f, 2) == b;
          if (ha && hb) continue;  // removed by the collapse
          Eigen::Vector3d cen;
          double ar;
          const Eigen::Vector3d n = tri(F(f, 0), F(f, 1), F(f, 2), cen, ar);
          if (ar < min_area2) {
            ok = false;
            break;
          }
          const Eigen::Vector3d r = reference_normal(cen);
          const bool is_bad = r.squaredNorm() > 0 && n.dot(r) < min_cosine;
          after += is_bad;
          min_area = std::min(min_area, ar);
          if (is_bad) continue;  // still part of the pleat: the fold checks below are for the rest
          mean_n += ar * n;
          normals.push_back(n);
          kept.push_back(f);
        }
        if (ok)
          for (const Eigen::Vector3d& n : normals) ok = ok && n.dot(mean_n) >= 0;  // no new crumple
        for (std::size_t i = 0; ok && i < kept.size(); ++i)  // no edge bent back by more than 120°
          for (std::size_t j = i + 1; ok && j < kept.size(); ++j) {
            int shared = 0;
            for (int s = 0; s < 3; ++s)
              for (int t2 = 0; t2 < 3; ++t2) shared += F(kept[i], s) == F(kept[j], t2) ||
                                                       (F(kept[i], s) == b && F(kept[j], t2) == a) ||
                                                       (F(kept[i], s) == a && F(kept[j], t2) == b);
            ok = shared < 2 || normals[i].dot(normals[j]) >= -0.5;
          }
        for (std::size_t i = 0; ok && i < kept.size(); ++i)  // ... nor against the faces around the star
          for (int s = 0; ok && s < 3; ++s) {
            const int p = F(kept[i], s), q = F(kept[i], (s + 1) % 3);
            if (p == a || p == b || q == a || q == b) continue;
            for (int g : vf[std::size_t(p)]) {
              if (g == kept[i] || std::binary_search(star.begin(), star.end(), g)) continue;
              if (F(g, 0) != q && F(g, 1) != q && F(g, 2) != q) continue;
              if (dead[std::size_t(g)] || bad[std::size_t(g)]) continue;  // removed this pass / pleat
              Eigen::Vector3d cen;
              double ar;
              const Eigen::Vector3d ng = tri(F(g, 0), F(g, 1), F(g, 2), cen, ar);
              ok = normals[i].dot(ng) >= -0.5;
            }
          }
        V.row(a) = pa;
        V.row(b) = pb;
        if (ok && (after < best_count || (after == best_count && min_area > best_area))) {
          best_count = after;
          best_area = min_area;
          best_pos = x;
        }
      }
      if (best_count >= before) continue;
      V.row(a) = best_pos;
      for (int f : vf[std::size_t(b)]) {
        if (F(f, 0) == a || F(f, 1) == a || F(f, 2) == a) {
          dead[std::size_t(f)] = 1;
        } else {
          for (int k = 0; k < 3; ++k)
            if (F(f, k) == b) F(f, k) = a;
        }
      }
      for (int f : star)
        for (int k = 0; k < 3; ++k) lock[std::size_t(F(f, k))] = 1;
      lock[std::size_t(b)] = 1;
      gone[std::size_t(b)] = 1;
      ++collapses;
    }
    if (collapses == 0) break;
    res.collapses += collapses;
    // compact: drop the removed faces and the merged-away vertices, keep the order
    Eigen::MatrixX3i F2(nf, 3);
    Eigen::Index m = 0;
    for (Eigen::Index f = 0; f < nf; ++f)
      if (!dead[std::size_t(f)]) F2.row(m++) = F.row(f);
    F2.conservativeResize(m, 3);
    std::vector<int> remap(static_cast<std::size_t>(nv), -1);
    int q = 0;
    for (Eigen::Index v = 0; v < nv; ++v)
      if (!gone[std::size_t(v)]) remap[std::size_t(v)] = q++;
    Eigen::MatrixX3d V2(q, 3);
    for (Eigen::Index v = 0; v < nv; ++v)
      if (!gone[std::size_t(v)]) V2.row(remap[std::size_t(v)]) = V.row(v);
    for (Eigen::Index f = 0; f < m; ++f)
      for (int k = 0; k < 3; ++k) F2(f, k) = remap[std::size_t(F2(f, k))];
    for (int& x : map)
      if (x >= 0) x = remap[std::size_t(x)];
    V = std::move(V2);
    F = std::move(F2);
    res.faces_after = -1;  // recounted below
  }
  if (res.faces_after < 0) {
    int nbad = 0;
#pragma omp parallel for schedule(dynamic, 1024) reduction(+ : nbad)
    for (Eigen::Index f = 0; f < F.rows(); ++f) nbad += against(F(f, 0), F(f, 1), F(f, 2));
    res.faces_after = nbad;
  }
  finish();
  return res;
}

IntersectionRepairResult repair_self_intersections(Eigen::MatrixX3d& V, const Eigen::MatrixX3i& F, int max_rounds) {
  IntersectionRepairResult res;
  std::vector<std::pair<int, int>> pairs;
  res.pairs_before = res.pairs_after = count_self_intersections(V, F, &pairs);
  if (res.pairs_before == 0) return res;
  const auto adj = vertex_adjacency(F, V.rows());
  std::vector<char> moved(static_cast<std::size_t>(V.rows()), 0);
  for (int round = 0; round < max_rounds && res.pairs_after > 0; ++round) {
    std::vector<char> region(static_cast<std::size_t>(V.rows()), 0);
    for (const auto& [a, b] : pairs)
      for (int f : {a, b})
        for (int k = 0; k < 3; ++k) region[std::size_t(F(f, k))] = 1;
    grow_region(region, adj, round / 10);  // crossings that persist: a wider region
    umbrella_step(V, adj, region, 0.5, &moved);
    ++res.rounds;
    res.pairs_after = count_self_intersections(V, F, &pairs);
  }
  for (char m : moved) res.vertices_moved += m;
  return res;
}

}  // namespace tbsp
