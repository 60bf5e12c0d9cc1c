// Benchmarks of the Laplacian deformation framework (thesis ch. 3): factorization vs
// back-substitution (prefactor-once / solve-many), CHOLMOD vs Eigen's SimplicialLDLT, and
// the rotation field. Run: ./build/bench/bench_deform [--benchmark_filter=...]
#include <benchmark/benchmark.h>

#include "bench_main.h"

#define CGAL_EIGEN3_ENABLED 1
#include <CGAL/Simple_cartesian.h>
#include <CGAL/Surface_mesh.h>
#include <CGAL/Surface_mesh_deformation.h>

#include <Eigen/Geometry>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <vector>

#include "tbsp/deform/laplacian_deformer.h"
#include "tbsp/io/mesh_io.h"
#include "tbsp/mesh/cotan_laplacian.h"
#include "tbsp/mesh/primitives.h"
#include "tbsp/solve/sparse_cholesky.h"

using namespace tbsp;

namespace {
// arg 4..7: icospheres of 2,562 / 10,242 / 40,962 / 163,842 vertices; 100: a 317 x 317 grid
// (100,489 vertices); 200: a 447 x 447 grid (199,809 vertices); 50: the Stanford Armadillo
// (49,990 vertices, ../shared/data)
TriMesh mesh_for(int arg) {
  if (arg == 100) return make_grid(317, 317);
  if (arg == 200) return make_grid(447, 447);
  if (arg == 50) {
    const std::string p = std::string(TBSP_SHARED_DATA_DIR) + "/meshes/keeganl__linear-subspace-deformation/armadillo.off";
    if (std::filesystem::exists(p)) return read_mesh(p);
    return make_icosphere(6);
  }
  return make_icosphere(arg);
}

void add_handles(LaplacianDeformer& d, const TriMesh& m, double shift) {
  for (Eigen::Index v = 0; v < m.V.rows(); v += m.V.rows() / 50)
    d.addPositionConstraint(SurfacePoint::atVertex(int(v)), m.V.row(v).transpose() + Eigen::Vector3d(shift * double(v % 3), 0, 0));
}
}  // namespace

static void BM_DeformFactorize(benchmark::State& st) {
  const TriMesh m = mesh_for(int(st.range(0)));
  for (auto _ : st) {
    LaplacianDeformer d;
    d.setMesh(m);
    add_handles(d, m, 0.1);
    benchmark::DoNotOptimize(d.deform());
  }
  st.counters["vertices"] = double(m.V.rows());
}
BENCHMARK(BM_DeformFactorize)->DenseRange(4, 6)->Unit(benchmark::kMillisecond);

static void BM_DeformResolveMovedTargets(benchmark::State& st) {
  const TriMesh m = mesh_for(int(st.range(0)));
  LaplacianDeformer d;
  d.setMesh(m);
  add_handles(d, m, 0.1);
  d.deform();
  double s = 0;
  for (auto _ : st) {
    d.setPositionTarget(0, Eigen::Vector3d(s, 0, 0));
    s += 1e-3;
    benchmark::DoNotOptimize(d.deform());
    st.counters["solve_ms"] = 1e3 * d.report().t_solve;
  }
  st.counters["vertices"] = double(m.V.rows());
}
BENCHMARK(BM_DeformResolveMovedTargets)->DenseRange(4, 6)->Arg(50)->Arg(100)->Arg(200)->Unit(benchmark::kMillisecond);

// The peer of an interactive re-solve: one iteration of CGAL's Surface_mesh_deformation (ARAP,
// its own prefactored solver) on the same mesh with the same control vertices, one of them moved.
static void BM_CgalArapIteration(benchmark::State& st) {
  using K = CGAL::Simple_cartesian<double>;
  using SM = CGAL::Surface_mesh<K::Point_3>;
  using VD = boost::graph_traits<SM>::vertex_descriptor;
  const TriMesh m = mesh_for(int(st.range(0)));
  SM sm;
  std::vector<VD> vd;
  for (Eigen::Index i = 0; i < m.V.rows(); ++i) vd.push_back(sm.add_vertex(K::Point_3(m.V(i, 0), m.V(i, 1), m.V(i, 2))));
  for (Eigen::Index f = 0; f < m.F.rows(); ++f) sm.add_face(vd[std::size_t(m.F(f, 0))], vd[std::size_t(m.F(f, 1))], vd[std::size_t(m.F(f, 2))]);
  CGAL::Surface_mesh_deformation<SM> def(sm);
  def.insert_roi_vertices(sm.vertices().begin(), sm.vertices().end());
  std::vector<Eigen::Index> controls;
  for (Eigen::Index v = 0; v < m.V.rows(); v += m.V.rows() / 50) {  // the handles of add_handles()
    def.insert_control_vertex(vd[std::size_t(v)]);
    controls.push_back(v);
  }
  if (!def.preprocess()) {
    st.SkipWithError("CGAL preprocess failed");
    return;
  }
  double s = 0;
  for (auto _ : st) {
    def.set_target_position(vd[0], K::Point_3(m.V(0, 0) + s, m.V(0, 1), m.V(0, 2)));
    s += 1e-3;
    def.deform(1, 0.0);
  }
  st.counters["vertices"] = double(m.V.rows());
}
BENCHMARK(BM_CgalArapIteration)->DenseRange(4, 6)->Arg(50)->Arg(100)->Arg(200)->Unit(benchmark::kMillisecond);

