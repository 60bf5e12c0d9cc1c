// Table 4.1 of the thesis: inverse texture mapping stage timings at the table's sizes, plus a
// 5-megapixel image with peak memory. Usage: bench_texture [--quick] [--repeat N]
// [--only ROW] (each time is the median of N runs; the 5 MP row runs once; --only 5 runs just
// the 5 MP row so that the peak RSS column is its own).
#include <sys/resource.h>

#include <Eigen/Dense>

#include <cstdio>
#include <algorithm>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

#include "tbsp/core/huge_pages.h"
#include "tbsp/fitting/inverse_texture_mapping.h"
#include "tbsp/io/mesh_io.h"
#include "tbsp/mesh/remeshing.h"

using namespace tbsp;

namespace {
std::string shared(const std::string& rel) { return std::string(TBSP_SHARED_DATA_DIR) + "/" + rel; }

/// k constraints at farthest-point-sampled vertices placed by a reference layout: planar (PCA
/// projection, for the flat face.off patch) or cylindrical about the vertical axis (face.obj: a
/// face mask that wraps round to the ears; y up, looking towards +z, axis at z = -2; vertices
/// more than 100° round the axis are not used).
std::vector<TextureConstraint> constraints(const TriMesh& m, int W, int H, int k, bool cylindrical) {
  Eigen::MatrixX2d P(m.V.rows(), 2);
  std::vector<char> usable(m.V.rows(), 1);
  if (!cylindrical) {
    const Eigen::RowVector3d c = m.V.colwise().mean();
    const Eigen::MatrixX3d X = m.V.rowwise() - c;
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(X.transpose() * X);
    P.col(0) = X * es.eigenvectors().col(2);
    P.col(1) = -(X * es.eigenvectors().col(1));
  } else {
    const double zc = -2, R = 13, umax = 100 * M_PI / 180;
    for (Eigen::Index i = 0; i < m.V.rows(); ++i) {
      const double u = std::atan2(m.V(i, 0), m.V(i, 2) - zc);
      P(i, 0) = R * u;
      P(i, 1) = -m.V(i, 1);
      usable[i] = std::abs(u) < umax;
    }
  }
  Eigen::RowVector2d lo(1e300, 1e300), hi(-1e300, -1e300);
  for (Eigen::Index i = 0; i < m.V.rows(); ++i)
    if (usable[i]) {
      lo = lo.cwiseMin(P.row(i));
      hi = hi.cwiseMax(P.row(i));
    }
  const double s = std::min((W - 1) * 0.88 / (hi.x() - lo.x()), (H - 1) * 0.88 / (hi.y() - lo.y()));
  std::vector<int> pick;
  Eigen::VectorXd d = Eigen::VectorXd::Constant(m.V.rows(), 1e300);
  int f = 0;
  while (!usable[f]) ++f;
  while (static_cast<int>(pick.size()) < k) {
    pick.push_back(f);
    d = d.cwiseMin((m.V.rowwise() - m.V.row(f)).rowwise().norm());
    for (Eigen::Index i = 0; i < m.V.rows(); ++i)
      if (!usable[i]) d(i) = -1;
    Eigen::Index next = 0;
    d.maxCoeff(&next);
    f = static_cast<int>(next);
  }
  std::vector<TextureConstraint> out;
  for (int v : pick) {
    TextureConstraint t;
    t.vertex = v;
    t.pixel = Eigen::Vector2d((W - 1) / 2.0 + s * (P(v, 0) - 0.5 * (lo.x() + hi.x())), (H - 1) / 2.0 + s * (P(v, 1) - 0.5 * (lo.y() + hi.y())));
    bool clash = false;  // a fold of the layout: skip vertices landing on a used pixel
    for (const auto& o : out) clash = clash || (o.pixel - t.pixel).norm() < 3.0;
    if (!clash) out.push_back(t);
  }
  return out;
}

TriMesh subdivide_all(const TriMesh& m) {
  SubdivisionResult r = adaptive_subdivide(m.V, m.F, std::vector<char>(m.F.rows(), 1));
  TriMesh out;
  out.V = r.V;
  out.F = r.F;
  return out;
}

long peak_rss_mb() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return u.ru_maxrss / 1024;
}
}  // namespace

