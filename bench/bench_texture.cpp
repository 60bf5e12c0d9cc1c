// Table 4.1 of the thesis: inverse texture mapping stage timings at the table's sizes, plus a
// 5-megapixel image with peak memory. Usage: bench_texture [--quick]
#include <sys/resource.h>

#include <Eigen/Dense>

#include <cstdio>
#include <cstring>
#include <string>
#include <vector>

#include "tbsp/fitting/inverse_texture_mapping.h"
#include "tbsp/io/mesh_io.h"
#include "tbsp/mesh/remeshing.h"

using namespace tbsp;

namespace {
std::string shared(const std::string& rel) { return std::string(TBSP_SHARED_DATA_DIR) + "/" + rel; }

/// Constraints from a planar (PCA) layout at farthest-point-sampled vertices.
std::vector<TextureConstraint> constraints(const TriMesh& m, int W, int H, int k) {
  const Eigen::RowVector3d c = m.V.colwise().mean();
  const Eigen::MatrixX3d X = m.V.rowwise() - c;
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(X.transpose() * X);
  Eigen::MatrixX2d P(m.V.rows(), 2);
  P.col(0) = X * es.eigenvectors().col(2);
  P.col(1) = -(X * es.eigenvectors().col(1));
  const Eigen::RowVector2d lo = P.colwise().minCoeff(), hi = P.colwise().maxCoeff();
  const double s = std::min((W - 1) * 0.88 / (hi.x() - lo.x()), (H - 1) * 0.88 / (hi.y() - lo.y()));
  std::vector<int> pick{0};
  Eigen::VectorXd d = (m.V.rowwise() - m.V.row(0)).rowwise().norm();
  while (static_cast<int>(pick.size()) < k) {
    Eigen::Index f = 0;
    d.maxCoeff(&f);
    pick.push_back(static_cast<int>(f));
    d = d.cwiseMin((m.V.rowwise() - m.V.row(f)).rowwise().norm());
  }
  std::vector<TextureConstraint> out;
  for (int v : pick) {
    TextureConstraint t;
    t.vertex = v;
    t.pixel = Eigen::Vector2d((W - 1) / 2.0 + s * (P(v, 0) - 0.5 * (lo.x() + hi.x())), (H - 1) / 2.0 + s * (P(v, 1) - 0.5 * (lo.y() + hi.y())));
    bool clash = false;  // a fold of the projection: skip vertices landing on a used pixel
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
  const bool quick = argc > 1 && std::strcmp(argv[1], "--quick") == 0;
  const TriMesh small = read_mesh(shared("meshes/cfwen__geometry-processing-package/data/face.off"));
  const TriMesh face = read_mesh(shared("meshes/libigl__libigl-tutorial-data/face.obj"));
  struct Row {
    std::string model;
    TriMesh mesh;
    int W, H, k;
  };
  std::vector<Row> rows{{"face.off", small, 200, 200, 24}, {"face.obj", face, 256, 256, 26}};
  if (!quick) {
    rows.push_back({"face.obj", face, 512, 512, 26});
    rows.push_back({"face.obj x4", subdivide_all(subdivide_all(face)), 256, 256, 25});
    rows.push_back({"face.obj (5 MP)", face, 2592, 1944, 26});
  }
  std::printf("| model | vertices | pixels | solve nodes | k | deform 1 | mesh geod | texture geod | matching | deform 2 | total (s) | thesis total | matched | max residual px | peak RSS MB |\n");
  std::printf("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n");
  const char* thesis[] = {"19.97 (1394/40K)", "51.4 (33K/65K)", "212.52 (33K/262K)", "66.61 (220K/65K)", "could not"};
  for (std::size_t i = 0; i < rows.size(); ++i) {
    const Row& r = rows[i];
    InverseTextureMapping itm;
    itm.setInputMesh(r.mesh);
    itm.setImageSize(r.W, r.H);
    itm.setConstraints(constraints(r.mesh, r.W, r.H, r.k));
    const TextureMappingResult res = itm.compute();
    const auto& p = res.report;
    std::printf("| %s | %ld | %ld | %ld | %d | %.2f | %.2f | %.2f | %.2f | %.2f | %.2f | %s | %.3f | %.2f | %ld |\n", r.model.c_str(),
                static_cast<long>(r.mesh.V.rows()), p.pixels, p.grid_nodes, r.k, p.t_deform1, p.t_mesh_geodesics, p.t_texture_geodesics,
                p.t_matching, p.t_deform2, p.t_total, thesis[i], p.matched_fraction, p.max_constraint_residual_px, peak_rss_mb());
    std::fflush(stdout);
  }
  return 0;
}
