#include <gtest/gtest.h>

#include <Eigen/Geometry>

#include "test_util.h"
#include "tbsp/core/error.h"
#include "tbsp/deform/laplacian_deformer.h"
#include "tbsp/mesh/cotan_laplacian.h"
#include "tbsp/mesh/primitives.h"

#ifdef _OPENMP
#include <omp.h>
#endif

using namespace tbsp;
using tbsp::test::farthest_points;

namespace {
double rel_err(const Eigen::MatrixX3d& A, const Eigen::MatrixX3d& B, const Eigen::MatrixX3d& ref) {
  return (A - B).rowwise().norm().maxCoeff() / bbox_diagonal(ref);
}
}  // namespace

class TranslationTest : public ::testing::TestWithParam<LaplacianWeights> {};

TEST_P(TranslationTest, TranslationOnlyConstraintsReproduceTheTranslatedMesh) {
  const TriMesh m = make_tube(30, 16, 1.0, 0.15);
  const Eigen::RowVector3d t(0.3, -1.2, 2.5);
  LaplacianDeformer d;
  d.setLaplacianWeights(GetParam());
  d.setMesh(m);
  for (int v : farthest_points(m.V, 8)) d.addPositionConstraint(SurfacePoint::atVertex(v), (m.V.row(v) + t).transpose(), 2.0);
  // a barycentric constraint on a face, and a hard one
  const Eigen::Vector3d b(0.2, 0.3, 0.5);
  Eigen::RowVector3d p = Eigen::RowVector3d::Zero();
  for (int k = 0; k < 3; ++k) p += b(k) * m.V.row(m.F(10, k));
  d.addPositionConstraint(SurfacePoint::onFace(10, b), (p + t).transpose());
  d.addHardConstraint(100, (m.V.row(100) + t).transpose());
  const Eigen::MatrixX3d X = d.deform();
  const Eigen::MatrixX3d expected = m.V.rowwise() + t;
  EXPECT_LT(rel_err(X, expected, m.V), 1e-8);
  EXPECT_FALSE(d.report().coupled_xyz);
  EXPECT_TRUE(d.report().refactorized);
}

INSTANTIATE_TEST_SUITE_P(Weights, TranslationTest, ::testing::Values(LaplacianWeights::Cotangent, LaplacianWeights::Uniform));

TEST(LaplacianDeformer, HardConstraintsAreExact) {
  const TriMesh m = make_icosphere(3);
  LaplacianDeformer d;
  d.setMesh(m);
  const std::vector<int> hv = farthest_points(m.V, 6);
  std::vector<Eigen::Vector3d> targets;
  for (std::size_t k = 0; k < hv.size(); ++k) {
    targets.push_back(m.V.row(hv[k]).transpose() * (1.0 + 0.3 * double(k)) + Eigen::Vector3d(0.1 * double(k), 0, 0));
    d.addHardConstraint(hv[k], targets.back());
  }
  d.addPositionConstraint(SurfacePoint::atVertex(17), Eigen::Vector3d(3, 3, 3), 10.0);
  const Eigen::MatrixX3d X = d.deform();
  for (std::size_t k = 0; k < hv.size(); ++k) EXPECT_EQ(X.row(hv[k]).transpose(), targets[k]);
  EXPECT_EQ(d.report().hard_constraints, 6);
  EXPECT_EQ(d.report().free_vertices, m.V.rows() - 6);
  EXPECT_THROW(d.addHardConstraint(hv[0], Eigen::Vector3d::Zero()), InvalidInput);  // twice
}

