// Benchmarks of the mesh queries every fit report, benchmark and acceptance figure uses:
// exact point-to-mesh distances (tbsp::point_mesh_distances, Embree's BVH) against CGAL's AABB
// tree (tbsp::MeshDistance) in the same run.
// Run: ./build/bench/bench_mesh [--benchmark_filter=...] [--benchmark_repetitions=5]
//
// Mesh: the Stanford Armadillo of ../shared/data (49,990 vertices, 99,976 faces; an icosphere
// of 40,962 vertices without it). Queries, 100,000 per call:
//   arg 0 "near": surface points (random face, random barycentrics, seed 1) moved along the
//         face normal by N(0, σ = 0.2 % of the bounding-box diagonal), like a scan's samples;
//   arg 1 "mixed": the same with every 10th point uniform in the box grown by 10 % (outliers,
//         as in bench_fit's ground-truth scans).
#include <benchmark/benchmark.h>

#include "bench_main.h"

#include <Eigen/Geometry>

#include <filesystem>
#include <random>
#include <string>

#include "tbsp/io/mesh_io.h"
#include "tbsp/mesh/point_mesh_distance.h"
#include "tbsp/mesh/primitives.h"

using namespace tbsp;

namespace {

const TriMesh& armadillo() {
  static const TriMesh m = [] {
    const std::string p = std::string(TBSP_SHARED_DATA_DIR) + "/meshes/keeganl__linear-subspace-deformation/armadillo.off";
    return std::filesystem::exists(p) ? read_mesh(p) : make_icosphere(6);
  }();
  return m;
}

Eigen::MatrixX3d queries(const TriMesh& m, bool outliers) {
  const Eigen::Vector3d lo = m.V.colwise().minCoeff(), hi = m.V.colwise().maxCoeff();
  const double diag = (hi - lo).norm();
  std::mt19937 rng(1);
  std::uniform_int_distribution<Eigen::Index> face(0, m.F.rows() - 1);
  std::uniform_real_distribution<double> u(0, 1);
  std::normal_distribution<double> noise(0, 0.002 * diag);
  Eigen::MatrixX3d Q(100000, 3);
  for (Eigen::Index i = 0; i < Q.rows(); ++i) {
    if (outliers && i % 10 == 0) {
      for (int k = 0; k < 3; ++k) Q(i, k) = lo(k) - 0.1 * (hi(k) - lo(k)) + 1.2 * (hi(k) - lo(k)) * u(rng);
      continue;
    }
    const Eigen::Index f = face(rng);
    const Eigen::Vector3d a = m.V.row(m.F(f, 0)), b = m.V.row(m.F(f, 1)), c = m.V.row(m.F(f, 2));
    double s = u(rng), t = u(rng);
    if (s + t > 1) s = 1 - s, t = 1 - t;
    const Eigen::Vector3d n = (b - a).cross(c - a).normalized();
    Q.row(i) = (a + s * (b - a) + t * (c - a) + noise(rng) * n).transpose();
  }
  return Q;
}

}  // namespace

static void BM_PointMeshDistances(benchmark::State& st) {
  const TriMesh& m = armadillo();
  const Eigen::MatrixX3d Q = queries(m, st.range(0) == 1);
  for (auto _ : st) benchmark::DoNotOptimize(point_mesh_distances(m.V, m.F, Q));
  st.counters["faces"] = double(m.F.rows());
  st.counters["points"] = double(Q.rows());
}
BENCHMARK(BM_PointMeshDistances)->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond)->UseRealTime();

// the peer: CGAL's AABB tree (built with accelerate_distance_queries), queried in parallel
static void BM_CgalAabbDistances(benchmark::State& st) {
  const TriMesh& m = armadillo();
  const Eigen::MatrixX3d Q = queries(m, st.range(0) == 1);
  for (auto _ : st) {
    const MeshDistance tree(m.V, m.F);
    benchmark::DoNotOptimize(tree.distances(Q));
  }
  st.counters["faces"] = double(m.F.rows());
  st.counters["points"] = double(Q.rows());
}
BENCHMARK(BM_CgalAabbDistances)->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond)->UseRealTime();

TBSP_BENCHMARK_MAIN()
