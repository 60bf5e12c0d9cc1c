// bench_capture_perf: marker-driven animation (issue 25, docs/performance_capture.md).
//   bench_capture_perf [--repeats N]
// 1. CMU 01_01 (42 markers, 2751 frames) drives the human base mesh (24k vertices) through a
//    ~4.5k-tet control mesh: setup, per-frame deformation and transfer (medians over the take),
//    frames per second, peak RSS. Repeated N times; the median take is reported.
// 2. The transfer to surfaces of 24k, ~50k and 98k vertices (the template; its lower half and all
//    of it midpoint-subdivided) on the same control mesh: median ms per frame over 300 frames.
// 3. Performance capture from video (PerformanceCapture, §9.2) on the synthetic studio (8 views,
//    --capture-size pixels, textured humanoid with a skirt, --capture-frames frames) for the
//    performer at detail 1 (4.3k vertices) and 2 (17k): per-frame medians of SIFT, matching,
//    pose (constraints + handle fit + deformer), optimization, transfer, refinement; and the
//    accuracy against the ground truth (worst mean vertex error, worst view IoU, drift).
//    bench_capture_perf --capture-frames 60 --capture-only is the acceptance run.
// 4. --vlasic STEPS: a real captured performer, the Vlasic et al. 2008 samba and crane meshes of
//    ../shared/data (frames 0000/0050/0100/0150, shared connectivity, ~10k vertices), rendered
//    into an 8-camera studio (--capture-size) with the solid texture, STEPS in-between frames per
//    gap made by interpolating vertex positions; template = frame 0000, tracked to the end; the
//    error and IoU at the captured frames 0050/0100/0150 and the worst over all frames.
//    --vlasic-turn: in-betweens that follow the body's turn (the best rotation between the two
//    captured frames slerped, the rest linear in the rotating frame); linear ones squash the crane
//    to 40-47 % of its volume where it turns by ~180 degrees (the table reports the smallest volume).
//    --vlasic-rigid: the same turn, the rest by an as-rigid-as-possible shape interpolation (per
//    triangle rotation slerped and stretch blended, vertices by a Poisson solve): near-isometric
//    in-betweens such as a real body makes.
//    --keyframes N [--keyframe-iou X] [--pose-rounds N] [--smoothness X] [--refine N] [--handles N]
//    [--tets N] [--anchor-weight X] [--reject-px X] [--deformer-iterations N]: those
//    PerformanceCaptureOptions (keyframe_interval, keyframe_iou, pose_rounds, smoothness,
//    refine_iterations, handles, tets, anchor_weight, reject_px, deformer_iterations) for the
//    --vlasic rows and the --capture-only row; --vlasic-only samba|crane runs one sequence.
//    --floor N: under each sequence's row (and the --capture-only row), its control model (the
//    same tets and handles) driven by the true positions of its handles, N deformer iterations
//    per frame: the error a tracker that found every handle exactly would reach with this model.
// 5. --stereo FRAMES: model-guided stereo after the silhouette refinement (stereo_refine) on the
//    performer with 1 cm folds (detail 2): the same sequence without and with it.
// 6. --hull FRAMES: a template placed by eye (turned about the vertical, scaled, moved) tracked
//    as placed and after the registration to the first frame's visual hull (register_to_hull):
//    the synthetic performer over FRAMES frames, the Vlasic samba and crane (frame 0000) on their
//    first frame; error and IoU against the truth.
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include <Eigen/Geometry>
#include <Eigen/SparseCholesky>
#include <Eigen/SVD>

#include "bench_util.h"

#include "tbsp/io/mesh_io.h"
#include "tbsp/mesh/trajectory_smoother.h"
#include "tbsp/io/mocap_io.h"
#include "tbsp/mesh/point_mesh_distance.h"
#include "tbsp/mesh/remeshing.h"
#include "tbsp/mesh/similarity_icp.h"
#include "tbsp/mesh/tetrahedralize.h"
#include "tbsp/deform/tet_deformer.h"
#include "tbsp/deform/deformation_transfer.h"
#include "tbsp/io/studio.h"
#include "tbsp/multiview/marker_animation.h"
#include "tbsp/multiview/performance_capture.h"
#include "tbsp/plugins/marker_map_json.h"
#include "tbsp/plugins/synth_studio.h"

using namespace tbsp;
using namespace tbsp::bench;