TEST(LaplacianDeformer, LineAndPlaneConstraintsAreMet) {
  const TriMesh m = make_tube(25, 12, 1.0, 0.1);
  const Eigen::RowVector3d t(0.0, 0.4, -0.2);
  // consistent: position handles translate the mesh, line/plane constraints pass through the
  // translated vertices -> the exact minimiser is the translated mesh, residuals 0
  LaplacianDeformer d;
  d.setMesh(m);
  d.addPositionConstraint(SurfacePoint::atVertex(0), (m.V.row(0) + t).transpose());
  for (int v : {50, 120, 200, 280})
    d.addLineConstraint(SurfacePoint::atVertex(v), (m.V.row(v) + t).transpose(), Eigen::Vector3d(1, 1, 0), 3.0);
  d.addPlaneConstraint(SurfacePoint::atVertex(250), (m.V.row(250) + t).transpose(), Eigen::Vector3d(0, 0, 1), 3.0);
  const Eigen::MatrixX3d X = d.deform();
  EXPECT_TRUE(d.report().coupled_xyz);
  EXPECT_LT(rel_err(X, m.V.rowwise() + t, m.V), 1e-8);
  EXPECT_LT(d.report().max_residual, 1e-8);
  // inconsistent: pull a vertex onto a line far away with a high weight -> met to ~1/w²
  LaplacianDeformer e;
  e.setMesh(m);
  for (int v = 0; v < 12; ++v) e.addHardConstraint(v, m.V.row(v).transpose());
  const int id = e.addLineConstraint(SurfacePoint::atVertex(290), Eigen::Vector3d(1.0, 0.5, 0.0), Eigen::Vector3d(0, 0, 1), 1000.0);
  const Eigen::MatrixX3d Y = e.deform();
  const Eigen::Vector3d p = Y.row(290).transpose();
  const double dist = (Eigen::Vector2d(p.x(), p.y()) - Eigen::Vector2d(1.0, 0.5)).norm();
  EXPECT_LT(dist, 1e-4 * bbox_diagonal(m.V));
  EXPECT_NEAR(e.report().residuals[std::size_t(id)].distance, dist, 1e-12);
}

TEST(LaplacianDeformer, ResolveWithMovedTargetsEqualsFreshSolve) {
  const TriMesh m = make_tube(30, 12, 1.0, 0.1);
  const std::vector<int> handles = farthest_points(m.V, 10);
  auto setup = [&](LaplacianDeformer& d, double s) {
    d.setMesh(m);
    for (std::size_t k = 0; k < handles.size(); ++k) {
      const Eigen::Vector3d q = m.V.row(handles[k]).transpose() + s * Eigen::Vector3d(0.1 * double(k), 0.2, -0.05 * double(k));
      if (k < 2) d.addHardConstraint(handles[k], q);
      else d.addPositionConstraint(SurfacePoint::atVertex(handles[k]), q, 1.0 + double(k));
    }
    d.addLineConstraint(SurfacePoint::atVertex(77), m.V.row(77).transpose(), Eigen::Vector3d(0, 1, 0));
  };
  LaplacianDeformer a;
  setup(a, 0.0);
  a.deform();
  EXPECT_TRUE(a.report().refactorized);
  for (std::size_t k = 0; k < handles.size(); ++k)
    a.setPositionTarget(int(k), m.V.row(handles[k]).transpose() + 2.0 * Eigen::Vector3d(0.1 * double(k), 0.2, -0.05 * double(k)));
  a.setLineOrPlane(int(handles.size()), m.V.row(77).transpose() + Eigen::Vector3d(0.3, 0, 0), Eigen::Vector3d(0, -2, 0));
  const Eigen::MatrixX3d Xa = a.deform();
  EXPECT_FALSE(a.report().refactorized) << "moving targets must re-use the factorization";
  LaplacianDeformer b;
  setup(b, 2.0);
  b.setLineOrPlane(int(handles.size()), m.V.row(77).transpose() + Eigen::Vector3d(0.3, 0, 0), Eigen::Vector3d(0, 1, 0));
  const Eigen::MatrixX3d Xb = b.deform();
  EXPECT_LT(rel_err(Xa, Xb, m.V), 1e-10);
  // a rotated line changes the matrix
  a.setLineOrPlane(int(handles.size()), m.V.row(77).transpose(), Eigen::Vector3d(1, 0, 0));
  a.deform();
  EXPECT_TRUE(a.report().refactorized);
  a.setWeight(3, 7.0);
  a.deform();
  EXPECT_TRUE(a.report().refactorized);
}

