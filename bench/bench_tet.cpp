// bench_tet — thesis Table 8.1 for tbsp::TetDeformer + DeformationTransfer, with CGAL's
// Surface_mesh_deformation (ARAP) on the surface of the same model with the same handles.
//
//   ./build/bench/bench_tet [--quick]
//
// Per model: tet vertices / tets, factorization, per-iteration step times (def = linear solve,
// rotext, rotint, rigid, difupd; medians over the run), iterations per second; for the
// Armadillo, the transfer to 43k and 173k (one 1-to-4 subdivision) vertices: precompute and
// apply (median of 21). The CGAL rows: the same model's tet-mesh boundary surface (identical
// vertices), the same fixed and moved handle vertices, ARAP iterations timed one by one; volume
// change of the closed surface for both methods after the same number of iterations.
#define CGAL_EIGEN3_ENABLED 1
#include <CGAL/Simple_cartesian.h>
#include <CGAL/Surface_mesh.h>
#include <CGAL/Surface_mesh_deformation.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <string>
#include <vector>

#include <omp.h>

#include "tbsp/core/huge_pages.h"
#include "tbsp/deform/deformation_transfer.h"
#include "tbsp/deform/tet_deformer.h"
#include "tbsp/io/mesh_io.h"
#include "tbsp/io/tet_mesh_io.h"
#include "tbsp/mesh/primitives.h"
#include "tbsp/mesh/remeshing.h"
#include "tbsp/mesh/tetrahedralize.h"

using namespace tbsp;
using Clock = std::chrono::steady_clock;

namespace {
double since(Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); }
double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v.empty() ? 0 : v[v.size() / 2];
}
const std::string kData = TBSP_SHARED_DATA_DIR;

double enclosed_volume(const Eigen::MatrixX3d& V, const Eigen::MatrixX3i& F) {
  double v = 0;
  for (Eigen::Index f = 0; f < F.rows(); ++f)
    v += Eigen::Vector3d(V.row(F(f, 0))).dot(Eigen::Vector3d(V.row(F(f, 1))).cross(Eigen::Vector3d(V.row(F(f, 2))))) / 6.0;
  return v;
}

struct Model {
  std::string name;
  TetMesh tets;
  std::vector<int> fixed, moved;  // tet vertex ids
  RigidMotion motion;
};

// Lowest 8 % of the vertices (by y) fixed; the highest 8 % turned by 40 degrees about z and
// pulled sideways by 10 % of the height (a lean, like Fig. 8.1/8.2 edits).
Model make_model(const std::string& name, TetMesh t) {
  Model m{name, std::move(t), {}, {}, {}};
  const double lo = m.tets.V.col(1).minCoeff(), hi = m.tets.V.col(1).maxCoeff(), h = hi - lo;
  for (Eigen::Index i = 0; i < m.tets.V.rows(); ++i) {
    if (m.tets.V(i, 1) < lo + 0.08 * h) m.fixed.push_back(int(i));
    if (m.tets.V(i, 1) > hi - 0.08 * h) m.moved.push_back(int(i));
  }
  const Eigen::Vector3d c = m.tets.V.colwise().mean().transpose();
  m.motion = RigidMotion::rotation(Eigen::Vector3d::UnitZ(), 40 * M_PI / 180, Eigen::Vector3d(c.x(), hi, c.z()),
                                   Eigen::Vector3d(-0.1 * h, 0, 0));
  return m;
}

struct TetRow {
  double factorize = 0, def = 0, rotext = 0, rotint = 0, rigid = 0, difupd = 0, its = 0, its_still = 0, vol = 0;
};

TetRow run_tet(const Model& m, int iterations) {
  TetDeformer d;
  d.setMesh(m.tets);
  d.addRegionHandle(m.fixed, {});
  RigidMotion start = m.motion;
  start.angle = 0;
  start.translation.setZero();
  const int moving = d.addRegionHandle(m.moved, start);
  TetDeformerOptions o;
  o.tolerance = 0;  // run all iterations
  d.setOptions(o);
  std::vector<double> def, rotext, rotint, difupd, rigid, total;
  d.iterate();  // factorizes (timed separately) and ramps
  TetRow r;
  r.factorize = d.report().t_factorize + d.report().t_setup + d.report().t_factorize_rotint;
  for (int k = 1; k < iterations; ++k) {
    // interactive drag: the handle moves a little every iteration (as in the thesis' fps)
    RigidMotion now = m.motion;
    now.angle *= double(k) / (iterations - 1);
    now.translation *= double(k) / (iterations - 1);
    d.setRegionMotion(moving, now);
    const TetDeformReport a = d.report();
    d.iterate();
    const TetDeformReport& b = d.report();
    def.push_back(b.t_def - a.t_def);
    rotext.push_back(b.t_rotext - a.t_rotext);
    rotint.push_back(b.t_rotint - a.t_rotint);
    rigid.push_back(b.t_rigid - a.t_rigid);
    difupd.push_back(b.t_difupd - a.t_difupd);
    total.push_back(def.back() + rotext.back() + rotint.back() + rigid.back() + difupd.back());
  }
  r.def = median(def);
  r.rotext = median(rotext);
  r.rotint = median(rotint);
  r.rigid = median(rigid);
  r.difupd = median(difupd);
  r.its = 1.0 / median(total);
  r.its_still = 1.0 / (r.def + r.rotext + r.rigid + r.difupd);  // step (III) is skipped while handles are still
  const Eigen::MatrixX3i F = tet_boundary_faces(m.tets.T);
  r.vol = enclosed_volume(d.positions(), F) / enclosed_volume(m.tets.V, F) - 1;
  return r;
}