int main(int argc, char** argv) {
  tbsp::reexec_with_huge_pages(argv);  // as the tbsp CLI (tbsp/core/huge_pages.h)
  bool quick = false;
  int repeat = 3;
  int only = -1;  // run just this row (0-based), e.g. to read the 5 MP row's own peak memory
  for (int i = 1; i < argc; ++i) {
    if (std::strcmp(argv[i], "--quick") == 0) quick = true;
    else if (std::strcmp(argv[i], "--repeat") == 0 && i + 1 < argc) repeat = std::max(1, std::atoi(argv[++i]));
    else if (std::strcmp(argv[i], "--only") == 0 && i + 1 < argc) only = std::atoi(argv[++i]);
    else {
      std::fprintf(stderr, "usage: bench_texture [--quick] [--repeat N] [--only ROW]   (medians of N runs per row, default 3; ROW 0-based)\n");
      return 2;
    }
  }
  const TriMesh small = read_mesh(shared("meshes/cfwen__geometry-processing-package/data/face.off"));
  const TriMesh face = read_mesh(shared("meshes/libigl__libigl-tutorial-data/face.obj"));
  struct Row {
    std::string model;
    TriMesh mesh;
    int W, H, k;
    bool cylindrical;
  };
  const TriMesh bunny = read_mesh(shared("meshes/dengnantianjie__3dcoursework/bunny/reconstruction/bun_zipper.ply"));
  std::vector<Row> rows{{"face.off", small, 200, 200, 24, false},
                        {"face.obj", face, 256, 256, 26, true},
                        {"bun_zipper.ply", bunny, 256, 256, 26, false}};
  if (!quick) {
    rows.push_back({"face.obj", face, 512, 512, 26, true});
    rows.push_back({"face.obj x4", subdivide_all(subdivide_all(face)), 256, 256, 25, true});
    rows.push_back({"face.obj (5 MP)", face, 2592, 1944, 26, true});
  }
  std::printf("| model | vertices | pixels | solve nodes | k | deform 1 | mesh geod | texture geod | matching | deform 2 | total (s) | thesis total | matched | max residual px | peak RSS MB |\n");
  std::printf("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n");
  const char* thesis[] = {"19.97 (1394/40K)", "51.4 (33K/65K)", "51.4 (33K/65K)", "212.52 (33K/262K)", "66.61 (220K/65K)", "could not"};
  for (std::size_t i = 0; i < rows.size(); ++i) {
    if (only >= 0 && static_cast<std::size_t>(only) != i) continue;
    const Row& r = rows[i];
    InverseTextureMapping itm;
    itm.setInputMesh(r.mesh);
    itm.setImageSize(r.W, r.H);
    itm.setConstraints(constraints(r.mesh, r.W, r.H, r.k, r.cylindrical));
    const int reps = i + 1 == rows.size() && !quick ? 1 : repeat;  // the 5 MP row once
    std::vector<TextureMappingReport> runs;
    for (int t = 0; t < reps; ++t) runs.push_back(itm.compute().report);
    auto median = [&](double TextureMappingReport::*field) {
      std::vector<double> v;
      for (const auto& p : runs) v.push_back(p.*field);
      std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2), v.end());
      return v[v.size() / 2];
    };
    const auto& p = runs.front();
    std::printf("| %s | %ld | %ld | %ld | %d | %.2f | %.2f | %.2f | %.2f | %.2f | %.2f | %s | %.3f | %.2f | %ld |\n", r.model.c_str(),
                static_cast<long>(r.mesh.V.rows()), p.pixels, p.grid_nodes, r.k, median(&TextureMappingReport::t_deform1),
                median(&TextureMappingReport::t_mesh_geodesics), median(&TextureMappingReport::t_texture_geodesics),
                median(&TextureMappingReport::t_matching), median(&TextureMappingReport::t_deform2), median(&TextureMappingReport::t_total),
                thesis[i], p.matched_fraction, p.max_constraint_residual_px, peak_rss_mb());
    std::fflush(stdout);
  }
  return 0;
}
