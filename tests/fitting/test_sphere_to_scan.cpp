// §5.5 (Fig. 5.10): a coarse sphere template fitted to a real closed scan (Igea, 134k points)
// with Laplacian updating, adaptive subdivision and fairing.
#include <gtest/gtest.h>

#include <cstdio>

#include "test_util.h"
#include "tbsp/fitting/template_fitter.h"
#include "tbsp/io/mesh_io.h"
#include "tbsp/mesh/mesh_validation.h"
#include "tbsp/mesh/point_mesh_distance.h"
#include "tbsp/mesh/point_search.h"
#include "tbsp/mesh/primitives.h"

using namespace tbsp;

TEST(SphereToRealScan, IgeaWithUpdatingRemeshingFairing) {
  const std::string path = test::shared("meshes/alecjacobson__common-3d-test-models/data/igea.ply");
  TBSP_REQUIRE_FILE(path);
  const TriMesh scan = read_mesh(path);
  const Eigen::MatrixX3d P = scan.V;  // the points only; normals are estimated by the fitter
  const Eigen::RowVector3d c = P.colwise().mean();
  const double radius = 0.5 * (P.colwise().maxCoeff() - P.colwise().minCoeff()).maxCoeff();
  TriMesh sphere = make_icosphere(3, radius);  // 642 vertices
  sphere.V.rowwise() += c;
  std::vector<FitMarker> markers;  // the 6 axis extremes of the sphere <-> of the scan
  for (int d = 0; d < 3; ++d)
    for (int sg : {-1, 1}) {
      Eigen::Vector3d dir = Eigen::Vector3d::Zero();
      dir(d) = sg;
      Eigen::Index sv, pv;
      (sphere.V * dir).maxCoeff(&sv);
      (P * dir).maxCoeff(&pv);
      markers.emplace_back(int(sv), pv);
    }
  FitParameters p;
  p.laplacian_updating = true;
  p.updating_match_weight = 2;
  p.remeshing = true;
  p.fairing = true;
  p.fairing_steps = 4;
  // subdivide faces whose data lie on average more than 0.1 % of the diagonal away (default
  // 0.15 %): ~55k vertices instead of ~35k, p99 0.14 -> 0.09 %, Hausdorff within 0.5 % for
  // every perturbation of the sweep in docs/dev/fitting_experiments.md
  p.subdivision_error = 0.001 * (P.colwise().maxCoeff() - P.colwise().minCoeff()).norm();
  p.rotation_field = false;  // a sphere has no pose to transfer
  p.estimate_scale = false;
  p.propagate_displacements = false;
  TriMesh fit;
  std::vector<VertexStatus> st;
  const FitReport r = fit_template(sphere, P, Eigen::MatrixX3d(), markers, {}, p, fit, st);
  // independent fold-over check against the scan's own (consistently oriented) surface normals
  const Eigen::MatrixX3d SN = vertex_normals(scan.V, scan.F), FN = face_normals(fit.V, fit.F);
  const PointSearch tree(scan.V);
  int opposing = 0, opposing_120 = 0;
  for (Eigen::Index f = 0; f < fit.F.rows(); ++f) {
    const Eigen::Vector3d cf = (fit.V.row(fit.F(f, 0)) + fit.V.row(fit.F(f, 1)) + fit.V.row(fit.F(f, 2))).transpose() / 3.0;
    const double d = FN.row(f).dot(SN.row(tree.nearest(cf)));
    opposing += d < 0;
    opposing_120 += d < -0.5;
  }
  std::printf("  sphere 642 -> %ld vertices, %d iterations, %.1f s: Hausdorff %.3f%%, p99 %.3f%%, rms %.3f%%, folded edges %d, "
              "local folds %d (%d vertices untangled), report's flipped faces %d, faces opposing the true normals %d (by > 120 deg: "
              "%d) of %ld; pleat collapse: %d -> %d faces against the cloud normals, %d edges collapsed; self-intersecting "
              "face pairs %d\n",
              (long)r.vertices, r.iterations, r.t_total, 100 * r.hausdorff_rel, 100 * r.p99 / r.bbox_diagonal,
              100 * r.rms / r.bbox_diagonal, r.folded_edges, r.local_folds, r.untangled_vertices, r.flipped_faces, opposing,
              opposing_120,
              (long)fit.F.rows(), r.pleat_faces_before, r.pleat_faces_after, r.pleat_collapses, r.self_intersections);
  // What is asserted, and why these bounds (docs/testing.md, "Numerically sensitive tests"):
  // adaptive subdivision, pleat collapses and fold repair are discrete decisions on thresholds,
  // so a difference in the last bit of one vertex (another CPU's OpenBLAS kernels in CHOLMOD)
  // sends the fit down another, equally valid path. Deterministic on one machine, but the
  // figures below are draws from a spread; each bound covers the spread measured over 27 runs
  // whose input differed by noise of 1e-9 of the diagonal or by the order of the points
  // (2026-12-01), with margin. The issue-3 target "Hausdorff <= 0.5 %" holds in the median
  // (0.43 %), not in every run (20 of 27).
  const double diag = r.bbox_diagonal;
  // one-sided Hausdorff scan -> fit, the maximum at a point in the recess under the chin that
  // the fit bridges: 0.32-0.62 % (median 0.43 %)
  EXPECT_LE(r.hausdorff_rel, 0.0075);
  // 99th percentile: 0.089-0.102 % over those 27 runs and 0.093-0.097 % over 4 more
  // (2026-12-02). SparseCholesky's own supernodal solve (2026-12-02) runs an AVX2 + FMA build
  // of its kernel where the CPU has it and a baseline build elsewhere; the two differ in the
  // last bits, and on the baseline build the unperturbed input gives p99 0.130 % (rms 0.038 %,
  // Hausdorff 0.70 %), on the AVX2 build 0.095 %: the fitter's known path sensitivity, and
  // this test must pass on both
  EXPECT_LE(r.p99 / diag, 0.0014);
  EXPECT_EQ(r.folded_edges, 0);  // no edge folded back by > 120°: 0 in every run
  // no face passes through another (the thesis's fold-over artefact, §5.5.3 / Fig. 5.8): 0 in
  // every run (CGAL, exact predicates)
  EXPECT_EQ(r.self_intersections, 0);
  // faces against their surroundings (small crumples the untangling leaves): 0-7
  EXPECT_LE(r.local_folds, 10);
  // the report's own count (> 120° against the consistent estimated normals): 0-7
  EXPECT_LE(r.flipped_faces, 15);
  // pleat collapse: faces against the consistent estimated normals before -> after, 125-392 ->
  // 8-107 (it removes a third to all but 3 %)
  EXPECT_GT(r.pleat_collapses, 0);
  EXPECT_LT(r.pleat_faces_after, r.pleat_faces_before);
  // against the scan's true normals (of the nearest scan vertex): 38-134 of ~110k faces
  // (<= 0.12 %), most of them large faces bridging the recess under the chin, the others
  // standing almost across the scan where it is sharply curved (docs/dev/fitting_experiments.md)
  EXPECT_LT(double(opposing) / double(fit.F.rows()), 0.002);
  // the same seen from the data: scan points whose closest face of the fit points against the
  // point's true normal (the faces above that no scan point is closest to — bridges, hidden
  // sheets of small folds — do not count here): 1-12 of 134k
  const MeshDistance md(fit.V, fit.F);
  Eigen::VectorXi closest_face;
  md.distances(scan.V, &closest_face);
  int points_against = 0;
  for (Eigen::Index i = 0; i < scan.V.rows(); ++i) points_against += FN.row(closest_face(i)).dot(SN.row(i)) < 0;
  std::printf("  scan points whose closest face points against their true normal: %d of %ld\n", points_against,
              (long)scan.V.rows());
  EXPECT_LE(points_against, 20);
  // fold-overs seen against the scan's surface itself: each face is probed along its normal for
  // ±0.1 % of the diagonal (the subdivision error, where the fit is meant to lie) and counts as
  // flipped when the probe enters the scan (check_orientation_against; the middle sheet of a pleat
  // lying on the data would). 0-11 of ~110k faces: most stand at 93-120° to the scan face nearest
  // to them (across it, where it is sharply curved), a few form small pleats at 120-135° within
  // 0.05 % of the scan. ~104-106k faces agree, ~4.3-6.1k are not judged (farther than the probe
  // from the scan - the bridges - or standing across it).
  const double scan_diag = (scan.V.colwise().maxCoeff() - scan.V.colwise().minCoeff()).norm();
  const ReferenceOrientation against = check_orientation_against(fit.V, fit.F, scan.V, scan.F, 0.001 * scan_diag);
  std::printf("  faces probed against the scan (+-0.1%%): %d agree, %d point into it, %d not judged\n", against.consistent,
              against.flipped, against.unmatched);
  EXPECT_LE(against.flipped, 25);
  EXPECT_GT(against.consistent, 0.95 * double(fit.F.rows()));
}
