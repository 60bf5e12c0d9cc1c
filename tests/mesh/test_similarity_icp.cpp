// similarity_icp: trimmed ICP with scale, checked against known similarity transforms.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <limits>

#include "tbsp/core/error.h"
#include "tbsp/mesh/primitives.h"
#include "tbsp/mesh/similarity_icp.h"
#include "tbsp/mesh/tri_mesh.h"

using namespace tbsp;

namespace {

// An ellipsoid with a bump on one side: no symmetry ICP could slide along.
TriMesh blob_mesh() {
  TriMesh s = make_icosphere(4, 1.0);
  Eigen::MatrixX3d V(s.V.rows(), 3);
  const Eigen::Vector3d bump(0.6, 0.6, 0.5);
  for (Eigen::Index i = 0; i < s.V.rows(); ++i) {
    const Eigen::Vector3d v = s.V.row(i).transpose();
    const double g = 0.4 * std::exp(-(v.normalized() - bump.normalized()).squaredNorm() / 0.15);
    V.row(i) = ((1.0 + g) * v).cwiseProduct(Eigen::Vector3d(1.0, 0.6, 0.4)).transpose();
  }
  s.V = V;
  return s;
}
Eigen::MatrixX3d blob() { return blob_mesh().V; }

Eigen::Matrix4d similarity(double deg, const Eigen::Vector3d& axis, double scale, const Eigen::Vector3d& t) {
  Eigen::Matrix4d T = Eigen::Matrix4d::Identity();
  T.topLeftCorner<3, 3>() = scale * Eigen::AngleAxisd(deg * M_PI / 180.0, axis.normalized()).toRotationMatrix();
  T.topRightCorner<3, 1>() = t;
  return T;
}

}  // namespace

TEST(SimilarityIcp, RecoversAKnownSimilarity) {
  const TriMesh B = blob_mesh();
  const Eigen::MatrixX3d& S = B.V;
  // point-to-point (Umeyama steps): a moderate offset
  {
    const Eigen::Matrix4d truth = similarity(8, Eigen::Vector3d(0.3, 1, 0.2), 1.1, Eigen::Vector3d(0.05, -0.03, 0.04));
    const Eigen::MatrixX3d T = transform_points(truth, S);
    const SimilarityIcpResult r = similarity_icp(S, T);
    const double err = (transform_points(r.transform, S) - T).rowwise().norm().maxCoeff();
    std::printf("point-to-point, 8 deg, x1.1: %d iterations, rotation %.3f deg, scale %.5f, max error %.2e\n", r.iterations, r.rotation_deg,
                r.scale, err);
    EXPECT_LT(err, 1e-6);
    EXPECT_NEAR(r.scale, 1.1, 1e-6);
    EXPECT_NEAR(r.rotation_deg, 8.0, 1e-4);
    EXPECT_TRUE(r.converged);
    EXPECT_LT(r.rms, 1e-6);
  }
  // point-to-plane with the target's normals: a larger offset, fewer iterations
  {
    const Eigen::Matrix4d truth = similarity(20, Eigen::Vector3d(0.3, 1, 0.2), 1.15, Eigen::Vector3d(0.1, -0.05, 0.08));
    TriMesh moved = B;
    moved.V = transform_points(truth, S);
    const Eigen::MatrixX3d N = vertex_normals(moved.V, moved.F);
    const SimilarityIcpResult r = similarity_icp(S, moved.V, {}, &N);
    const double err = (transform_points(r.transform, S) - moved.V).rowwise().norm().maxCoeff();
    std::printf("point-to-plane, 20 deg, x1.15: %d iterations, rotation %.3f deg, scale %.5f, max error %.2e\n", r.iterations, r.rotation_deg,
                r.scale, err);
    EXPECT_LT(err, 1e-6);
    EXPECT_NEAR(r.scale, 1.15, 1e-6);
    EXPECT_NEAR(r.rotation_deg, 20.0, 1e-4);
    EXPECT_LT(r.iterations, 40);
  }
}