static void BM_DeformRotationField(benchmark::State& st) {
  const TriMesh m = mesh_for(int(st.range(0)));
  for (auto _ : st) {
    LaplacianDeformer d;
    d.setMesh(m);
    add_handles(d, m, 0.1);
    d.setUseRotationField(true);
    benchmark::DoNotOptimize(d.deform());
  }
  st.counters["vertices"] = double(m.V.rows());
}
BENCHMARK(BM_DeformRotationField)->DenseRange(4, 6)->Unit(benchmark::kMillisecond);

static void BM_Factorize(benchmark::State& st, SparseCholesky::Backend backend) {
  const TriMesh m = mesh_for(int(st.range(0)));
  const Eigen::SparseMatrix<double> L = laplacian(m.V, m.F);
  Eigen::SparseMatrix<double> N = Eigen::SparseMatrix<double>(L.transpose() * L);
  for (int i = 0; i < N.rows(); i += 50) N.coeffRef(i, i) += 1.0;
  for (auto _ : st) {
    SparseCholesky s(backend);
    s.compute(N);
    benchmark::DoNotOptimize(s.isFactorized());
  }
  st.counters["vertices"] = double(m.V.rows());
}
BENCHMARK_CAPTURE(BM_Factorize, cholmod, SparseCholesky::Backend::Cholmod)->DenseRange(4, 6)->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_Factorize, eigen_ldlt, SparseCholesky::Backend::EigenLDLT)->DenseRange(4, 6)->Unit(benchmark::kMillisecond);

static void BM_RefactorizeSamePattern(benchmark::State& st) {
  const TriMesh m = mesh_for(int(st.range(0)));
  const Eigen::SparseMatrix<double> L = laplacian(m.V, m.F);
  Eigen::SparseMatrix<double> N = Eigen::SparseMatrix<double>(L.transpose() * L);
  for (int i = 0; i < N.rows(); ++i) N.coeffRef(i, i) += 1.0;
  SparseCholesky s;
  s.compute(N);
  double w = 1.0;
  for (auto _ : st) {
    for (int i = 0; i < N.rows(); i += 3) N.coeffRef(i, i) += (w += 1e-3);
    s.compute(N);  // numeric factorization only: the analysis is reused
  }
  st.counters["vertices"] = double(m.V.rows());
  st.counters["analyses"] = s.numAnalyses();
}
BENCHMARK(BM_RefactorizeSamePattern)->DenseRange(4, 6)->Unit(benchmark::kMillisecond);

// LᵀL of m with every 50th diagonal entry + 1 (the matrix of BM_Factorize), factorized into s.
static Eigen::SparseMatrix<double> factorized_bilaplacian(const TriMesh& m, SparseCholesky& s) {
  const Eigen::SparseMatrix<double> L = laplacian(m.V, m.F);
  Eigen::SparseMatrix<double> N = Eigen::SparseMatrix<double>(L.transpose() * L);
  for (int i = 0; i < N.rows(); i += 50) N.coeffRef(i, i) += 1.0;
  s.compute(N);
  return N;
}

// Back-substitution alone (three right-hand sides, the x, y, z of a re-solve) on the same
// matrix as BM_Factorize: what deform() pays on top of it is the right-hand side and the report.
static void BM_CholeskySolve3(benchmark::State& st, bool cholmod_solve) {
  const TriMesh m = mesh_for(int(st.range(0)));
  SparseCholesky s;
  const Eigen::SparseMatrix<double> N = factorized_bilaplacian(m, s);
  s.setCholmodSolve(cholmod_solve);
  const Eigen::MatrixXd B = Eigen::MatrixXd::Ones(N.rows(), 3);
  Eigen::MatrixXd X;
  for (auto _ : st) {
    s.solve(B, X);
    benchmark::DoNotOptimize(X.data());
  }
  st.counters["vertices"] = double(m.V.rows());
  st.counters["factor_MB"] = 8e-6 * double(s.factorNonZeros());
}
BENCHMARK_CAPTURE(BM_CholeskySolve3, tbsp, false)->DenseRange(4, 6)->Arg(50)->Arg(100)->Arg(200)->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_CholeskySolve3, cholmod, true)->DenseRange(4, 6)->Arg(50)->Arg(100)->Arg(200)->Unit(benchmark::kMillisecond);