// a deformer of another rest shape on the same connectivity solves with a copied analysis to
// the same bits as with its own
TEST(LaplacianDeformer, CopiedSolverAnalysisGivesTheSameDeformation) {
  const TriMesh m = make_tube(30, 12, 1.0, 0.1);
  TriMesh bent = m;
  for (Eigen::Index i = 0; i < bent.V.rows(); ++i) bent.V(i, 1) += 0.2 * bent.V(i, 0) * bent.V(i, 0);
  const std::vector<int> handles = farthest_points(m.V, 8);
  auto setup = [&](LaplacianDeformer& d, const TriMesh& rest) {
    d.setMesh(rest);
    for (std::size_t k = 0; k < handles.size(); ++k)
      d.addPositionConstraint(SurfacePoint::atVertex(handles[k]), m.V.row(handles[k]).transpose() + Eigen::Vector3d(0, 0.1 * double(k), 0));
  };
  LaplacianDeformer a, own, copied;
  setup(a, m);
  a.deform();
  setup(own, bent);
  setup(copied, bent);
  copied.copySolverAnalysis(a);
  const Eigen::MatrixX3d X_own = own.deform(), X_copied = copied.deform();
  EXPECT_TRUE(copied.report().refactorized);
  EXPECT_EQ(X_own, X_copied);  // bit for bit
  EXPECT_GT((X_own - a.deform()).norm(), 1e-3);  // another rest shape: another deformation
  copied.addHardConstraint(handles[0], m.V.row(handles[0]).transpose());  // another pattern: analysed anew
  own.addHardConstraint(handles[0], m.V.row(handles[0]).transpose());
  EXPECT_EQ(own.deform(), copied.deform());
}

TEST(LaplacianDeformer, ScaledDifferentialCoordinatesScaleTheShape) {
  const TriMesh m = make_icosphere(3);
  LaplacianDeformer d;
  d.setMesh(m);
  for (int v : farthest_points(m.V, 5)) d.addPositionConstraint(SurfacePoint::atVertex(v), 2.5 * m.V.row(v).transpose());
  d.setScale(2.5);
  EXPECT_LT(rel_err(d.deform(), 2.5 * m.V, m.V), 1e-8);
  EXPECT_THROW(d.setScale(0), InvalidInput);
  EXPECT_THROW(d.setScale(std::nan("")), InvalidInput);
}

TEST(LaplacianDeformer, RotationFieldReproducesRigidRotationOfPrimitive) {
  const TriMesh m = make_tube(40, 16, 1.0, 0.1);
  const Eigen::Matrix3d R = Eigen::AngleAxisd(M_PI * 0.75, Eigen::Vector3d(0, 0.3, 1).normalized()).toRotationMatrix();
  const Eigen::MatrixX3d target = m.V * R.transpose();
  LaplacianDeformer d;
  d.setMesh(m);
  for (int v : farthest_points(m.V, 12)) d.addPositionConstraint(SurfacePoint::atVertex(v), target.row(v).transpose());
  d.setUseRotationField(true);
  EXPECT_LT(rel_err(d.deform(), target, m.V), 1e-6);
  EXPECT_EQ(d.report().rotation_nodes, 12);
  EXPECT_EQ(d.lastRotations().size(), std::size_t(m.V.rows()));
}

#ifdef _OPENMP
// deform() builds the rotation field's skeleton concurrently with the factorization when it
// has two threads: the result must be bit-identical to the sequential build, and errors and
// progress must still come out
TEST(LaplacianDeformer, ConcurrentSetUpGivesTheSequentialResult) {
  const TriMesh m = make_tube(40, 16, 1.0, 0.1);
  const Eigen::Matrix3d R = Eigen::AngleAxisd(1.0, Eigen::Vector3d(1, 0.2, 0.5).normalized()).toRotationMatrix();
  const Eigen::MatrixX3d target = m.V * R.transpose();
  const int threads = omp_get_max_threads();
  Eigen::MatrixX3d X[2];
  for (int k = 0; k < 2; ++k) {
    omp_set_num_threads(k == 0 ? 1 : 2);
    LaplacianDeformer d;
    d.setMesh(m);
    for (int v : farthest_points(m.V, 10)) d.addPositionConstraint(SurfacePoint::atVertex(v), target.row(v).transpose());
    d.setUseRotationField(true);
    int calls = 0;
    d.setProgressCallback([&](double, const std::string&) { ++calls; return true; });
    X[k] = d.deform();
    EXPECT_GT(calls, 0);
    EXPECT_GT(d.report().t_graph, 0);
  }
  EXPECT_EQ((X[0] - X[1]).cwiseAbs().maxCoeff(), 0.0);
  // an error of either part is rethrown: a rotation field needs 3 non-collinear nodes
  omp_set_num_threads(2);
  LaplacianDeformer d;
  d.setMesh(m);
  d.addPositionConstraint(SurfacePoint::atVertex(0), m.V.row(0).transpose());
  d.setUseRotationField(true);
  EXPECT_THROW(d.deform(), InvalidInput);
  omp_set_num_threads(threads);
}
#endif

