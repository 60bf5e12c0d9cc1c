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
  // every perturbation of the sweep in docs/fitting.md
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
  // issue target; measured 0.447 % (updating weights 1.8 / 1.9 / 2.1 / 2.5 give 0.445 / 0.464 /
  // 0.480 / 0.486 %, any OPENBLAS_NUM_THREADS: the fit runs BLAS single-threaded; docs/fitting.md)
  EXPECT_LE(r.hausdorff_rel, 0.005);
  EXPECT_EQ(r.folded_edges, 0);  // no edge folded back by > 120°
  // no face passes through another (the thesis's fold-over artefact, §5.5.3 / Fig. 5.8): measured
  // 0 (also 0 over the updating-weight sweep 1.8 / 1.9 / 2.1 / 2.5)
  EXPECT_EQ(r.self_intersections, 0);
  // no face against its surroundings (small crumples): measured 0; this path amplifies tiny
  // differences (the updating-weight sweep 1.8 / 1.9 / 2.1 / 2.5 leaves 0 / 0 / 2 / 0), so a
  // handful is tolerated rather than a flaky 0
  EXPECT_LE(r.local_folds, 10);
  // the report's own count (> 120° against the estimated normals, made consistent for the count):
  // issue target 0, measured 2 (495 before the estimated normals were made consistent for it, 5
  // before the pleat collapse); the updating-weight sweep gives 0-3
  EXPECT_LE(r.flipped_faces, 10);
  // pleat collapse: faces against the (consistent) estimated normals 166 -> 9, 110 edges collapsed
  EXPECT_GT(r.pleat_collapses, 0);
  EXPECT_LE(4 * r.pleat_faces_after, r.pleat_faces_before);
  // against the scan's true normals, issue target 0: measured 70 of 110k (0.063 %; 215 without
  // the pleat collapse; sweep 1.8 / 1.9 / 2 / 2.1 / 2.5: 38 / 43 / 70 / 43 / 46 (33 at 1.8 before the
  // self-intersection repair), without it
  // 176 / 169 / 215 / 165 / 265): 50 of the 70 lie more than 0.1 % of the diagonal off the scan
  // (large faces bridging the recess under the chin), the other 20 stand within 8° of
  // perpendicular to it (docs/fitting.md); none lies on the scan pointing into it (below)
  EXPECT_LT(double(opposing) / double(fit.F.rows()), 0.001);
  // the same seen from the data: scan points whose closest face of the fit points against the
  // point's true normal (the faces above that no scan point is closest to — bridges, hidden
  // sheets of small folds — do not count here): measured 4 of 134k (sweep 3-8)
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
  // lying on the data would). Measured 0 flipped, 105,593 agreeing, 4,653 not judged (farther than
  // the probe from the scan — the bridges — or standing across it). Sweep of the updating weight
  // 1.8 / 1.9 / 2.1 / 2.5: 0 / 2 / 0 / 3 flipped, faces at 98-112° to the normal of the scan face
  // closest to them (almost across it) where the scan is sharply curved; probes of 0.05 / 0.2 /
  // 0.5 % at weight 2: 1 / 0 / 1 (docs/fitting.md)
  const double scan_diag = (scan.V.colwise().maxCoeff() - scan.V.colwise().minCoeff()).norm();
  const ReferenceOrientation against = check_orientation_against(fit.V, fit.F, scan.V, scan.F, 0.001 * scan_diag);
  std::printf("  faces probed against the scan (+-0.1%%): %d agree, %d point into it, %d not judged\n", against.consistent,
              against.flipped, against.unmatched);
  EXPECT_EQ(against.flipped, 0);
  EXPECT_GT(against.consistent, 0.95 * double(fit.F.rows()));
}
