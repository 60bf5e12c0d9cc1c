// Detail rounds of a fit (beyond the thesis; FitParameters::detail_rounds).
#include <algorithm>
#include <cmath>
#include <limits>
#include <optional>
#include <vector>

#include "fit_state.h"
#include "tbsp/core/logging.h"
#include "tbsp/core/timer.h"
#include "tbsp/mesh/cotan_laplacian.h"
#include "tbsp/mesh/point_mesh_distance.h"
#include "tbsp/mesh/radius_grid.h"

namespace tbsp {
namespace fit_impl {

namespace {

// The faces around the corners of each face, each once, in the order the corners' face lists
// give them (corner 0's faces first): where a tracked point's closest point is looked for after
// the fit moved a little. The first of equally close faces wins, as over the lists with repeats.
std::vector<std::vector<int>> face_neighbourhoods(Eigen::Index nv, const Eigen::MatrixX3i& F) {
  std::vector<std::vector<int>> vf(static_cast<std::size_t>(nv));  // faces around each vertex
  for (Eigen::Index f = 0; f < F.rows(); ++f)
    for (int c = 0; c < 3; ++c) vf[std::size_t(F(f, c))].push_back(int(f));
  std::vector<std::vector<int>> near(std::size_t(F.rows()));
#pragma omp parallel for schedule(static)
  for (Eigen::Index f = 0; f < F.rows(); ++f) {
    std::vector<int>& out = near[std::size_t(f)];
    for (int c = 0; c < 3; ++c)
      for (int g : vf[std::size_t(F(f, c))])
        if (std::find(out.begin(), out.end(), g) == out.end()) out.push_back(g);
  }
  return near;
}

// Bounding spheres of the faces (centroid and farthest corner): a lower bound of a point's
// distance to a face that costs one subtraction and norm.
class FaceSpheres {
public:
  FaceSpheres(const Eigen::MatrixX3d& V, const Eigen::MatrixX3i& F) : s_(F.rows(), 4) {
#pragma omp parallel for schedule(static)
    for (Eigen::Index f = 0; f < F.rows(); ++f) set(V, F, f);
  }
  // after only the corners of `faces` moved
  void update(const Eigen::MatrixX3d& V, const Eigen::MatrixX3i& F, const std::vector<int>& faces) {
#pragma omp parallel for schedule(static)
    for (std::size_t k = 0; k < faces.size(); ++k) set(V, F, faces[k]);
  }
  // true when every point of face f is surely farther than sqrt(d2) from p (a margin of 1e-9 of
  // the distances involved covers the rounding of the bound)
  bool fartherThan(int f, const Eigen::Vector3d& p, double d2) const {
    const double dc = (p - s_.row(f).head<3>().transpose()).norm();
    const double lb = dc - s_(f, 3) - 1e-9 * (dc + s_(f, 3));
    return lb > 0 && lb * lb > d2;
  }

private:
  void set(const Eigen::MatrixX3d& V, const Eigen::MatrixX3i& F, Eigen::Index f) {
    const Eigen::RowVector3d c = (V.row(F(f, 0)) + V.row(F(f, 1)) + V.row(F(f, 2))) / 3.0;
    double r2 = 0;
    for (int k = 0; k < 3; ++k) r2 = std::max(r2, (V.row(F(f, k)) - c).squaredNorm());
    s_.row(f) << c, std::sqrt(r2);
  }
  Eigen::Matrix<double, Eigen::Dynamic, 4, Eigen::RowMajor> s_;
};

// Unit normal of face f (zero for a degenerate face), as face_normals computes it.
Eigen::RowVector3d unit_face_normal(const Eigen::MatrixX3d& V, const Eigen::MatrixX3i& F, Eigen::Index f) {
  const Eigen::Vector3d a = V.row(F(f, 0)), b = V.row(F(f, 1)), c = V.row(F(f, 2));
  const Eigen::Vector3d n = (b - a).cross(c - a);
  const double len = n.norm();
  return len > 0 ? Eigen::RowVector3d(n.transpose() / len) : Eigen::RowVector3d::Zero();
}

// Whether face f has a corner with mark[v] set.
bool touches(const std::vector<char>& mark, const Eigen::MatrixX3i& F, Eigen::Index f) {
  return mark[std::size_t(F(f, 0))] || mark[std::size_t(F(f, 1))] || mark[std::size_t(F(f, 2))];
}

// The vertices within reach of the unexplained regions (pull rounds): closer than 1.5 × the
// farthest region's distance + the kernel radius r_d to one of the regions' points.
std::vector<char> near_regions(const Eigen::MatrixX3d& V, const Eigen::MatrixX3d& Q, const std::vector<int>& member,
                               const std::vector<FitReport::UnexplainedRegion>& regions, double rd) {
  double reach = 0;
  for (const auto& g : regions) reach = std::max(reach, 1.5 * g.max_distance);
  reach += rd;
  std::vector<Eigen::Index> rows;
  for (std::size_t k = 0; k < member.size(); ++k)
    if (member[k] >= 0) rows.push_back(Eigen::Index(k));
  Eigen::MatrixX3d R(Eigen::Index(rows.size()), 3);
  for (std::size_t k = 0; k < rows.size(); ++k) R.row(Eigen::Index(k)) = Q.row(rows[k]);
  const RadiusGrid grid(R, reach);
  std::vector<char> out(std::size_t(V.rows()), 0);
#pragma omp parallel for schedule(static)
  for (Eigen::Index j = 0; j < V.rows(); ++j) {
    bool found = false;
    grid.forEachWithin(V.row(j).transpose(), [&](Eigen::Index, double) { found = true; });
    out[std::size_t(j)] = found;
  }
  return out;
}

}  // namespace

// Detail rounds (beyond the thesis; FitParameters::detail_rounds): §5.5.1's Laplacian
// updating after the §5.3 fit, with everything the data does not support held where the fit
// put it. Each round takes the Laplacian and differential coordinates of the current fit as
// the regularizer (so the template's detail no longer holds protrusions back), constrains the
// matched vertices to data targets with detail_weight — the kernel mean of the data -> fit
// residuals (detail_residual_matching) or the §5.3 kernel targets — every other vertex to its
// current position with match_weight (the semantic hole filling stays) and, with
// detail_surface_weight, faces to the cloud points that project onto them; it factorizes once
// and iterates matching + back-substitution.
// `local` (pull rounds, FitParameters::pull_rounds): only the vertices near the regions the fit
// leaves unexplained move, every other one is held where the fit put it; nothing runs when the
// first round finds no region.
static void run_rounds(FitState& s, int rounds, bool local) {
  FitParameters& u = s.u;
  FitReport& rep = s.rep;
  Eigen::MatrixX3d& V = s.V;
  const Eigen::MatrixX3i& F = s.F;
  const Eigen::MatrixX3d& P = s.cloud.P;
  const Eigen::MatrixX3d& N = s.N;
  const std::vector<char>& roi_ok = s.cloud.roi_ok;
  const std::vector<VertexStatus>& status = s.status;
  const PointSearch& search = s.cloud.search;
  const Eigen::Index np = s.cloud.np;
  const double cos_max = s.cos_max;
  const auto t0 = Clock::now();
  const char* stage = local ? "pull rounds" : "detail rounds";
  const double r = u.max_match_distance;
  const double rd = u.detail_radius_factor * r;  // kernel radius of the residual matching
  const double cos_detail = std::cos(u.detail_normal_angle_deg * M_PI / 180.0);
  std::vector<std::vector<int>> near;  // face_neighbourhoods, built when a round first needs them
  LaplacianDeformer Dd;  // one for all rounds: the solver keeps its symbolic analysis
  Dd.setUseRotationField(false);
  // the cloud indices of the ROI points (the rows of roi_distances' Q): the same every round
  std::vector<Eigen::Index> qi;
  for (Eigen::Index i = 0; i < np; ++i)
    if (roi_ok[std::size_t(i)]) qi.push_back(i);
  const std::size_t nq = qi.size();
  // local: the points of any round's regions keep pulling (by their first region's reach) and
  // the vertices near them keep moving, so a part is drawn in all the way and not only until
  // its points fall below the region threshold
  std::vector<double> pulled_cap(local ? nq : 0, 0.0);  // per ROI point
  std::vector<char> pulled_near(local ? std::size_t(V.rows()) : 0, 0);
  for (int round = 0; round < rounds; ++round) {
    // (each round a point to cancel at; the compared fits also hand a finished fit's threads
    // over here)
    report_progress(s.progress, 0.9 + 0.05 * double(round) / rounds, stage);
    const auto t_round = Clock::now();
    // residual matching: every ROI point's closest point on the fit, as a face and barycentric
    // weights, found at the start of the round and then updated among the faces around the
    // last one after each solve (the fit moves little per iteration). Points farther than 3 r
    // are not tracked; the kernel below skips those farther than r (outliers, other surfaces).
    std::vector<Eigen::Index> rk;  // cloud index of each tracked point
    std::vector<int> rf;           // its closest face
    Eigen::MatrixX3d rb;           // and the barycentric weights of its closest point
    std::vector<double> rcap;      // per tracked point: the largest residual it may pull by
    std::vector<char> movable(std::size_t(V.rows()), 1);  // local: the vertices near a region
    bool nothing_to_pull = false;
    if (u.detail_residual_matching) {
      // every ROI point's distance and closest face (Embree; the lowest of equally close faces)
      const RoiDistances& measured = roi_distances(s);
      const Eigen::VectorXi& fq = measured.f;
      const Eigen::VectorXd& dq = measured.d;
      const Eigen::MatrixX3d& Q = measured.Q;
      // points of the regions the fit leaves unexplained (a part the fit has not reached: the
      // tip of a thin ear folded back) are tracked at any distance and pull by their whole
      // residual; scattered far points (outliers) form no region and stay ignored
      std::vector<double> cap(nq, r);  // per ROI point
      std::vector<char> in_region(nq, 0);
      if (u.detail_pull_unexplained || local) {
        std::vector<int> member;
        const auto regions = unexplained_regions(Q, dq, s.cloud.diag, r, &member);
        for (std::size_t k = 0; k < nq; ++k)
          if (member[k] >= 0) {
            cap[k] = 1.5 * regions[std::size_t(member[k])].max_distance;
            in_region[k] = 1;
          }
        if (local) {
          if (!regions.empty()) {
            const std::vector<char> within = near_regions(V, Q, member, regions, rd);
            for (std::size_t j = 0; j < within.size(); ++j) pulled_near[j] = pulled_near[j] || within[j];
          }
          for (std::size_t k = 0; k < nq; ++k) {
            if (in_region[k]) pulled_cap[k] = std::max(pulled_cap[k], cap[k]);
            if (pulled_cap[k] > 0) {
              cap[k] = std::max(cap[k], pulled_cap[k]);
              in_region[k] = 1;
            }
          }
          movable = pulled_near;
          nothing_to_pull = std::find(movable.begin(), movable.end(), char(1)) == movable.end();
        } else if (!regions.empty()) {
          ++rep.detail_rounds_pulling;
          logger()->debug("[TemplateFitting] detail round {}: {} unexplained region(s), {} points pull at any distance", round + 1,
                          regions.size(), unexplained_points(regions));
        }
      }
      if (nothing_to_pull) break;
      // local: only the points that can reach a vertex that moves
      auto reaches = [&](std::size_t k) {
        if (!local || in_region[k]) return true;
        return touches(movable, F, fq(Eigen::Index(k)));
      };
      for (std::size_t k = 0; k < nq; ++k)
        if (fq(Eigen::Index(k)) >= 0 && dq(Eigen::Index(k)) <= std::max(3 * r, cap[k]) && reaches(k)) {
          rk.push_back(qi[k]);
          rf.push_back(fq(Eigen::Index(k)));
          rcap.push_back(cap[k]);
        }
      rb.resize(Eigen::Index(rk.size()), 3);
      for (std::size_t t = 0; t < rk.size(); ++t) {
        const int f = rf[t];
        rb.row(Eigen::Index(t)) = closest_point_barycentric(P.row(rk[t]).transpose(), V.row(F(f, 0)).transpose(),
                                                      V.row(F(f, 1)).transpose(), V.row(F(f, 2)).transpose()).transpose();
      }
    }
    TriMesh cur;
    cur.V = V;
    // local: the solve is set up on the faces within two rings of the moving vertices only (the
    // vertices of no face are fixed): the Laplacian rows that hold a moving vertex are those of
    // the moving vertices and their neighbours, whole there; the non-moving vertices of these
    // faces are held exactly. The weights are scaled by the ratio of the Laplacians' area
    // normalizations (L̂ = Ā L over the vertices of the faces set), so the energy is the
    // whole mesh's with every other vertex held where it is.
    double wscale = 1.0;
    std::vector<char> in_solve;    // local: vertex of a face of the solve
    std::vector<int> solve_face;   // local: row of each face of F in the solve's faces (-1: none)
    std::vector<int> moving_faces;  // local: the faces at a moving vertex
    if (local) {
      std::vector<char> ring = movable;  // and their neighbours
      for (Eigen::Index f = 0; f < F.rows(); ++f)
        if (touches(movable, F, f)) {
          moving_faces.push_back(int(f));
          for (int c = 0; c < 3; ++c) ring[std::size_t(F(f, c))] = 1;
        }
      std::vector<Eigen::Index> rows;
      for (Eigen::Index f = 0; f < F.rows(); ++f)
        if (touches(ring, F, f)) rows.push_back(f);
      cur.F.resize(Eigen::Index(rows.size()), 3);
      in_solve.assign(std::size_t(V.rows()), 0);
      solve_face.assign(std::size_t(F.rows()), -1);
      for (std::size_t k = 0; k < rows.size(); ++k) {
        cur.F.row(Eigen::Index(k)) = F.row(rows[k]);
        solve_face[std::size_t(rows[k])] = int(k);
        for (int c = 0; c < 3; ++c) in_solve[std::size_t(F(rows[k], c))] = 1;
      }
      const double a_solve = mean_voronoi_area(V, cur.F), a_all = mean_voronoi_area(V, F);
      if (a_solve > 0 && a_all > 0) wscale = a_solve / a_all;
    } else {
      cur.F = F;
    }
    Dd.clearConstraints();
    Dd.setMesh(cur);
    s.addMarkers(Dd, u.detail_marker_weight * wscale);
    if (near.empty()) near = face_neighbourhoods(V.rows(), F);
    // the tracked points in the order of their faces at the round's start: the loops over them
    // read the mesh in order instead of at random (each point's result is its own)
    std::vector<Eigen::Index> by_face(rk.size());
    for (std::size_t t = 0; t < rk.size(); ++t) by_face[t] = Eigen::Index(t);
    std::sort(by_face.begin(), by_face.end(), [&](Eigen::Index a, Eigen::Index b) {
      return rf[std::size_t(a)] != rf[std::size_t(b)] ? rf[std::size_t(a)] < rf[std::size_t(b)] : a < b;
    });
    // the tracked points' closest points on the current fit
    auto tracked_closest = [&]() {
      Eigen::MatrixX3d C(Eigen::Index(rk.size()), 3);
#pragma omp parallel for schedule(static)
      for (Eigen::Index i = 0; i < C.rows(); ++i) {
        const Eigen::Index t = by_face[std::size_t(i)];
        const int f = rf[std::size_t(t)];
        C.row(t) = rb(t, 0) * V.row(F(f, 0)) + rb(t, 1) * V.row(F(f, 1)) + rb(t, 2) * V.row(F(f, 2));
      }
      return C;
    };
    // kernel sums of the residual matching at v: Σw, Σw², Σw (p_k − c_k) over the tracked points
    // whose closest point c_k lies within r_d of v, whose normal is within
    // detail_normal_angle_deg of their face's and whose residual is at most their cap
    struct ResidualSums {
      double sw = 0, sw2 = 0;
      Eigen::Vector3d sr = Eigen::Vector3d::Zero();
    };
    // the tracked points that pass the normal and residual tests (they do not depend on the
    // vertex asking), their residuals and a search over their closest points on the current fit:
    // built for the support weights and reused by the first iteration (the fit has not moved in
    // between), rebuilt after every solve
    struct ResidualIndex {
      Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor> R;  // residual p_k − c_k of each kept point, in the grid's slot order
      RadiusGrid grid;     // over the kept points' c_k, cells r_d wide
    };
    auto index_residuals = [&]() {
      const Eigen::MatrixX3d C = tracked_closest();
      // the tests on both threads, the kept points listed in order after
      std::vector<char> pass(rk.size());
#pragma omp parallel for schedule(static)
      for (Eigen::Index t = 0; t < Eigen::Index(rk.size()); ++t) {
        const Eigen::Index ci = rk[std::size_t(t)];
        pass[std::size_t(t)] = !(N.row(ci).dot(unit_face_normal(V, F, rf[std::size_t(t)])) < cos_detail) &&
                               !((P.row(ci) - C.row(t)).norm() > rcap[std::size_t(t)]);
      }
      std::vector<Eigen::Index> keep;
      keep.reserve(rk.size());
      for (std::size_t t = 0; t < rk.size(); ++t)
        if (pass[t]) keep.push_back(Eigen::Index(t));
      ResidualIndex x;
      Eigen::MatrixX3d Ck(Eigen::Index(keep.size()), 3);
      for (std::size_t k = 0; k < keep.size(); ++k) Ck.row(Eigen::Index(k)) = C.row(keep[k]);
      x.grid = RadiusGrid(Ck, rd);
      x.R.resize(Eigen::Index(keep.size()), 3);  // in the grid's order
      for (std::size_t slot = 0; slot < keep.size(); ++slot) {
        const Eigen::Index t = keep[x.grid.rows()[slot]];
        x.R.row(Eigen::Index(slot)) = P.row(rk[std::size_t(t)]) - C.row(t);
      }
      return x;
    };
    auto residual_sums = [&](const ResidualIndex& x, const Eigen::Vector3d& v) {
      ResidualSums a;
      x.grid.forEachSlotWithin(v, [&](std::size_t slot, double d2) {
        const double w = bspline_weight(std::sqrt(d2) / rd);
        a.sw += w;
        a.sw2 += w * w;
        a.sr += w * x.R.row(Eigen::Index(slot)).transpose();
      });
      return a;
    };
    // the vertices in the order of the grid cells they start the round in: the vertex loops
    // below read the residual grid in order (each vertex's result is its own)
    // (local: only the moving vertices enter these loops)
    std::vector<Eigen::Index> by_cell;
    if (u.detail_residual_matching && local) {
      std::vector<Eigen::Index> mv;
      for (Eigen::Index j = 0; j < V.rows(); ++j)
        if (movable[std::size_t(j)]) mv.push_back(j);
      Eigen::MatrixX3d Vm(Eigen::Index(mv.size()), 3);
      for (std::size_t k = 0; k < mv.size(); ++k) Vm.row(Eigen::Index(k)) = V.row(mv[k]);
      const RadiusGrid cells(Vm, rd);
      for (Eigen::Index k : cells.rows()) by_cell.push_back(mv[std::size_t(k)]);
    } else if (u.detail_residual_matching) {
      const RadiusGrid cells(V, rd);
      by_cell.assign(cells.rows().begin(), cells.rows().end());
    }
    // sparse support, as in stage 2: a vertex whose residual kernel holds fewer than
    // support_points × (r_d / r)² effective points (the count stage 2's kernel would see in the
    // same patch) gets least-squares weight ∝ n_eff — at the rim of holes one or two noisy
    // points otherwise pull it off the surface
    std::optional<ResidualIndex> index;
    Eigen::VectorXd dscale = Eigen::VectorXd::Ones(V.rows());
    if (u.detail_residual_matching && u.support_points > 0) {
      const double need = u.support_points * (rd / r) * (rd / r);
      index = index_residuals();
      const ResidualIndex& x = *index;
#pragma omp parallel for schedule(dynamic, 256)
      for (Eigen::Index i = 0; i < Eigen::Index(by_cell.size()); ++i) {
        const Eigen::Index j = by_cell[std::size_t(i)];
        if (status[std::size_t(j)] != VertexStatus::Matched || !movable[std::size_t(j)]) continue;
        const ResidualSums a = residual_sums(x, V.row(j).transpose());
        dscale(j) = a.sw2 > 0 ? std::min(1.0, a.sw * a.sw / a.sw2 / need) : 1.0;
      }
    }
    std::vector<int> ids(std::size_t(V.rows()), -1);
    for (Eigen::Index j = 0; j < V.rows(); ++j) {
      if (local && !movable[std::size_t(j)]) {
        if (in_solve[std::size_t(j)]) Dd.addHardConstraint(int(j), V.row(j).transpose());
        continue;
      }
      const bool data = status[std::size_t(j)] == VertexStatus::Matched;
      const int id = Dd.addPositionConstraint(SurfacePoint::atVertex(int(j)), V.row(j).transpose(),
                                              (data ? u.detail_weight * std::sqrt(dscale(j)) : u.match_weight) * wscale);
      if (data && movable[std::size_t(j)]) ids[std::size_t(j)] = id;  // held otherwise
    }
    std::vector<char> is_data(std::size_t(V.rows()), 0);
    for (Eigen::Index j = 0; j < V.rows(); ++j) is_data[std::size_t(j)] = ids[std::size_t(j)] >= 0;
    // data -> surface: each face onto which 3 or more cloud points (ROI, within r) project
    // pulls its centroid by their mean residual. The §5.3 kernel targets (residual matching
    // off) move along the normals only; these also pull sideways where the data reach beyond
    // the mesh (the tip of a protrusion projects onto the faces around the fit's tip vertex).
    if (u.detail_surface_weight > 0) {
      const MeshDistance md(V, F);
      Eigen::MatrixX3d CP(np, 3);
      Eigen::VectorXi CF = Eigen::VectorXi::Constant(np, -1);
#pragma omp parallel for schedule(dynamic, 1024)
      for (Eigen::Index i = 0; i < np; ++i) {
        if (!roi_ok[std::size_t(i)]) continue;
        int f = -1;
        CP.row(i) = md.closest(P.row(i).transpose(), &f).transpose();
        CF(i) = f;
      }
      Eigen::MatrixX3d rsum = Eigen::MatrixX3d::Zero(F.rows(), 3);
      Eigen::VectorXi rcount = Eigen::VectorXi::Zero(F.rows());
      for (Eigen::Index i = 0; i < np; ++i) {
        const int f = CF(i);
        if (f < 0 || (P.row(i) - CP.row(i)).norm() > r) continue;
        rsum.row(f) += P.row(i) - CP.row(i);
        ++rcount(f);
      }
      for (Eigen::Index f = 0; f < F.rows(); ++f) {
        if (rcount(f) < 3) continue;
        const int at = local ? solve_face[std::size_t(f)] : int(f);  // a face of the solve
        if (at < 0) continue;
        const Eigen::RowVector3d centroid = (V.row(F(f, 0)) + V.row(F(f, 1)) + V.row(F(f, 2))) / 3.0;
        Dd.addPositionConstraint(SurfacePoint::onFace(at, Eigen::Vector3d::Constant(1.0 / 3)),
                                 (centroid + rsum.row(f) / rcount(f)).transpose(), u.detail_surface_weight * wscale);
        ++rep.detail_surface_constraints;
      }
    }
    if (!local) rep.detail_points_tracked = Eigen::Index(rk.size());
    logger()->trace("[TemplateFitting] detail round {}: set-up {:.3f} s ({} data -> surface constraints, {} points tracked)",
                    round + 1, seconds_since(t_round), rep.detail_surface_constraints, rk.size());
    std::optional<FaceSpheres> spheres;  // of the faces, kept current by the closest-point updates
    int k = 0;
    for (; k < u.detail_iterations; ++k) {
      Eigen::MatrixX3d T = Eigen::MatrixX3d::Constant(V.rows(), 3, std::numeric_limits<double>::quiet_NaN());
      if (u.detail_residual_matching) {
        if (k > 0) {
          // the fit moved a little: each point's closest point among the faces around its last one
          // (the first of equally close ones in near's order). A face whose bounding sphere is
          // farther from the point than its last face is skipped: it cannot be the closest.
          // local: only the faces at a moving vertex change
          if (!spheres) spheres.emplace(V, F);
          else if (local) spheres->update(V, F, moving_faces);
          else *spheres = FaceSpheres(V, F);
#pragma omp parallel for schedule(dynamic, 1024)
          for (Eigen::Index i = 0; i < Eigen::Index(rk.size()); ++i) {
            const Eigen::Index t = by_face[std::size_t(i)];
            const Eigen::Vector3d p = P.row(rk[std::size_t(t)]).transpose();
            const int f0 = rf[std::size_t(t)];
            const auto on_face = [&](int f, Eigen::Vector3d& w) {
              const Eigen::Vector3d a = V.row(F(f, 0)).transpose(), b = V.row(F(f, 1)).transpose(), e = V.row(F(f, 2)).transpose();
              w = closest_point_barycentric(p, a, b, e);
              return (p - (w(0) * a + w(1) * b + w(2) * e)).squaredNorm();
            };
            Eigen::Vector3d w0;
            const double d0 = on_face(f0, w0);
            double best = std::numeric_limits<double>::infinity();
            for (int f : near[std::size_t(f0)]) {
              Eigen::Vector3d w = w0;
              double d2 = d0;
              if (f != f0) {
                if (spheres->fartherThan(f, p, d0)) continue;
                d2 = on_face(f, w);
              }
              if (d2 < best) { best = d2; rf[std::size_t(t)] = f; rb.row(t) = w.transpose(); }
            }
          }
        }
        // target = vertex + kernel-weighted mean of the residuals p_k - c_k
        if (k > 0 || !index) index = index_residuals();
        const ResidualIndex& x = *index;
#pragma omp parallel for schedule(dynamic, 256)
        for (Eigen::Index i = 0; i < Eigen::Index(by_cell.size()); ++i) {
          const Eigen::Index j = by_cell[std::size_t(i)];
          if (ids[std::size_t(j)] < 0) continue;
          const Eigen::Vector3d vj = V.row(j).transpose();
          const ResidualSums a = residual_sums(x, vj);
          if (a.sw <= 0) continue;
          Eigen::Vector3d m = a.sr / a.sw;
          if (m.norm() > r) m *= r / m.norm();
          T.row(j) = (vj + m).transpose();
        }
      } else {
        const Eigen::MatrixX3d VN = vertex_normals(V, F);
#pragma omp parallel
        {
          std::vector<std::pair<Eigen::Index, double>> nb;
#pragma omp for schedule(dynamic, 256)
          for (Eigen::Index j = 0; j < V.rows(); ++j) {
            if (ids[std::size_t(j)] < 0) continue;
            const Eigen::Vector3d vj = V.row(j).transpose(), nj = VN.row(j).transpose();
            if (nj.squaredNorm() == 0) continue;
            search.radius(vj, r, nb);
            double sw = 0, off = 0;
            Eigen::Vector3d sp = Eigen::Vector3d::Zero();
            Eigen::Matrix3d spp = Eigen::Matrix3d::Zero();
            kernel_sums(nb, P, N, roi_ok, nj, cos_max, r, sw, sp, spp);
            if (sw <= 0) continue;
            const Eigen::Vector3d q = kernel_target(vj, nj, sw, sp, spp, u.plane_fit, double(nb.size()), &off);
            if (off > u.rim_rejection * r) continue;
            T.row(j) = (vj + std::clamp((q - vj).dot(nj), -r, r) * nj).transpose();
          }
        }
      }
      for (Eigen::Index j = 0; j < V.rows(); ++j)  // no data this time: the last target stays
        if (ids[std::size_t(j)] >= 0 && T.row(j).allFinite()) Dd.setPositionTarget(ids[std::size_t(j)], T.row(j).transpose());
      const Eigen::MatrixX3d Vn = Dd.deform();
      // 99th percentile move of the data-supported vertices, as in stage 2
      const double move = percentile99_move(Vn, V, is_data);
      V = Vn;
      logger()->debug("[TemplateFitting] detail round {} iteration {}: 99th percentile move {:.3g}", round + 1, k + 1, move);
      logger()->trace("[TemplateFitting] detail solve: factorize {:.3f}, back-substitution {:.3f}", Dd.report().t_factorize,
                      Dd.report().t_solve);
      if (move < u.detail_tolerance) { ++k; break; }
    }
    if (local) ++rep.pull_rounds_run;
    else rep.detail_iterations_run += k;
  }
  (local ? rep.t_pull : rep.t_detail) = seconds_since(t0);
}

void detail_rounds(FitState& s) {
  const FitParameters& u = s.u;
  if (u.detail_rounds > 0 && (u.laplacian_updating || u.remeshing))
    s.rep.message += "detail rounds skipped: Laplacian updating already regularizes with the current shape. ";
  if (!(u.detail_rounds > 0 && u.max_iterations > 0 && !u.laplacian_updating && !u.remeshing)) return;
  run_rounds(s, u.detail_rounds, false);
}

void pull_rounds(FitState& s) {
  const FitParameters& u = s.u;
  if (u.pull_rounds <= 0 || u.detail_rounds > 0 || u.max_iterations <= 0 || u.laplacian_updating || u.remeshing ||
      !u.detail_residual_matching)
    return;
  run_rounds(s, u.pull_rounds, true);
}

}  // namespace fit_impl
}  // namespace tbsp