TEST(LaplacianDeformer, UserRotationsAreUsed) {
  const TriMesh m = make_tube(20, 10, 1.0, 0.1);
  const Eigen::Matrix3d R = Eigen::AngleAxisd(1.2, Eigen::Vector3d::UnitY()).toRotationMatrix();
  LaplacianDeformer d;
  d.setMesh(m);
  DeformConstraint c;
  c.at = SurfacePoint::atVertex(0);
  c.target = (R * m.V.row(0).transpose());
  c.rotation = R;
  d.addConstraint(c);  // a single node with a user rotation: the whole field is R
  d.setUseRotationField(true);
  EXPECT_LT(rel_err(d.deform(), m.V * R.transpose(), m.V), 1e-8);
  // explicit dense rotations
  d.setRotations(std::vector<Eigen::Matrix3d>(std::size_t(m.V.rows()), R));
  EXPECT_LT(rel_err(d.deform(), m.V * R.transpose(), m.V), 1e-8);
  EXPECT_THROW(d.setRotations(std::vector<Eigen::Matrix3d>(3, R)), InvalidInput);
}

TEST(LaplacianDeformer, IsolatedVerticesStayPut) {
  TriMesh m = make_icosphere(2);
  m.V.conservativeResize(m.V.rows() + 1, 3);
  m.V.row(m.V.rows() - 1) << 9, 9, 9;
  LaplacianDeformer d;
  d.setMesh(m);
  d.addPositionConstraint(SurfacePoint::atVertex(0), Eigen::Vector3d(5, 0, 0));
  const Eigen::MatrixX3d X = d.deform();
  EXPECT_EQ(X.row(m.V.rows() - 1), m.V.row(m.V.rows() - 1));
  EXPECT_EQ(d.report().fixed_isolated, 1);
}