namespace {

// The synthetic studio (8 views of size², textured performer with a skirt) written to `dir`.
struct SynthSequence {
  Studio studio;
  TriMesh rest;
  double diag = 0;
};
SynthSequence synth_sequence(const std::string& dir, int frames, int size, int detail, double folds = 0) {
  synth::StudioOptions so;
  so.frames = frames;
  so.width = so.height = size;
  so.detail = detail;
  so.folds = folds;
  so.markers = 4;
  synth::write_synthetic_studio(dir, so);
  SynthSequence s;
  s.studio = read_studio(dir + "/studio.yaml");
  s.rest = read_mesh(dir + "/template.ply");
  s.diag = (s.rest.V.colwise().maxCoeff() - s.rest.V.colwise().minCoeff()).norm();
  return s;
}

// Tracks the whole sequence with `pc` (cameras and template set here); per frame,
// on_frame(frame number, tracked mesh, ground truth, the frame's report).
template <typename OnFrame>
void track_sequence(const SynthSequence& seq, PerformanceCapture& pc, OnFrame on_frame) {
  pc.setCameras(seq.studio.cameraList());
  pc.setTemplate(seq.rest);
  StudioFrameStream stream(seq.studio, {});
  StudioFrame f;
  while (stream.next(f)) {
    TriMesh m;
    pc.track(f.images, f.silhouettes, f.frame, m);
    on_frame(f.frame, m, read_mesh(seq.studio.groundTruthPath(f.frame)), pc.report().frames.back());
  }
}

std::vector<double> control_model_floor(const TriMesh& templ, const std::vector<Eigen::MatrixX3d>& truth, const PerformanceCaptureOptions& po,
                                        int iterations, double diag);

void capture_rows(int frames, int size, const std::vector<int>& details, const PerformanceCaptureOptions& po = {}, int floor_iterations = 0) {
  std::printf("\n## Performance capture (8 views of %dx%d, %d frames; medians per frame, seconds)\n\n", size, size, frames);
  std::printf("| template vertices | control tets | setup | SIFT | matching + lifting | pose | optimization | transfer | refinement | total per frame | "
              "worst mean vertex error (%% diag) | worst view IoU | error last / frame 5 |\n|---|---|---|---|---|---|---|---|---|---|---|---|---|\n");
  for (int detail : details) {
    const SynthSequence seq = synth_sequence("/tmp/tbsp_bench_capture_d" + std::to_string(detail), frames, size, detail);
    const TriMesh& rest = seq.rest;
    const double diag = seq.diag;
    PerformanceCapture pc;
    pc.setOptions(po);
    std::vector<double> err;
    std::vector<Eigen::MatrixX3d> tracked, truth;
    double worst_iou = 1;
    track_sequence(seq, pc, [&](int, const TriMesh& m, const TriMesh& gt, const CaptureFrameReport& fr) {
      err.push_back((m.V - gt.V).rowwise().norm().mean() / diag);
      tracked.push_back(m.V);
      truth.push_back(gt.V);
      worst_iou = std::min(worst_iou, fr.iou_min);
    });
    const auto& r = pc.report();
    std::vector<double> t[7];
    for (std::size_t k = 1; k < r.frames.size(); ++k) {  // frame 0 registers; the rest track
      const auto& fr = r.frames[k];
      const double v[7] = {fr.t_features, fr.t_match, fr.t_pose, fr.t_optimize, fr.t_transfer, fr.t_refine, fr.t_total};
      for (int q = 0; q < 7; ++q) t[q].push_back(v[q]);
    }
    std::printf("| %ld | %ld | %.2f | %.3f | %.3f | %.3f | %.3f | %.3f | %.3f | %.2f | %.3f | %.4f | %.2f |\n", long(rest.V.rows()), long(r.tets),
                r.t_setup, median(t[0]), median(t[1]), median(t[2]), median(t[3]), median(t[4]), median(t[5]), median(t[6]),
                100 * *std::max_element(err.begin(), err.end()), worst_iou, err.size() > 5 ? err.back() / err[5] : 0.0);
    if (floor_iterations > 0) {  // the control model driven by its handles' true positions
      const std::vector<double> fl = control_model_floor(rest, truth, po, floor_iterations, diag);
      std::printf("| %ld, its control model driven by the handles' true positions (%d deformer iterations per frame) | | | | | | | | | | %.3f | | %.2f |\n",
                  long(rest.V.rows()), floor_iterations, 100 * *std::max_element(fl.begin(), fl.end()), fl.size() > 5 ? fl.back() / fl[5] : 0.0);
    }
    // The optional temporal smoothing of the trajectories (TrajectorySmoother) on the same run.
    for (double sigma : {1.0, 2.0}) {
      const std::vector<Eigen::MatrixX3d> sm = smooth_trajectories(tracked, sigma);
      std::vector<double> es;
      for (std::size_t k = 0; k < sm.size(); ++k) es.push_back((sm[k] - truth[k]).rowwise().norm().mean() / diag);
      std::printf("| %ld, trajectories smoothed (sigma %.0f frames) | | | | | | | | | | %.3f | | %.2f |\n", long(rest.V.rows()), sigma, 100 * *std::max_element(es.begin(), es.end()), es.size() > 5 ? es.back() / es[5] : 0.0);
    }
    std::printf("\nper frame: mean vertex error (%% diag) / first-frame anchor matches:");
    for (std::size_t k = 0; k < err.size(); ++k) std::printf("%s%.3f/%d", k % 10 ? " " : "\n  ", 100 * err[k], r.frames[k].anchor_matches);
    std::printf("\n");
    std::fflush(stdout);
  }
}

enum class InBetween { linear, turn, turn_rigid };

// Shape interpolation that keeps each triangle as rigid as the two ends allow (Alexa et al. 2000;
// Xu et al. 2005): per face, the deformation gradient from `a` to `b` (both centred, the global
// turn removed) split by polar decomposition into a rotation Q and a stretch S; at t the face's
// target is slerp(I, Q, t) ((1 - t) I + t S) applied to its rest edges; the vertex positions are the
// least-squares fit of all edges (a Poisson solve, one factorization per pair), centred. Gives a
// at t = 0 and b at t = 1 (up to the centring).
class RigidInterpolation {
public:
  RigidInterpolation(const Eigen::MatrixX3d& a, const Eigen::MatrixX3d& b, const Eigen::MatrixX3i& F) : a_(a), F_(F) {
    const Eigen::Index n = a.rows(), m = F.rows();
    Q_.resize(std::size_t(m));
    S_.resize(std::size_t(m));
    std::vector<Eigen::Triplet<double>> L;
    for (Eigen::Index f = 0; f < m; ++f) {
      auto frame = [&](const Eigen::MatrixX3d& X) {
        const Eigen::Vector3d e1 = X.row(F(f, 1)) - X.row(F(f, 0)), e2 = X.row(F(f, 2)) - X.row(F(f, 0));
        const Eigen::Vector3d nrm = e1.cross(e2);
        Eigen::Matrix3d M;
        M << e1, e2, nrm / std::sqrt(std::max(nrm.norm(), 1e-300));
        return M;
      };
      const Eigen::Matrix3d Ma = frame(a), Mb = frame(b);
      Eigen::Matrix3d G = Eigen::Matrix3d::Identity();
      if (std::abs(Ma.determinant()) > 1e-18) G = Mb * Ma.inverse();
      const Eigen::JacobiSVD<Eigen::Matrix3d> svd(G, Eigen::ComputeFullU | Eigen::ComputeFullV);
      Eigen::Matrix3d U = svd.matrixU();
      Eigen::Vector3d sig = svd.singularValues();
      if ((U * svd.matrixV().transpose()).determinant() < 0) {
        U.col(2) *= -1;
        sig(2) *= -1;
      }
      Q_[std::size_t(f)] = Eigen::Quaterniond(Eigen::Matrix3d(U * svd.matrixV().transpose()));
      S_[std::size_t(f)] = svd.matrixV() * sig.asDiagonal() * svd.matrixV().transpose();
      for (int k = 0; k < 3; ++k) {
        const int i = F(f, k), j = F(f, (k + 1) % 3);
        L.emplace_back(i, i, 1.0);
        L.emplace_back(j, j, 1.0);
        L.emplace_back(i, j, -1.0);
        L.emplace_back(j, i, -1.0);
      }
    }
    L.emplace_back(0, 0, 1e-8);  // translation: fixed by the centring below
    Eigen::SparseMatrix<double> Lm(n, n);
    Lm.setFromTriplets(L.begin(), L.end());
    solver_.compute(Lm);
  }
  Eigen::MatrixX3d at(double t) const {
    Eigen::MatrixX3d rhs = Eigen::MatrixX3d::Zero(a_.rows(), 3);
    for (Eigen::Index f = 0; f < F_.rows(); ++f) {
      const Eigen::Matrix3d G = Eigen::Quaterniond::Identity().slerp(t, Q_[std::size_t(f)]).toRotationMatrix() *
                                ((1 - t) * Eigen::Matrix3d::Identity() + t * S_[std::size_t(f)]);
      for (int k = 0; k < 3; ++k) {
        const int i = F_(f, k), j = F_(f, (k + 1) % 3);
        const Eigen::RowVector3d e = (G * (a_.row(j) - a_.row(i)).transpose()).transpose();
        rhs.row(j) += e;
        rhs.row(i) -= e;
      }
    }
    Eigen::MatrixX3d X = solver_.solve(rhs);
    return X.rowwise() - X.colwise().mean();
  }

private:
  Eigen::MatrixX3d a_;
  Eigen::MatrixX3i F_;
  std::vector<Eigen::Quaterniond> Q_;
  std::vector<Eigen::Matrix3d> S_;
  Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>> solver_;
};

// In-betweens of two captured frames A -> B (same connectivity), t in [0, 1]. linear: vertex
// positions interpolated (the recipe). turn: the best rotation R from A to B about the
// centroids slerped, the rest of the motion interpolated linearly in the rotating frame,
// X(t) = R_t (A - cA + t (R^T (B - cB) - (A - cA))) + (1 - t) cA + t cB. turn_rigid: the same
// turn, the rest by RigidInterpolation (factored once per pair, in the constructor).
class GapInterpolation {
public:
  GapInterpolation(const Eigen::MatrixX3d& A, const Eigen::MatrixX3d& B, const Eigen::MatrixX3i& F, InBetween mode)
      : A_(A), B_(B), mode_(mode) {
    if (mode == InBetween::linear) return;
    ca_ = A.colwise().mean();
    cb_ = B.colwise().mean();
    a_ = A.rowwise() - ca_;
    const Eigen::MatrixX3d b = B.rowwise() - cb_;
    R_ = Eigen::umeyama(a_.transpose(), b.transpose(), false).block<3, 3>(0, 0);
    bt_ = b * R_;  // rows: R^T (b_i)
    if (mode == InBetween::turn_rigid) rigid_ = std::make_unique<RigidInterpolation>(a_, bt_, F);
  }
  Eigen::MatrixX3d at(double t) const {
    if (mode_ == InBetween::linear) return (1 - t) * A_ + t * B_;
    if (mode_ == InBetween::turn_rigid && t == 1) return B_;  // exactly the captured frame (the solve reproduces it to rounding)
    const Eigen::MatrixX3d shape = rigid_ ? rigid_->at(t) : Eigen::MatrixX3d(a_ + t * (bt_ - a_));
    const Eigen::Quaterniond q = Eigen::Quaterniond::Identity().slerp(t, Eigen::Quaterniond(R_));
    return (shape * q.toRotationMatrix().transpose()).rowwise() + ((1 - t) * ca_ + t * cb_);
  }

private:
  Eigen::MatrixX3d A_, B_, a_, bt_;
  InBetween mode_;
  Eigen::RowVector3d ca_, cb_;
  Eigen::Matrix3d R_ = Eigen::Matrix3d::Identity();
  std::unique_ptr<RigidInterpolation> rigid_;
};

// Signed volume of a closed mesh.
double mesh_volume(const Eigen::MatrixX3d& V, const Eigen::MatrixX3i& F) {
  double v = 0;
  for (Eigen::Index f = 0; f < F.rows(); ++f)
    v += V.row(F(f, 0)).dot(V.row(F(f, 1)).cross(V.row(F(f, 2)))) / 6.0;
  return v;
}

// The control model's floor: the tracker's tet mesh and handles (build_capture_control_model, as
// PerformanceCapture::start builds them) driven by the *true* positions of its handles
// in every frame (each handle's closest template surface point, carried by the truth's
// vertices), `iterations` deformer iterations per frame warm-started from the last, carried to
// the template by the same transfer. Mean vertex error per frame (fraction of `diag`): what a
// tracker that found every handle exactly would reach with this model.
std::vector<double> control_model_floor(const TriMesh& templ, const std::vector<Eigen::MatrixX3d>& truth, const PerformanceCaptureOptions& po,
                                        int iterations, double diag) {
  const CaptureControlModel cm = build_capture_control_model(templ, po.tets, po.handles);
  const TetMesh& tets = cm.tets;
  const std::vector<int>& handles = cm.handles;
  // each handle's closest template surface point: face, barycentrics
  Eigen::MatrixX3d H(Eigen::Index(handles.size()), 3);
  for (std::size_t h = 0; h < handles.size(); ++h) H.row(Eigen::Index(h)) = tets.V.row(handles[h]);
  Eigen::VectorXi face;
  point_mesh_distances(templ.V, templ.F, H, &face);
  std::vector<Eigen::Vector3d> bary(handles.size());
  for (std::size_t h = 0; h < handles.size(); ++h)
    bary[h] = closest_point_barycentric(H.row(Eigen::Index(h)).transpose(), templ.V.row(templ.F(face(Eigen::Index(h)), 0)).transpose(),
                                        templ.V.row(templ.F(face(Eigen::Index(h)), 1)).transpose(),
                                        templ.V.row(templ.F(face(Eigen::Index(h)), 2)).transpose());
  TetDeformer D;
  D.setMesh(tets);
  for (int v : handles) D.addVertexHandle(v, tets.V.row(v).transpose());
  DeformationTransfer transfer;
  DeformationTransferOptions to;
  to.radius = po.transfer_radius;
  transfer.setOptions(to);
  transfer.precompute(tets, templ.V);
  std::vector<double> err;
  for (const Eigen::MatrixX3d& T : truth) {
    for (std::size_t h = 0; h < handles.size(); ++h) {
      Eigen::Vector3d q = Eigen::Vector3d::Zero();
      for (int c = 0; c < 3; ++c) q += bary[h](c) * T.row(templ.F(face(Eigen::Index(h)), c)).transpose();
      D.setHandleTarget(int(h), q);
    }
    for (int it = 0; it < iterations; ++it) D.iterate();
    err.push_back((transfer.apply(D.inputPositions()) - T).rowwise().norm().mean() / diag);
  }
  return err;
}

void vlasic_rows(int steps, int size, InBetween mode, const PerformanceCaptureOptions& po, const std::string& only, int floor_iterations) {
  const std::string base = std::string(TBSP_SHARED_DATA_DIR) + "/meshes/CraGL__Hyperspectral-Inverse-Skinning/models/";
  std::printf("\n## Performance capture of the Vlasic meshes (8 views of %dx%d, %d in-between frames per 50 captured frames, %s)\n\n", size, size,
              steps,
              mode == InBetween::linear ? "linear in-betweens"
              : mode == InBetween::turn ? "in-betweens follow the body's turn"
                                        : "in-betweens follow the body's turn, each triangle as rigid as the ends allow");
  std::printf("| sequence | vertices | frames | smallest in-between volume (%% of its keyframe) | error at 0050 / 0100 / 0150 (%% diag) | view IoU min at 0050 / 0100 / 0150 | worst error, all frames | worst view IoU, all frames | error last / frame 5 | failed frames | s per frame |\n"
              "|---|---|---|---|---|---|---|---|---|---|---|\n");
  for (const char* seq : {"samba", "crane"}) {
    if (!only.empty() && only != seq) continue;
    std::vector<TriMesh> key;
    for (const char* f : {"0000", "0050", "0100", "0150"}) key.push_back(read_mesh(base + seq + "/mesh_" + f + ".obj"));
    const int frames = 3 * steps + 1;
    std::vector<Eigen::MatrixX3d> truth(static_cast<std::size_t>(frames));
    for (int g = 0; g < 3; ++g) {
      const GapInterpolation gap(key[std::size_t(g)].V, key[std::size_t(g + 1)].V, key[0].F, mode);
      for (int k = g == 0 ? 0 : 1; k <= steps; ++k) truth[std::size_t(g * steps + k)] = gap.at(double(k) / steps);
    }
    auto frame = [&](int f) {
      TriMesh m = key[0];
      m.V = truth[std::size_t(f)];
      return m;
    };
    // How much volume the in-betweens lose (a body squashed through a turn is no performance).
    double min_volume = 1;
    for (int f = 0; f < frames; ++f)
      min_volume = std::min(min_volume, mesh_volume(frame(f).V, key[0].F) / mesh_volume(key[std::size_t(std::min(f / steps, 2))].V, key[0].F));
    const std::string dir = std::string("/tmp/tbsp_bench_vlasic_") + seq +
                            (mode == InBetween::linear ? "" : mode == InBetween::turn ? "_turn" : "_rigid");
    synth::StudioOptions so;
    so.frames = frames;
    so.width = so.height = size;
    synth::write_sequence_studio(dir, key[0], frame, so);
    const Studio st = read_studio(dir + "/studio.yaml");
    const double diag = (key[0].V.colwise().maxCoeff() - key[0].V.colwise().minCoeff()).norm();
    PerformanceCapture pc;
    pc.setOptions(po);
    pc.setCameras(st.cameraList());
    pc.setTemplate(key[0]);
    StudioFrameStream stream(st, {});
    StudioFrame fr;
    std::vector<double> err, iou;
    const auto t0 = Clock::now();
    while (stream.next(fr)) {
      TriMesh m;
      pc.track(fr.images, fr.silhouettes, fr.frame, m);
      err.push_back((m.V - frame(fr.frame).V).rowwise().norm().mean() / diag);
      iou.push_back(pc.report().frames.back().iou_min);
      if (fr.frame % steps == 0) write_mesh(dir + "/tracked_" + std::to_string(fr.frame) + ".ply", m);  // to look at (tbsp render)
    }
    const double secs = since(t0) / frames;
    std::fprintf(stderr, "%s per frame: mean vertex error (%% diag) / worst view IoU / anchor matches:", seq);
    for (std::size_t k = 0; k < err.size(); ++k)
      std::fprintf(stderr, "%s%.2f/%.3f/%d", k % 8 ? " " : "\n  ", 100 * err[k], iou[k], pc.report().frames[k].anchor_matches);
    std::fprintf(stderr, "\n");
    std::printf("| %s | %ld | %d | %.0f | %.2f / %.2f / %.2f | %.3f / %.3f / %.3f | %.2f | %.3f | %.2f | %d | %.2f |\n", seq, long(key[0].V.rows()), frames, 100 * min_volume,
                100 * err[std::size_t(steps)], 100 * err[std::size_t(2 * steps)], 100 * err[std::size_t(3 * steps)], iou[std::size_t(steps)],
                iou[std::size_t(2 * steps)], iou[std::size_t(3 * steps)], 100 * *std::max_element(err.begin(), err.end()),
                *std::min_element(iou.begin(), iou.end()), err.size() > 5 ? err.back() / err[5] : 0.0, pc.report().failed_frames, secs);
    if (floor_iterations > 0) {
      const std::vector<double> fl = control_model_floor(key[0], truth, po, floor_iterations, diag);
      std::fprintf(stderr, "%s, the control model driven by its handles' true positions (%d deformer iterations per frame): mean vertex error (%% diag):", seq,
                   floor_iterations);
      for (std::size_t k = 0; k < fl.size(); ++k) std::fprintf(stderr, "%s%.2f", k % 8 ? " " : "\n  ", 100 * fl[k]);
      std::fprintf(stderr, "\n");
      std::printf("| %s: its control model driven by the handles' true positions | | | | %.2f / %.2f / %.2f | | %.2f | | %.2f | | |\n", seq,
                  100 * fl[std::size_t(steps)], 100 * fl[std::size_t(2 * steps)], 100 * fl[std::size_t(3 * steps)],
                  100 * *std::max_element(fl.begin(), fl.end()), fl.size() > 5 ? fl.back() / fl[5] : 0.0);
    }
    std::fflush(stdout);
  }
}


// A template placed by eye: turned by `deg` about the vertical (y) through its centroid, scaled by
// `scale`, moved by `shift` × its diagonal.
TriMesh misplace(const TriMesh& m, double deg, double scale, double shift) {
  const Eigen::Vector3d c = m.V.colwise().mean().transpose();
  const double diag = (m.V.colwise().maxCoeff() - m.V.colwise().minCoeff()).norm();
  Eigen::Matrix4d T = Eigen::Matrix4d::Identity();
  T.topLeftCorner<3, 3>() = scale * Eigen::AngleAxisd(deg * M_PI / 180, Eigen::Vector3d::UnitY()).toRotationMatrix();
  T.topRightCorner<3, 1>() = c - T.topLeftCorner<3, 3>() * c + shift * diag * Eigen::Vector3d(1, 0.3, -0.6).normalized();
  TriMesh out = m;
  out.V = transform_points(T, m.V);
  return out;
}

void hull_rows(int frames, int size) {
  std::printf("\n## First frame: a template placed by eye, as placed and registered to the visual hull (8 views of %dx%d)\n\n", size, size);
  std::printf("| performer | frames | offset (turn, scale, shift %% diag) | as placed: worst error (%% diag) / worst view IoU | registered: worst error / worst view IoU | "
              "registration: rotation, scale, IoU before -> after, s |\n|---|---|---|---|---|---|\n");
  struct Offset {
    double deg, scale, shift;
  };
  const Offset offsets[] = {{0, 1, 0}, {10, 1.05, 0.03}, {15, 1.08, 0.05}, {25, 1.15, 0.08}, {35, 1.2, 0.1}};
  auto run = [&](const std::string& name, const Studio& st, const TriMesh& templ, double diag, int nframes,
                 const std::function<TriMesh(int)>& truth) {
    for (const Offset& off : offsets) {
      const TriMesh rough = misplace(templ, off.deg, off.scale, off.shift);
      double worst[2] = {0, 0}, iou[2] = {1, 1};
      HullRegistration reg;
      for (int mode = 0; mode < 2; ++mode) {
        PerformanceCapture pc;
        PerformanceCaptureOptions po;
        po.register_to_hull = mode == 1;
        pc.setOptions(po);
        pc.setCameras(st.cameraList());
        pc.setTemplate(rough);
        StudioFrameStream stream(st, {});
        StudioFrame fr;
        for (int f = 0; f < nframes && stream.next(fr); ++f) {
          TriMesh m;
          pc.track(fr.images, fr.silhouettes, fr.frame, m);
          worst[mode] = std::max(worst[mode], (m.V - truth(fr.frame).V).rowwise().norm().mean() / diag);
          iou[mode] = std::min(iou[mode], pc.report().frames.back().iou_min);
        }
        if (mode == 1) reg = pc.report().hull;
      }
      std::printf("| %s | %d | %.0f deg, x%.2f, %.0f %% | %.3f / %.4f | %.3f / %.4f | %.1f deg, x%.3f, %.3f -> %.3f, %.2f s |\n", name.c_str(), nframes,
                  off.deg, off.scale, 100 * off.shift, 100 * worst[0], iou[0], 100 * worst[1], iou[1], reg.icp.rotation_deg, reg.icp.scale,
                  reg.iou_before, reg.iou_after, reg.seconds);
      std::fflush(stdout);
    }
  };
  {
    const SynthSequence seq = synth_sequence("/tmp/tbsp_bench_hull_synth", frames, size, 1);
    run("synthetic performer", seq.studio, seq.rest, seq.diag, frames, [&](int f) { return read_mesh(seq.studio.groundTruthPath(f)); });
  }
  const std::string base = std::string(TBSP_SHARED_DATA_DIR) + "/meshes/CraGL__Hyperspectral-Inverse-Skinning/models/";
  for (const char* name : {"samba", "crane"}) {
    const TriMesh key = read_mesh(base + name + "/mesh_0000.obj");
    const std::string dir = std::string("/tmp/tbsp_bench_hull_") + name;
    synth::StudioOptions so;
    so.frames = 1;
    so.width = so.height = size;
    synth::write_sequence_studio(dir, key, [&](int) { return key; }, so);
    const Studio st = read_studio(dir + "/studio.yaml");
    const double diag = (key.V.colwise().maxCoeff() - key.V.colwise().minCoeff()).norm();
    run(std::string("Vlasic ") + name + " 0000", st, key, diag, 1, [&](int) { return key; });
  }
}

// Model-guided stereo after the refinement (PerformanceCapture::stereo_refine) on a performer
// with 1 cm folds (synth-studio --detail 2 --folds 0.01): the same sequence without and with it.
void stereo_rows(int frames, int size) {
  const SynthSequence seq = synth_sequence("/tmp/tbsp_bench_capture_folds", frames, size, 2, 0.01);
  const TriMesh& rest = seq.rest;
  const double diag = seq.diag;
  std::printf("\n## Performance capture with model-guided stereo (8 views of %dx%d, %d frames, 1 cm folds, %ld vertices)\n\n", size, size, frames,
              long(rest.V.rows()));
  std::printf("| stereo_refine | mean vertex error, mean over frames (%% diag) | worst frame | distance to the truth's surface, mean (%% diag) | "
              "worst view IoU | stereo points per frame | stereo s per frame | total s per frame |\n|---|---|---|---|---|---|---|---|\n");
  for (bool stereo : {false, true}) {
    PerformanceCaptureOptions o;
    o.stereo_refine = stereo;
    PerformanceCapture pc;
    pc.setOptions(o);
    std::vector<double> err, surf, ts, tt, pts;
    double worst_iou = 1;
    track_sequence(seq, pc, [&](int frame, const TriMesh& m, const TriMesh& gt, const CaptureFrameReport& fr) {
      err.push_back((m.V - gt.V).rowwise().norm().mean() / diag);
      surf.push_back(point_mesh_distances(gt.V, gt.F, m.V).mean() / diag);  // closest point: no tangential slide counted
      worst_iou = std::min(worst_iou, fr.iou_min);
      if (frame > 0) {
        ts.push_back(fr.t_stereo);
        tt.push_back(fr.t_total);
        pts.push_back(fr.stereo_points);
      }
    });
    double mean = 0, smean = 0;
    for (double e : err) mean += e / double(err.size());
    for (double e : surf) smean += e / double(surf.size());
    std::printf("| %s | %.3f | %.3f | %.3f | %.4f | %.0f | %.2f | %.2f |\n", stereo ? "on" : "off", 100 * mean,
                100 * *std::max_element(err.begin(), err.end()), 100 * smean, worst_iou, median(pts), median(ts), median(tt));
    std::fflush(stdout);
  }
}

}  // namespace

