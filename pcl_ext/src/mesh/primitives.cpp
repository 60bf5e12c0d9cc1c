#include "tbsp/mesh/primitives.h"

#include <Eigen/Geometry>
#include <cmath>
#include <map>
#include <tuple>
#include <random>
#include <vector>

#include "tbsp/core/error.h"

namespace tbsp {

TriMesh make_icosphere(int level, double radius) {
  if (level < 0 || level > 9) throw InvalidInput("[tbsp::make_icosphere] level must be in 0..9");
  const double t = (1.0 + std::sqrt(5.0)) / 2.0;
  std::vector<Eigen::Vector3d> v = {{-1, t, 0}, {1, t, 0}, {-1, -t, 0}, {1, -t, 0}, {0, -1, t}, {0, 1, t},
                                    {0, -1, -t}, {0, 1, -t}, {t, 0, -1}, {t, 0, 1}, {-t, 0, -1}, {-t, 0, 1}};
  std::vector<Eigen::Vector3i> f = {{0, 11, 5}, {0, 5, 1},  {0, 1, 7},   {0, 7, 10}, {0, 10, 11}, {1, 5, 9}, {5, 11, 4},
                                    {11, 10, 2}, {10, 7, 6}, {7, 1, 8},   {3, 9, 4},  {3, 4, 2},   {3, 2, 6}, {3, 6, 8},
                                    {3, 8, 9},  {4, 9, 5},  {2, 4, 11},  {6, 2, 10}, {8, 6, 7},   {9, 8, 1}};
  for (auto& p : v) p.normalize();
  for (int l = 0; l < level; ++l) {
    std::map<std::pair<int, int>, int> mid;
    auto midpoint = [&](int a, int b) {
      auto key = std::make_pair(std::min(a, b), std::max(a, b));
      auto it = mid.find(key);
      if (it != mid.end()) return it->second;
      v.push_back((v[std::size_t(a)] + v[std::size_t(b)]).normalized());
      return mid[key] = int(v.size()) - 1;
    };
    std::vector<Eigen::Vector3i> nf;
    nf.reserve(f.size() * 4);
    for (auto& tri : f) {
      const int a = midpoint(tri(0), tri(1)), b = midpoint(tri(1), tri(2)), c = midpoint(tri(2), tri(0));
      nf.emplace_back(tri(0), a, c);
      nf.emplace_back(tri(1), b, a);
      nf.emplace_back(tri(2), c, b);
      nf.emplace_back(a, b, c);
    }
    f.swap(nf);
  }
  TriMesh m;
  m.V.resize(Eigen::Index(v.size()), 3);
  for (std::size_t i = 0; i < v.size(); ++i) m.V.row(Eigen::Index(i)) = radius * v[i].transpose();
  m.F.resize(Eigen::Index(f.size()), 3);
  for (std::size_t i = 0; i < f.size(); ++i) m.F.row(Eigen::Index(i)) = f[i].transpose();
  return m;
}

TriMesh make_grid(int nx, int ny, double sx, double sy, double jitter, unsigned seed) {
  if (nx < 1 || ny < 1) throw InvalidInput("[tbsp::make_grid] nx and ny must be >= 1");
  TriMesh m;
  m.V.resize(Eigen::Index(nx + 1) * (ny + 1), 3);
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-jitter, jitter);
  for (int j = 0; j <= ny; ++j)
    for (int i = 0; i <= nx; ++i) {
      double x = double(i), y = double(j);
      if (jitter > 0 && i > 0 && i < nx && j > 0 && j < ny) { x += u(rng); y += u(rng); }
      m.V.row(j * (nx + 1) + i) << sx * x / nx, sy * y / ny, 0.0;
    }
  m.F.resize(2 * nx * ny, 3);
  int k = 0;
  for (int j = 0; j < ny; ++j)
    for (int i = 0; i < nx; ++i) {
      const int a = j * (nx + 1) + i, b = a + 1, c = a + nx + 1, d = c + 1;
      if ((i + j) % 2 == 0) { m.F.row(k++) << a, b, d; m.F.row(k++) << a, d, c; }
      else { m.F.row(k++) << a, b, c; m.F.row(k++) << b, d, c; }
    }
  return m;
}