// What the fitter's pull rounds rely on (fit_detail.cpp): a solve that moves only a patch, set
// up on the faces within two rings of it (the other vertices belong to no face, so they are
// fixed), with the patch's neighbours held exactly and the soft weights scaled by the ratio of
// the area normalizations Ā (the mean Voronoi area of the vertices given), equals the whole
// mesh's solve with every vertex outside the patch held exactly.
TEST(LaplacianDeformer, APatchSolvedOnItsNeighbourhoodEqualsTheWholeMeshSolve) {
  TriMesh m = make_icosphere(4);  // 2,562 vertices
  for (Eigen::Index v = 0; v < m.V.rows(); ++v) m.V.row(v) *= 1 + 0.1 * std::sin(7 * m.V(v, 0)) * std::cos(5 * m.V(v, 2));
  const Eigen::Index n = m.V.rows();
  std::vector<char> patch(std::size_t(n), 0);  // the vertices near (0, 0, 1)
  for (Eigen::Index v = 0; v < n; ++v) patch[std::size_t(v)] = (m.V.row(v).normalized() - Eigen::RowVector3d(0, 0, 1)).norm() < 0.5;
  auto grow = [&](const std::vector<char>& mark) {
    std::vector<char> out = mark;
    for (Eigen::Index f = 0; f < m.F.rows(); ++f)
      if (mark[std::size_t(m.F(f, 0))] || mark[std::size_t(m.F(f, 1))] || mark[std::size_t(m.F(f, 2))])
        for (int c = 0; c < 3; ++c) out[std::size_t(m.F(f, c))] = 1;
    return out;
  };
  const std::vector<char> ring = grow(patch);
  std::vector<Eigen::Index> rows;
  for (Eigen::Index f = 0; f < m.F.rows(); ++f)
    if (ring[std::size_t(m.F(f, 0))] || ring[std::size_t(m.F(f, 1))] || ring[std::size_t(m.F(f, 2))]) rows.push_back(f);
  TriMesh sub;
  sub.V = m.V;
  sub.F.resize(Eigen::Index(rows.size()), 3);
  for (std::size_t k = 0; k < rows.size(); ++k) sub.F.row(Eigen::Index(k)) = m.F.row(rows[k]);
  ASSERT_LT(sub.F.rows(), m.F.rows() / 3);
  const double wscale = mean_voronoi_area(m.V, sub.F) / mean_voronoi_area(m.V, m.F);
  ASSERT_GT(std::abs(wscale - 1), 1e-3);  // the scaling matters here
  std::vector<char> in_sub(std::size_t(n), 0);
  for (Eigen::Index f = 0; f < sub.F.rows(); ++f)
    for (int c = 0; c < 3; ++c) in_sub[std::size_t(sub.F(f, c))] = 1;
  auto solve = [&](const TriMesh& mesh, double scale) {
    LaplacianDeformer d;
    d.setMesh(mesh);
    for (Eigen::Index v = 0; v < n; ++v) {
      if (patch[std::size_t(v)]) {  // pulled outwards, by weights that differ per vertex
        const Eigen::Vector3d t = 1.2 * m.V.row(v).transpose();
        d.addPositionConstraint(SurfacePoint::atVertex(int(v)), t, (0.5 + 0.5 * double(v % 3)) * scale);
      } else if (&mesh == &m || in_sub[std::size_t(v)]) {
        d.addHardConstraint(int(v), m.V.row(v).transpose());
      }
    }
    return d.deform();
  };
  const Eigen::MatrixX3d whole = solve(m, 1.0);
  const Eigen::MatrixX3d local = solve(sub, wscale);
  const double moved = (whole - m.V).rowwise().norm().maxCoeff();
  ASSERT_GT(moved, 0.05);
  EXPECT_LT(rel_err(whole, local, m.V), 1e-9) << "largest move " << moved;
  // without the scaling the patch comes out differently
  EXPECT_GT(rel_err(whole, solve(sub, 1.0), m.V), 1e-4);
}

