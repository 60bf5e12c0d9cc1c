#include "tbsp/mesh/remeshing.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <map>
#include <unordered_map>

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

}  // namespace tbsp
