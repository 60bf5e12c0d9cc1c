// Tet deformation and deformation transfer on real meshes from ../shared/data (integration).
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <algorithm>

#include "test_util.h"
#include "tbsp/deform/deformation_transfer.h"
#include "tbsp/deform/tet_deformer.h"
#include "tbsp/io/mesh_io.h"
#include "tbsp/io/tet_mesh_io.h"
#include "tbsp/mesh/tetrahedralize.h"
#include "tbsp/plugins/preview_render.h"

using namespace tbsp;

namespace {
const std::string kLibigl = "meshes/libigl__libigl-tutorial-data/";

// A smooth non-rigid map: bend about the z axis by an angle growing with y, plus a twist.
Eigen::Vector3d bend(const Eigen::Vector3d& p) {
  const double a = 0.9 * (p.y() + 0.6);
  const Eigen::Vector3d q = Eigen::AngleAxisd(0.6 * a, Eigen::Vector3d::UnitY()) * p;
  return Eigen::AngleAxisd(0.5 * a, Eigen::Vector3d::UnitZ()) * q;
}
Eigen::MatrixX3d apply_bend(const Eigen::MatrixX3d& V) {
  Eigen::MatrixX3d out(V.rows(), 3);
  for (Eigen::Index i = 0; i < V.rows(); ++i) out.row(i) = bend(V.row(i).transpose()).transpose();
  return out;
}
// Angle (degrees) between corresponding vertex normals; returns the given percentile.
double normal_deviation(const Eigen::MatrixX3d& A, const Eigen::MatrixX3d& B, const Eigen::MatrixX3i& F, double pct) {
  const Eigen::MatrixX3d na = vertex_normals(A, F), nb = vertex_normals(B, F);
  std::vector<double> ang(std::size_t(A.rows()));
  for (Eigen::Index i = 0; i < A.rows(); ++i)
    ang[std::size_t(i)] = std::acos(std::clamp(na.row(i).dot(nb.row(i)), -1.0, 1.0)) * 180 / M_PI;
  std::sort(ang.begin(), ang.end());
  return ang[std::size_t(pct * double(ang.size() - 1))];
}
}  // namespace

TEST(TetReal, LibiglTetMeshesReadAndDeform) {
  struct Case { const char* file; Eigen::Index v, t; };
  for (const Case& c : {Case{"octopus-low.mesh", 452, 1140}, Case{"bunny.mesh", 5433, 34055}, Case{"hand.mesh", 7234, 29998}}) {
    const std::string path = test::shared(kLibigl + c.file);
    TBSP_REQUIRE_FILE(path);
    TetMesh m = read_tet_mesh(path);
    EXPECT_EQ(m.V.rows(), c.v) << c.file;
    EXPECT_EQ(m.T.rows(), c.t) << c.file;
    EXPECT_NO_THROW(require_valid_tet_mesh(m, c.file));
    // identity handles reproduce the input; a rigid motion of two handles moves it rigidly
    TetDeformer d;
    d.setMesh(m);
    std::vector<int> order(std::size_t(m.V.rows()));
    for (std::size_t i = 0; i < order.size(); ++i) order[i] = int(i);
    std::sort(order.begin(), order.end(), [&](int a, int b) { return m.V(a, 1) < m.V(b, 1); });
    const std::size_t k = order.size() / 20;
    const std::vector<int> low(order.begin(), order.begin() + long(k)), high(order.end() - long(k), order.end());
    const int h0 = d.addRegionHandle(low, {}), h1 = d.addRegionHandle(high, {});
    EXPECT_LT((d.deform(3) - m.V).cwiseAbs().maxCoeff(), 1e-9 * bbox_diagonal(m.V)) << c.file;
    const RigidMotion M = RigidMotion::rotation(Eigen::Vector3d(0.3, 1, 0.2), 1.2, m.V.colwise().mean().transpose(), Eigen::Vector3d(0.1, 0.2, 0.3));
    d.setRegionMotion(h0, M);
    d.setRegionMotion(h1, M);
    const Eigen::MatrixX3d X = d.deform(50);
    double err = 0;
    for (Eigen::Index i = 0; i < X.rows(); ++i) err = std::max(err, (X.row(i).transpose() - M.apply(m.V.row(i).transpose())).norm());
    EXPECT_LT(err, 1e-6 * bbox_diagonal(m.V)) << c.file << " after " << d.report().iterations << " iterations";
  }
}