TriMesh make_tube(int rings, int segments, double length, double radius) {
  if (rings < 2 || segments < 3) throw InvalidInput("[tbsp::make_tube] needs rings >= 2 and segments >= 3");
  TriMesh m;
  const int n = rings * segments;
  m.V.resize(n + 2, 3);
  for (int i = 0; i < rings; ++i)
    for (int s = 0; s < segments; ++s) {
      const double a = 2 * M_PI * s / segments;
      m.V.row(i * segments + s) << length * i / (rings - 1), radius * std::cos(a), radius * std::sin(a);
    }
  m.V.row(n) << 0, 0, 0;
  m.V.row(n + 1) << length, 0, 0;
  m.F.resize(2 * (rings - 1) * segments + 2 * segments, 3);
  int k = 0;
  for (int i = 0; i + 1 < rings; ++i)
    for (int s = 0; s < segments; ++s) {
      const int a = i * segments + s, b = i * segments + (s + 1) % segments;
      const int c = a + segments, d = b + segments;
      m.F.row(k++) << a, b, d;
      m.F.row(k++) << a, d, c;
    }
  for (int s = 0; s < segments; ++s) {
    m.F.row(k++) << n, (s + 1) % segments, s;
    m.F.row(k++) << n + 1, (rings - 1) * segments + s, (rings - 1) * segments + (s + 1) % segments;
  }
  return m;
}

TriMesh make_box(int nx, int ny, int nz, double sx, double sy, double sz) {
  if (nx < 1 || ny < 1 || nz < 1 || !(sx > 0) || !(sy > 0) || !(sz > 0))
    throw InvalidInput("[tbsp::make_box] divisions must be >= 1 and sizes > 0");
  const int n[3] = {nx, ny, nz};
  std::map<std::tuple<int, int, int>, int> index;
  std::vector<Eigen::Vector3d> v;
  auto vid = [&](int i, int j, int k) {
    const auto key = std::make_tuple(i, j, k);
    auto it = index.find(key);
    if (it != index.end()) return it->second;
    v.emplace_back(sx * i / nx, sy * j / ny, sz * k / nz);
    return index[key] = int(v.size()) - 1;
  };
  std::vector<Eigen::Vector3i> f;
  for (int axis = 0; axis < 3; ++axis)
    for (int side = 0; side < 2; ++side) {
      const int a = (axis + 1) % 3, b = (axis + 2) % 3;
      Eigen::Vector3d outward = Eigen::Vector3d::Zero();
      outward(axis) = side ? 1 : -1;
      for (int u = 0; u < n[a]; ++u)
        for (int w = 0; w < n[b]; ++w) {
          int q[4];
          const int du[4] = {0, 1, 1, 0}, dw[4] = {0, 0, 1, 1};
          for (int c4 = 0; c4 < 4; ++c4) {
            int ijk[3];
            ijk[axis] = side ? n[axis] : 0;
            ijk[a] = u + du[c4];
            ijk[b] = w + dw[c4];
            q[c4] = vid(ijk[0], ijk[1], ijk[2]);
          }
          Eigen::Vector3i t1(q[0], q[1], q[2]), t2(q[0], q[2], q[3]);
          const Eigen::Vector3d nrm = (v[std::size_t(q[1])] - v[std::size_t(q[0])]).cross(v[std::size_t(q[2])] - v[std::size_t(q[0])]);
          if (nrm.dot(outward) < 0) {
            std::swap(t1(1), t1(2));
            std::swap(t2(1), t2(2));
          }
          f.push_back(t1);
          f.push_back(t2);
        }
    }
  TriMesh m;
  m.V.resize(Eigen::Index(v.size()), 3);
  for (std::size_t i = 0; i < v.size(); ++i) m.V.row(Eigen::Index(i)) = v[i].transpose();
  m.F.resize(Eigen::Index(f.size()), 3);
  for (std::size_t i = 0; i < f.size(); ++i) m.F.row(Eigen::Index(i)) = f[i].transpose();
  return m;
}

}  // namespace tbsp