TEST(LaplacianDeformer, RejectsBadConstraintsAndSingularSystems) {
  const TriMesh m = make_icosphere(1);
  LaplacianDeformer d;
  EXPECT_THROW(d.deform(), InvalidInput);  // no mesh
  d.setMesh(m);
  EXPECT_THROW(d.deform(), InvalidInput);  // no constraints: singular
  EXPECT_THROW(d.addPositionConstraint(SurfacePoint::atVertex(int(m.V.rows())), Eigen::Vector3d::Zero()), InvalidInput);
  EXPECT_THROW(d.addPositionConstraint(SurfacePoint::onFace(int(m.F.rows()), Eigen::Vector3d(1, 0, 0)), Eigen::Vector3d::Zero()), InvalidInput);
  EXPECT_THROW(d.addPositionConstraint(SurfacePoint::onFace(0, Eigen::Vector3d(0.5, 0.6, 0)), Eigen::Vector3d::Zero()), InvalidInput);
  EXPECT_THROW(d.addPositionConstraint(SurfacePoint::atVertex(0), Eigen::Vector3d(std::nan(""), 0, 0)), InvalidInput);
  EXPECT_THROW(d.addPositionConstraint(SurfacePoint::atVertex(0), Eigen::Vector3d::Zero(), 0.0), InvalidInput);
  // a weight whose square overflows (found by hand 2026-12-06: 1e300 ended in "the solution is
  // not finite"); 1e100 is the largest accepted and solves
  EXPECT_THROW(d.addPositionConstraint(SurfacePoint::atVertex(0), Eigen::Vector3d::Zero(), 1e300), InvalidInput);
  {  // one hard constraint per vertex (the message names it); none after clearConstraints
    LaplacianDeformer h;
    h.setMesh(m);
    h.addHardConstraint(3, m.V.row(3).transpose());
    h.addPositionConstraint(SurfacePoint::atVertex(3), m.V.row(3).transpose());  // a soft one is fine
    try {
      h.addHardConstraint(3, Eigen::Vector3d::Zero());
      ADD_FAILURE() << "no error for a second hard constraint";
    } catch (const InvalidInput& e) {
      EXPECT_NE(std::string(e.what()).find("vertex 3 already has a hard constraint"), std::string::npos) << e.what();
    }
    h.clearConstraints();
    EXPECT_NO_THROW(h.addHardConstraint(3, Eigen::Vector3d::Zero()));
  }
  {
    LaplacianDeformer big;
    big.setMesh(m);
    big.addPositionConstraint(SurfacePoint::atVertex(0), m.V.row(0).transpose() + Eigen::Vector3d(0.1, 0, 0), 1e100);
    big.addPositionConstraint(SurfacePoint::atVertex(5), m.V.row(5).transpose());
    const Eigen::MatrixX3d B = big.deform();
    EXPECT_TRUE(B.allFinite());
    EXPECT_LT((B.row(0).transpose() - m.V.row(0).transpose() - Eigen::Vector3d(0.1, 0, 0)).norm(), 1e-6);
    EXPECT_THROW(big.setWeight(0, 1e101), InvalidInput);
  }
  EXPECT_THROW(d.addLineConstraint(SurfacePoint::atVertex(0), Eigen::Vector3d::Zero(), Eigen::Vector3d::Zero()), InvalidInput);
  DeformConstraint hard_face;
  hard_face.at = SurfacePoint::onFace(0, Eigen::Vector3d(1, 0, 0));
  hard_face.hard = true;
  EXPECT_THROW(d.addConstraint(hard_face), InvalidInput);
  EXPECT_THROW(d.setPositionTarget(42, Eigen::Vector3d::Zero()), InvalidInput);
  // a single plane constraint leaves two translations free: singular, named in the message
  d.addPlaneConstraint(SurfacePoint::atVertex(0), Eigen::Vector3d::Zero(), Eigen::Vector3d::UnitZ());
  try {
    d.deform();
    FAIL() << "expected InvalidInput";
  } catch (const InvalidInput& e) {
    EXPECT_NE(std::string(e.what()).find("free to translate"), std::string::npos) << e.what();
  }
  // with an anchor the free directions keep their rest positions instead (a part without
  // silhouette rims in SilhouetteRefinement)
  d.setAnchor(1e-6);
  const Eigen::MatrixX3d X = d.deform();
  EXPECT_LT((X - m.V).cwiseAbs().maxCoeff(), 1e-6);
  // rotation field with too few nodes
  LaplacianDeformer r;
  r.setMesh(m);
  r.addPositionConstraint(SurfacePoint::atVertex(0), Eigen::Vector3d::Zero());
  r.addPositionConstraint(SurfacePoint::atVertex(1), Eigen::Vector3d::Ones());
  r.setUseRotationField(true);
  EXPECT_THROW(r.deform(), InvalidInput);
  // duplicate faces are rejected at setMesh
  TriMesh dup = m;
  dup.F.conservativeResize(dup.F.rows() + 1, 3);
  dup.F.row(dup.F.rows() - 1) = dup.F.row(0);
  EXPECT_THROW(r.setMesh(dup), InvalidInput);
}

TEST(LaplacianDeformer, ProgressCallbackCanCancel) {
  const TriMesh m = make_icosphere(2);
  LaplacianDeformer d;
  d.setMesh(m);
  d.addPositionConstraint(SurfacePoint::atVertex(0), Eigen::Vector3d::Zero());
  std::vector<std::string> stages;
  d.setProgressCallback([&](double, const std::string& s) { stages.push_back(s); return true; });
  d.deform();
  EXPECT_NE(std::find(stages.begin(), stages.end(), "factorize"), stages.end());
  d.setProgressCallback([](double, const std::string& s) { return s != "solve"; });
  EXPECT_THROW(d.deform(), Cancelled);
}