TEST(SimilarityIcp, RigidKeepsTheScaleAndTrimmingIgnoresOutliersAndMissingParts) {
  const Eigen::MatrixX3d S = blob();
  const Eigen::Matrix4d truth = similarity(6, Eigen::Vector3d(1, 0.2, -0.4), 1.0, Eigen::Vector3d(-0.05, 0.05, 0.0));
  const Eigen::MatrixX3d moved = transform_points(truth, S);
  // target: the part with x > -0.4 (a scan with a hole) and 5 % far outliers
  std::vector<Eigen::Vector3d> pts;
  for (Eigen::Index i = 0; i < S.rows(); ++i)
    if (S(i, 0) > -0.4) pts.push_back(moved.row(i).transpose());
  const std::size_t keep = pts.size();
  for (std::size_t k = 0; k < keep / 20; ++k) {
    const double a = 2.399963 * double(k);  // golden-angle spiral, deterministic
    pts.push_back(Eigen::Vector3d(2.5 * std::cos(a), 2.5 * std::sin(a), 0.1 * double(k % 7)));
  }
  Eigen::MatrixX3d T(Eigen::Index(pts.size()), 3);
  for (std::size_t k = 0; k < pts.size(); ++k) T.row(Eigen::Index(k)) = pts[k].transpose();
  SimilarityIcpOptions o;
  o.estimate_scale = false;
  o.trim = 0.1;
  const SimilarityIcpResult r = similarity_icp(S, T, o);
  const double err = (transform_points(r.transform, S) - moved).rowwise().norm().maxCoeff();
  std::printf("rigid, hole + 5 %% outliers: %d iterations, rotation %.3f deg, scale %.6f, max vertex error %.2e\n", r.iterations, r.rotation_deg,
              r.scale, err);
  EXPECT_NEAR(r.scale, 1.0, 1e-9);
  EXPECT_LT(err, 1e-3);  // of a ~2-unit shape
  // without trimming the outliers pull it off
  o.trim = 0;
  const SimilarityIcpResult u = similarity_icp(S, T, o);
  const double err_u = (transform_points(u.transform, S) - moved).rowwise().norm().maxCoeff();
  std::printf("untrimmed: max vertex error %.2e\n", err_u);
  EXPECT_GT(err_u, 10 * err);
}

TEST(SimilarityIcp, SymmetricPointToPlaneRecoversASimilarity) {
  // the setting of the visual-hull registration: pairs both ways, 20 % trimmed, target normals
  TriMesh moved = blob_mesh();
  const Eigen::MatrixX3d S = moved.V;
  const Eigen::Matrix4d truth = similarity(15, Eigen::Vector3d(0, 0.3, 1), 0.9, Eigen::Vector3d(0.02, 0.03, -0.04));
  moved.V = transform_points(truth, S);
  const Eigen::MatrixX3d N = vertex_normals(moved.V, moved.F);
  SimilarityIcpOptions o;
  o.symmetric = true;
  o.trim = 0.2;
  const SimilarityIcpResult r = similarity_icp(S, moved.V, o, &N);
  std::printf("symmetric point-to-plane: %d iterations, rotation %.4f deg, scale %.6f\n", r.iterations, r.rotation_deg, r.scale);
  EXPECT_LT((transform_points(r.transform, S) - moved.V).rowwise().norm().maxCoeff(), 1e-6);
  EXPECT_NEAR(r.scale, 0.9, 1e-6);
  EXPECT_TRUE(r.converged);
}

TEST(SimilarityIcp, BadInputIsAClearError) {
  const Eigen::MatrixX3d S = blob();
  EXPECT_THROW(similarity_icp(S.topRows(2), S), InvalidInput);
  EXPECT_THROW(similarity_icp(S, S.topRows(2)), InvalidInput);
  Eigen::MatrixX3d bad = S;
  bad(3, 1) = std::numeric_limits<double>::quiet_NaN();
  EXPECT_THROW(similarity_icp(bad, S), InvalidInput);
  EXPECT_THROW(similarity_icp(S, bad), InvalidInput);
  SimilarityIcpOptions o;
  o.trim = 0.95;
  EXPECT_THROW(similarity_icp(S, S, o), InvalidInput);
  o = {};
  o.max_iterations = 0;
  EXPECT_THROW(similarity_icp(S, S, o), InvalidInput);
  o = {};
  o.stall_iterations = -1;
  EXPECT_THROW(similarity_icp(S, S, o), InvalidInput);
  o = {};
  o.tolerance = -1;
  EXPECT_THROW(similarity_icp(S, S, o), InvalidInput);
  const Eigen::MatrixX3d few_normals = S.topRows(5);
  EXPECT_THROW(similarity_icp(S, S, {}, &few_normals), InvalidInput);
  try {
    similarity_icp(S.topRows(1), S);
    FAIL();
  } catch (const InvalidInput& e) {
    EXPECT_NE(std::string(e.what()).find("at least 3"), std::string::npos) << e.what();
  }
}