struct CgalRow {
  double per_iteration = 0, vol = 0;
  bool ok = false;
};

CgalRow run_cgal(const Model& m, int iterations) {
  using K = CGAL::Simple_cartesian<double>;
  using SM = CGAL::Surface_mesh<K::Point_3>;
  using VD = boost::graph_traits<SM>::vertex_descriptor;
  const Eigen::MatrixX3i F = tet_boundary_faces(m.tets.T);
  SM sm;
  std::vector<VD> vd(std::size_t(m.tets.V.rows()));
  std::vector<char> used(std::size_t(m.tets.V.rows()), 0);
  for (Eigen::Index f = 0; f < F.rows(); ++f)
    for (int k = 0; k < 3; ++k) used[std::size_t(F(f, k))] = 1;
  for (Eigen::Index i = 0; i < m.tets.V.rows(); ++i)
    if (used[std::size_t(i)]) vd[std::size_t(i)] = sm.add_vertex(K::Point_3(m.tets.V(i, 0), m.tets.V(i, 1), m.tets.V(i, 2)));
  CgalRow r;
  for (Eigen::Index f = 0; f < F.rows(); ++f)
    if (sm.add_face(vd[std::size_t(F(f, 0))], vd[std::size_t(F(f, 1))], vd[std::size_t(F(f, 2))]) == SM::null_face())
      return r;  // boundary surface not a 2-manifold for Surface_mesh: no CGAL row
  CGAL::Surface_mesh_deformation<SM> def(sm);
  def.insert_roi_vertices(sm.vertices().begin(), sm.vertices().end());
  std::vector<int> handles;
  for (int v : m.fixed)
    if (used[std::size_t(v)]) def.insert_control_vertex(vd[std::size_t(v)]), handles.push_back(v);
  for (int v : m.moved)
    if (used[std::size_t(v)]) def.insert_control_vertex(vd[std::size_t(v)]);
  if (!def.preprocess()) return r;
  for (int v : m.moved)
    if (used[std::size_t(v)]) {
      const Eigen::Vector3d p = m.motion.apply(m.tets.V.row(v).transpose());
      def.set_target_position(vd[std::size_t(v)], K::Point_3(p.x(), p.y(), p.z()));
    }
  std::vector<double> t;
  for (int k = 0; k < iterations; ++k) {
    const auto t0 = Clock::now();
    def.deform(1, 0.0);
    t.push_back(since(t0));
  }
  r.per_iteration = median(t);
  Eigen::MatrixX3d X = m.tets.V;
  for (Eigen::Index i = 0; i < X.rows(); ++i)
    if (used[std::size_t(i)]) {
      const auto& p = sm.point(vd[std::size_t(i)]);
      X.row(i) << p.x(), p.y(), p.z();
    }
  r.vol = enclosed_volume(X, F) / enclosed_volume(m.tets.V, F) - 1;
  r.ok = true;
  return r;
}
}  // namespace