// The memory floor of a solve: streaming as many doubles as the factor stores, twice (forward
// and backward), on 1 or 2 threads; what BM_CholeskySolve3/tbsp costs above it is arithmetic
// and gathers, not bandwidth.
static void BM_StreamFactorTwice(benchmark::State& st) {
  const TriMesh m = mesh_for(int(st.range(0)));
  SparseCholesky s;
  factorized_bilaplacian(m, s);
  const std::vector<double> values(s.factorNonZeros(), 1.0);
  const long count = long(values.size());
  const int threads = int(st.range(1));
  for (auto _ : st) {
    double sum = 0;
    for (int pass = 0; pass < 2; ++pass) {
#pragma omp parallel for simd num_threads(threads) reduction(+ : sum)
      for (long i = 0; i < count; ++i) sum += values[std::size_t(i)];
    }
    benchmark::DoNotOptimize(sum);
  }
  st.counters["vertices"] = double(m.V.rows());
  st.counters["factor_MB"] = 8e-6 * double(values.size());
}
BENCHMARK(BM_StreamFactorTwice)->ArgsProduct({{4, 6, 50, 100, 200}, {1, 2}})->Unit(benchmark::kMillisecond);

// The deformation survey's 40k-vertex `plane` (Botsch & Sorkine 2008; ../shared/data,
// EmperorJack__ShapeDeformer): a fixed region (1,809 vertices) and a handle region (1,608)
// moved by the .def transform, hard, with the rotation field: first deform() from scratch
// (constraint graph + rotation field + factorization + solve). arg 1: each region one handle
// group (one graph node each); arg 0: every constrained vertex its own node (before the
// handle groups: 27.8 s here).
static void BM_SurveyPlaneRotationField(benchmark::State& st) {
  const std::string dir = std::string(TBSP_SHARED_DATA_DIR) + "/meshes/EmperorJack__ShapeDeformer/res/";
  if (!std::filesystem::exists(dir + "plane.off")) {
    st.SkipWithError("../shared/data missing");
    return;
  }
  const TriMesh m = read_mesh(dir + "plane.off");
  std::ifstream sel(dir + "plane.sel"), def(dir + "plane.def");
  std::vector<int> status;
  Eigen::Matrix4d M;
  std::string line;
  while (std::getline(sel, line))
    if (!line.empty() && line[0] != '#') status.push_back(std::stoi(line));
  int r = 0;
  while (std::getline(def, line))
    if (!line.empty() && line[0] != '#') {
      std::istringstream is(line);
      for (int c = 0; c < 4; ++c) is >> M(r, c);
      ++r;
    }
  const bool grouped = st.range(0) == 1;
  for (auto _ : st) {
    const auto t0 = std::chrono::steady_clock::now();
    LaplacianDeformer d;
    d.setMesh(m);
    st.counters["setmesh_s"] = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    for (Eigen::Index v = 0; v < m.V.rows(); ++v) {
      if (status[std::size_t(v)] == 1) continue;
      DeformConstraint c;
      c.at = SurfacePoint::atVertex(int(v));
      c.hard = true;
      c.group = grouped ? status[std::size_t(v)] : -1;
      const Eigen::Matrix4d T = status[std::size_t(v)] == 2 ? M : Eigen::Matrix4d::Identity();
      c.target = (T * m.V.row(v).transpose().homogeneous()).head<3>();
      c.rotation = Eigen::Matrix3d(T.topLeftCorner<3, 3>());
      d.addConstraint(c);
    }
    d.setUseRotationField(true);
    benchmark::DoNotOptimize(d.deform());
    st.counters["nodes"] = d.report().rotation_nodes;
    st.counters["graph_s"] = d.report().t_graph;
    st.counters["factorize_s"] = d.report().t_factorize;
    st.counters["laplacian_s"] = d.report().t_laplacian;
    st.counters["rotations_s"] = d.report().t_rotations;
    st.counters["solve_s"] = d.report().t_solve;
  }
}
BENCHMARK(BM_SurveyPlaneRotationField)->Arg(1)->Arg(0)->Iterations(1)->Unit(benchmark::kMillisecond);

TBSP_BENCHMARK_MAIN()