int main(int argc, char** argv) {
  tbsp::bench::heap_as_the_cli(argv);  // as the tbsp CLI (bench_util.h)
  int repeats = 3, capture_frames = 10, capture_size = 1004, vlasic = 0, stereo = 0, hull = 0;
  bool capture_only = false;
  InBetween vlasic_mode = InBetween::linear;
  std::string vlasic_only;  // samba or crane; empty = both
  int floor_iterations = 0;  // --floor N: also the control model driven by its handles' true positions
  int capture_detail = 1;
  PerformanceCaptureOptions po;  // defaults, unless a flag below changes them
  for (int i = 1; i < argc; ++i) {
    if (!std::strcmp(argv[i], "--repeats") && i + 1 < argc) repeats = std::max(1, std::atoi(argv[++i]));
    else if (!std::strcmp(argv[i], "--capture-frames") && i + 1 < argc) capture_frames = std::max(0, std::atoi(argv[++i]));
    else if (!std::strcmp(argv[i], "--capture-size") && i + 1 < argc) capture_size = std::max(64, std::atoi(argv[++i]));
    else if (!std::strcmp(argv[i], "--capture-only")) capture_only = true;
    else if (!std::strcmp(argv[i], "--capture-detail") && i + 1 < argc) capture_detail = std::clamp(std::atoi(argv[++i]), 1, 2);
    else if (!std::strcmp(argv[i], "--vlasic") && i + 1 < argc) vlasic = std::max(0, std::atoi(argv[++i]));
    else if (!std::strcmp(argv[i], "--stereo") && i + 1 < argc) stereo = std::max(0, std::atoi(argv[++i]));
    else if (!std::strcmp(argv[i], "--vlasic-turn")) vlasic_mode = InBetween::turn;
    else if (!std::strcmp(argv[i], "--vlasic-rigid")) vlasic_mode = InBetween::turn_rigid;
    else if (!std::strcmp(argv[i], "--hull") && i + 1 < argc) hull = std::max(0, std::atoi(argv[++i]));
    else if (!std::strcmp(argv[i], "--keyframes") && i + 1 < argc) po.keyframe_interval = std::max(0, std::atoi(argv[++i]));
    else if (!std::strcmp(argv[i], "--keyframe-iou") && i + 1 < argc) po.keyframe_iou = std::atof(argv[++i]);
    else if (!std::strcmp(argv[i], "--pose-rounds") && i + 1 < argc) po.pose_rounds = std::atoi(argv[++i]);
    else if (!std::strcmp(argv[i], "--smoothness") && i + 1 < argc) po.smoothness = std::atof(argv[++i]);
    else if (!std::strcmp(argv[i], "--refine") && i + 1 < argc) po.refine_iterations = std::atoi(argv[++i]);
    else if (!std::strcmp(argv[i], "--handles") && i + 1 < argc) po.handles = std::atoi(argv[++i]);
    else if (!std::strcmp(argv[i], "--tets") && i + 1 < argc) po.tets = std::atoi(argv[++i]);
    else if (!std::strcmp(argv[i], "--anchor-weight") && i + 1 < argc) po.anchor_weight = std::atof(argv[++i]);
    else if (!std::strcmp(argv[i], "--reject-px") && i + 1 < argc) po.reject_px = std::atof(argv[++i]);
    else if (!std::strcmp(argv[i], "--deformer-iterations") && i + 1 < argc) po.deformer_iterations = std::atoi(argv[++i]);
    else if (!std::strcmp(argv[i], "--vlasic-only") && i + 1 < argc) vlasic_only = argv[++i];
    else if (!std::strcmp(argv[i], "--floor") && i + 1 < argc) floor_iterations = std::max(0, std::atoi(argv[++i]));
    else {
      std::fprintf(stderr, "usage: bench_capture_perf [--repeats N] [--capture-frames N (10; 0 = none)] [--capture-size PX (1004)] [--capture-only [--capture-detail 1|2 (1)]] [--vlasic STEPS [--vlasic-turn | --vlasic-rigid]] [--keyframes N [--keyframe-iou X]] [--pose-rounds N] [--smoothness X] [--refine N] [--handles N] [--tets N] [--anchor-weight X] [--reject-px X] [--deformer-iterations N] [--vlasic-only samba|crane] [--floor ITERATIONS] [--stereo FRAMES] [--hull FRAMES]\n");
      return 2;
    }
  }
  if (capture_only || vlasic > 0 || stereo > 0 || hull > 0) {
    std::string why;
    if (!po.isValid(&why)) {
      std::fprintf(stderr, "bench_capture_perf: %s\n", why.c_str());
      return 2;
    }
    if (capture_frames > 0 && capture_only) capture_rows(capture_frames, capture_size, {capture_detail}, po, floor_iterations);
    if (vlasic > 0) vlasic_rows(vlasic, capture_size, vlasic_mode, po, vlasic_only, floor_iterations);
    if (stereo > 0) stereo_rows(stereo, capture_size);
    if (hull > 0) hull_rows(hull, capture_size);
    return 0;
  }
  const std::string shared = TBSP_SHARED_DATA_DIR;
  const MarkerTrajectories mk = read_c3d(shared + "/capture/surenkum__c3d_to_xyz/01_01.c3d");
  const TriMesh tmpl = read_mesh(shared + "/meshes/dengnantianjie__3dcoursework/bunny/data/FinalBaseMesh.obj");
  const auto map = load_marker_map_json(std::string(TBSP_SAMPLE_DATA_DIR) + "/markers/cmu_finalbasemesh_map.json");

  struct Take {
    double setup = 0, wall = 0, deform = 0, transfer = 0, residual = 0;
    long tets = 0, tet_vertices = 0;
  };
  std::vector<Take> takes;
  std::vector<Eigen::MatrixX3d> tet_positions;  // of the last take, every 10th frame (for part 2)
  TetMesh rest_tets;
  for (int r = 0; r < repeats; ++r) {
    MarkerAnimation anim;
    anim.setTemplate(tmpl);
    anim.setMarkerMap(map);
    anim.setMarkers(mk.names, mk.data);
    const auto t0 = Clock::now();
    anim.start();
    TriMesh m;
    std::vector<double> d, t, res;
    while (anim.next(m)) {
      d.push_back(anim.report().frames.back().seconds_deform);
      t.push_back(anim.report().frames.back().seconds_transfer);
      res.push_back(anim.report().frames.back().median_residual);
    }
    Take k;
    k.wall = since(t0);
    k.setup = anim.report().seconds_setup;
    k.deform = median(d);
    k.transfer = median(t);
    k.residual = median(res);
    k.tets = long(anim.report().tets);
    k.tet_vertices = long(anim.report().tet_vertices);
    takes.push_back(k);
  }
  std::sort(takes.begin(), takes.end(), [](const Take& a, const Take& b) { return a.wall < b.wall; });
  const Take& k = takes[takes.size() / 2];
  std::printf("## Marker animation: CMU 01_01 (%d frames, %zu mapped markers) on the human base mesh (median of %d takes)\n\n", mk.numFrames(),
              map.size(), repeats);
  std::printf("| surface vertices | tet vertices / tets | setup (s) | deform per frame (ms) | frames/s (deformation) | transfer per frame (ms) | "
              "whole take (s) | median marker residual (mm) | peak RSS (MB) |\n|---|---|---|---|---|---|---|---|---|\n");
  std::printf("| %ld | %ld / %ld | %.2f | %.2f | %.0f | %.2f | %.1f | %.1f | %.0f |\n", long(tmpl.V.rows()), k.tet_vertices, k.tets, k.setup,
              1000 * k.deform, 1.0 / k.deform, 1000 * k.transfer, k.wall, k.residual, peak_rss_mb());

  // Part 2: bigger surfaces on the same control mesh (the template's, 5000 tets asked): the
  // first 300 frames; median transfer time per frame.
  const TetMesh tets = tetrahedralize_to_size(tmpl, 5000);
  std::vector<TriMesh> surfaces{tmpl};
  {
    std::vector<char> half(std::size_t(tmpl.F.rows()), 0);
    for (std::size_t f = 0; f < half.size(); ++f)  // the faces of the lower half of the body split
      half[f] = tmpl.V(tmpl.F(Eigen::Index(f), 0), 1) < 0.45 * tmpl.V.col(1).maxCoeff();
    const SubdivisionResult a = adaptive_subdivide(tmpl.V, tmpl.F, half);
    const SubdivisionResult b = adaptive_subdivide(tmpl.V, tmpl.F, std::vector<char>(std::size_t(tmpl.F.rows()), 1));
    TriMesh ma, mb;
    ma.V = a.V;
    ma.F = a.F;
    mb.V = b.V;
    mb.F = b.F;
    surfaces.push_back(ma);
    surfaces.push_back(mb);
  }
  std::printf("\n## Transfer to the surface (same control mesh, %ld tets; first 300 frames)\n\n| surface vertices | precompute (s) | transfer per frame (ms) |\n|---|---|---|\n",
              long(tets.T.rows()));
  for (const TriMesh& sfc : surfaces) {
    MarkerAnimation anim;
    anim.setTemplate(sfc, tets);
    anim.setMarkerMap(map);  // the map's vertices keep their indices (subdivision appends)
    anim.setMarkers(mk.names, mk.data.topRows(300));
    const auto t0 = Clock::now();
    anim.start();
    const double setup = since(t0);
    TriMesh m;
    std::vector<double> t;
    while (anim.next(m)) t.push_back(anim.report().frames.back().seconds_transfer);
    std::printf("| %ld | %.2f | %.2f |\n", long(sfc.V.rows()), setup, 1000 * median(t));
  }
  if (capture_frames > 0) capture_rows(capture_frames, capture_size, {1, 2});
  return 0;
}