int main(int argc, char** argv) {
  tbsp::reexec_with_huge_pages(argv);  // as the tbsp CLI (tbsp/core/huge_pages.h)
  const bool quick = argc > 1 && std::strcmp(argv[1], "--quick") == 0;
  const int iterations = 60;
  std::printf("threads: %d, %d iterations per model (timings: medians per iteration, ms)\n\n", omp_get_max_threads(), iterations);
  std::vector<Model> models;
  auto t0 = Clock::now();
  {
    // The bar of Fig. 7.2/7.3 (lying along x): left end fixed, right end bent down by 90
    // degrees onto the arc a length-preserving bend would give.
    TetgenOptions o;
    o.max_volume = std::pow(0.05, 3) / 6;
    Model bar{"Bar (Fig. 7.3 bend)", tetrahedralize(make_box(20, 4, 4, 1.0, 0.2, 0.2), o), {}, {}, {}};
    for (Eigen::Index i = 0; i < bar.tets.V.rows(); ++i) {
      if (bar.tets.V(i, 0) <= 0.05 + 1e-9) bar.fixed.push_back(int(i));
      if (bar.tets.V(i, 0) >= 0.95 - 1e-9) bar.moved.push_back(int(i));
    }
    const double th = M_PI / 2, rho = 0.9 / th;
    const Eigen::Vector3d start(0.95, 0.1, 0.1), end(0.05 + rho, 0.1, 0.1 - rho);
    bar.motion = RigidMotion::rotation(Eigen::Vector3d::UnitY(), th, start, end - start);
    models.push_back(bar);
  }
  const TriMesh arm = read_mesh(kData + "/meshes/libigl__libigl-tutorial-data/armadillo.obj");
  models.push_back(make_model("Armadillo", tetrahedralize_to_size(arm, 5400)));
  models.push_back(make_model("Octopus (libigl .mesh)", read_tet_mesh(kData + "/meshes/libigl__libigl-tutorial-data/octopus-low.mesh")));
  if (!quick) {
    models.push_back(make_model("Armadillo", tetrahedralize_to_size(arm, 25000)));
    models.push_back(make_model("Hand (libigl .mesh)", read_tet_mesh(kData + "/meshes/libigl__libigl-tutorial-data/hand.mesh")));
    models.push_back(make_model("Bunny (libigl .mesh)", read_tet_mesh(kData + "/meshes/libigl__libigl-tutorial-data/bunny.mesh")));
    models.push_back(make_model("Armadillo", tetrahedralize_to_size(arm, 100000)));
  }
  std::printf("(models prepared in %.1f s: decimation + TetGen)\n\n", since(t0));
  std::printf("| model | vertices / tets | factorize ms | def | rotext | rotint | rigid | difupd | iterations/s (dragging) | iterations/s (handles still) | volume change | "
              "CGAL ARAP (surface) ms/iteration | CGAL volume change | speed ratio tbsp/CGAL |\n"
              "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n");
  for (const Model& m : models) {
    const TetRow r = run_tet(m, iterations);
    const CgalRow c = run_cgal(m, iterations);
    std::printf("| %s | %ld / %ld | %.1f | %.3f | %.3f | %.3f | %.3f | %.3f | %.0f | %.0f | %+.2f %% | %s | %s | %s |\n", m.name.c_str(),
                long(m.tets.V.rows()), long(m.tets.T.rows()), 1e3 * r.factorize, 1e3 * r.def, 1e3 * r.rotext, 1e3 * r.rotint,
                1e3 * r.rigid, 1e3 * r.difupd, r.its, r.its_still, 100 * r.vol,
                c.ok ? std::to_string(1e3 * c.per_iteration).substr(0, 6).c_str() : "n/a (non-manifold surface)",
                c.ok ? (std::to_string(100 * c.vol).substr(0, 6) + " %").c_str() : "-",
                c.ok ? (std::to_string(c.per_iteration * r.its).substr(0, 5) + "x").c_str() : "-");
    std::fflush(stdout);
  }

  // Deformation transfer (§7.3): Armadillo tet mesh -> 43k and 173k vertices.
  std::printf("\n| transfer | tet mesh vertices / tets | high-res vertices | precompute s | apply ms (median of 21) | "
              "tets per vertex | nnz(B) |\n|---|---|---|---|---|---|---|\n");
  const Model& am = models[1];
  TriMesh big = arm;
  {
    const SubdivisionResult s = adaptive_subdivide(arm.V, arm.F, std::vector<char>(std::size_t(arm.F.rows()), 1));
    big.V = s.V;
    big.F = s.F;
  }
  TetDeformer d;
  d.setMesh(am.tets);
  d.addRegionHandle(am.fixed, {});
  d.addRegionHandle(am.moved, am.motion);
  const Eigen::MatrixX3d X = d.deform(30);
  for (const TriMesh* hi : std::vector<const TriMesh*>{&arm, &big}) {
    DeformationTransfer dt;
    dt.precompute(am.tets, hi->V);
    std::vector<double> t;
    Eigen::MatrixX3d out;
    for (int k = 0; k < 21; ++k) {
      const auto a = Clock::now();
      out = dt.apply(X);
      t.push_back(since(a));
    }
    std::printf("| Armadillo | %ld / %ld | %ld | %.2f | %.1f | %.1f | %ld |\n", long(am.tets.V.rows()), long(am.tets.T.rows()),
                long(hi->V.rows()), dt.precomputeSeconds(), 1e3 * median(t), dt.meanTetsPerVertex(), long(dt.matrix().nonZeros()));
  }
  return 0;
}