TEST(TetReal, ArmadilloTransferIsSmoothAndExactForRigidMotions) {
  const std::string path = test::shared(kLibigl + "armadillo.obj");
  TBSP_REQUIRE_FILE(path);
  const TriMesh hi = read_mesh(path);
  const TetMesh tets = tetrahedralize_to_size(hi, 5000);
  ASSERT_GT(tets.T.rows(), 3000);
  DeformationTransfer wend;
  wend.precompute(tets, hi.V);
  EXPECT_EQ(wend.fallbackVertices(), 0);
  // identity and rigid motions exactly
  EXPECT_LT((wend.apply(tets.V) - hi.V).cwiseAbs().maxCoeff(), 1e-12);
  const Eigen::Matrix3d R = Eigen::AngleAxisd(2.5, Eigen::Vector3d(1, 1, -1).normalized()).toRotationMatrix();
  const Eigen::RowVector3d t(0.3, -4, 1);
  EXPECT_LT((wend.apply((tets.V * R.transpose()).rowwise() + t) - ((hi.V * R.transpose()).rowwise() + t)).cwiseAbs().maxCoeff(), 1e-12);

  // Smoothness: a smooth bend applied to the tet vertices and transferred, against the same
  // bend applied to the high-res vertices directly. The Wendland blend of §7.3 against the
  // "fast and easy" nearest-tet barycentric transfer (piecewise linear: kinks at tet faces).
  DeformationTransfer nearest;
  nearest.precompute(tets, hi.V, 1e-9);  // no tet within the radius: nearest tet only
  const Eigen::MatrixX3d exact = apply_bend(hi.V), Xt = apply_bend(tets.V);
  const Eigen::MatrixX3d a = wend.apply(Xt), b = nearest.apply(Xt);
  const double diag = bbox_diagonal(hi.V);
  const double pos_w = (a - exact).rowwise().norm().maxCoeff() / diag, pos_n = (b - exact).rowwise().norm().maxCoeff() / diag;
  const double n95_w = normal_deviation(a, exact, hi.F, 0.95), n95_n = normal_deviation(b, exact, hi.F, 0.95);
  std::printf("bend transfer to %ld vertices from %ld tets: max position error %.4f%% (Wendland) vs %.4f%% (nearest tet) of "
              "the diagonal; 95th percentile normal deviation %.2f vs %.2f degrees\n",
              long(hi.V.rows()), long(tets.T.rows()), 100 * pos_w, 100 * pos_n, n95_w, n95_n);
  EXPECT_LT(n95_w, 0.7 * n95_n);
  EXPECT_LT(pos_w, 0.01);

  // A real edit: feet fixed, head and shoulders pulled sideways and turned; transfer; render.
  TetDeformer d;
  d.setMesh(tets);
  std::vector<int> feet, head;
  for (Eigen::Index i = 0; i < tets.V.rows(); ++i) {
    if (tets.V(i, 1) < -0.50) feet.push_back(int(i));
    if (tets.V(i, 1) > 0.30) head.push_back(int(i));
  }
  ASSERT_FALSE(feet.empty());
  ASSERT_FALSE(head.empty());
  d.addRegionHandle(feet, {});
  d.addRegionHandle(head, RigidMotion::rotation(Eigen::Vector3d::UnitZ(), 0.5, Eigen::Vector3d(0, 0.35, 0), Eigen::Vector3d(-0.25, -0.05, 0)));
  const Eigen::MatrixX3d X = d.deform(60);
  EXPECT_LT(std::abs(d.report().volume_ratio - 1), 0.03) << d.report().volume_ratio;
  TriMesh out = hi;
  out.V = wend.apply(X);
  TriMesh tet_surface = tet_boundary_mesh(tets);
  tet_surface.V = X;
  const auto dir = test::temp_dir("tet_real");
  const std::string png = (dir / "armadillo_tetdeform.png").string();
  RenderOptions ro;
  ro.azimuth_deg = 0;
  ro.elevation_deg = 5;
  render_panels_png(png, {{hi, "input 43k"}, {tet_surface, "tet mesh, deformed"}, {out, "transferred (Wendland)"}}, ro);
  EXPECT_TRUE(std::filesystem::exists(png));
  std::printf("render: %s\n", png.c_str());
}
