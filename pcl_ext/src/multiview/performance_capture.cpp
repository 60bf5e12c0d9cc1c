#include "tbsp/multiview/performance_capture.h"

#include <algorithm>
#include <cmath>

#include <opencv2/imgproc.hpp>

#include "tbsp/core/error.h"
#include "tbsp/core/logging.h"
#include "tbsp/core/timer.h"
#include "tbsp/deform/deformation_transfer.h"
#include "tbsp/deform/tet_deformer.h"
#include "tbsp/mesh/point_search.h"
#include "tbsp/mesh/tetrahedralize.h"
#include "tbsp/mesh/topology.h"
#include "tbsp/multiview/rasterizer.h"
#include "tbsp/multiview/model_guided_stereo.h"
#include "tbsp/multiview/silhouette_refinement.h"
#include "capture_features.h"
#include "capture_pose.h"
#include "silhouette_match.h"

namespace tbsp {

bool PerformanceCaptureOptions::isValid(std::string* why) const {
  auto fail = [&](const std::string& m) {
    if (why) *why = m;
    return false;
  };
  auto finite_pos = [](double v) { return v > 0 && std::isfinite(v); };
  if (tets != 0 && tets < 100) return fail("tets must be 0 (the template as is) or >= 100");
  if (handles < 4 || handles > 5000) return fail("handles must be in 4..5000");
  if (!(transfer_radius >= 0) || !std::isfinite(transfer_radius)) return fail("transfer_radius must be >= 0");
  if (pose_rounds < 1 || pose_rounds > 20) return fail("pose_rounds must be in 1..20");
  if (deformer_iterations < 1 || deformer_iterations > 100) return fail("deformer_iterations must be in 1..100");
  if (!finite_pos(smoothness)) return fail("smoothness must be > 0");
  if (!finite_pos(robust_px)) return fail("robust_px must be > 0");
  if (!(reject_px > robust_px) || !std::isfinite(reject_px)) return fail("reject_px must be > robust_px");
  if (max_features < 100 || max_features > 100000) return fail("max_features must be in 100..100000");
  if (!(ratio > 0) || ratio > 1) return fail("ratio must be in (0, 1]");
  if (!finite_pos(max_flow_px)) return fail("max_flow_px must be > 0");
  if (!finite_pos(anchor_weight) || anchor_weight > 100) return fail("anchor_weight must be in (0, 100]");
  if (keyframe_interval < 0 || keyframe_interval > 10000) return fail("keyframe_interval must be in 0..10000");
  if (!(keyframe_iou > 0) || keyframe_iou > 1) return fail("keyframe_iou must be in (0, 1]");
  if (!(silhouette_weight > 0) || silhouette_weight > 10) return fail("silhouette_weight must be in (0, 10]");
  if (!finite_pos(search_px)) return fail("search_px must be > 0");
  if (key_handles < 1 || key_handles > 100) return fail("key_handles must be in 1..100");
  if (max_evaluations < 10) return fail("max_evaluations must be >= 10");
  if (!(optimize_image_scale > 0) || optimize_image_scale > 1) return fail("optimize_image_scale must be in (0, 1]");
  if (!(stereo_search_range >= 0) || !std::isfinite(stereo_search_range)) return fail("stereo_search_range must be >= 0 and finite");
  if (stereo_refine && !features) return fail("stereo_refine needs the images (features = true)");
  if (refine_iterations < 0 || refine_iterations > 100) return fail("refine_iterations must be in 0..100");
  if (!(failure_iou >= 0) || !(failure_iou < 1)) return fail("failure_iou must be in [0, 1)");
  if (!features && !silhouettes) return fail("features and silhouettes are both off: nothing would drive the template");
  if (hull_resolution < 16 || hull_resolution > 1024) return fail("hull_resolution must be in 16..1024");
  if (!(hull_min_iou_gain >= 0 && hull_min_iou_gain <= 1)) return fail("hull_min_iou_gain must be in [0, 1]");
  return true;
}

CaptureControlModel build_capture_control_model(const TriMesh& templ, int tets, int handles, const TetMesh* given) {
  CaptureControlModel cm;
  if (given) {
    cm.tets = *given;
    cm.surface = tet_boundary_faces(cm.tets.T);
  } else {
    try {
      try {
        cm.tets = tetrahedralize_to_size(templ, tets);
      } catch (const Error&) {
        cm.tets = tetrahedralize_components(templ, tets);  // overlapping closed parts
        cm.per_component = true;
      }
      cm.surface = tet_boundary_faces(cm.tets.T);
    } catch (const Error&) {
      const TriMesh dec = tets > 0 && tets < templ.F.rows() ? decimate_mesh(templ, tets) : templ;
      cm.tets = surface_to_tets(dec);  // one tetrahedron per triangle (§10.8)
      cm.surface = dec.F;
      cm.shell = true;
    }
  }
  std::vector<char> on(std::size_t(cm.tets.V.rows()), 0);
  for (Eigen::Index f = 0; f < cm.surface.rows(); ++f)
    for (int c = 0; c < 3; ++c) {
      const int v = cm.surface(f, c);
      if (!on[std::size_t(v)]) {
        on[std::size_t(v)] = 1;
        cm.surface_vertices.push_back(v);
      }
    }
  cm.handles = farthest_point_sample(cm.tets.V, cm.surface_vertices, handles);
  return cm;
}

struct PerformanceCapture::Impl {
  TetMesh tets;
  TetDeformer D;
  DeformationTransfer transfer;
  std::vector<int> surf_vertex;    // tet vertices on the control surface
  Eigen::MatrixX3i surf_faces;     // tet vertex indices
  std::vector<int> handle_vertex;  // handle id -> tet vertex
  std::vector<int> key;            // handle ids of the optimization
  Eigen::MatrixXd response;        // template vertex x handle: the deformer's linear response, transferred
  Eigen::MatrixXd stiffness;       // handle x handle: membrane energy of the template motion they cause
  Eigen::MatrixX3d X;              // control mesh, current pose
  TriMesh mesh;                    // output of the last frame
  std::vector<detail::LiftedFeatures> prev, anchor;
  int frames = 0;
  int last_keyframe = 0;
  std::vector<RenderBuffers> buffers;  // re-used by every render of every frame (no refill)
  SilhouetteRefinement refinement;     // the same: its render buffers stay between frames
};

PerformanceCapture::PerformanceCapture() : impl_(new Impl) {}
PerformanceCapture::~PerformanceCapture() = default;

void PerformanceCapture::setOptions(const PerformanceCaptureOptions& o) {
  std::string why;
  if (!o.isValid(&why)) throw InvalidInput("[tbsp::PerformanceCapture::setOptions] " + why);
  options_ = o;
  started_ = false;
}

void PerformanceCapture::setCameras(std::vector<Camera> cameras) {
  cameras_ = std::move(cameras);
  started_ = false;
}

void PerformanceCapture::setTemplate(const TriMesh& posed) {
  template_ = posed;
  template_tets_ = TetMesh{};
  tets_given_ = false;
  started_ = false;
}

void PerformanceCapture::setTemplate(const TriMesh& posed, const TetMesh& tets) {
  template_ = posed;
  template_tets_ = tets;
  tets_given_ = true;
  started_ = false;
}

TetMesh PerformanceCapture::controlMesh() const {
  TetMesh t = impl_->tets;
  if (started_) t.V = impl_->X;
  return t;
}

void PerformanceCapture::start(const Eigen::Matrix4d* registration) {
  const std::string who = "[tbsp::PerformanceCapture] ";
  const auto t0 = Clock::now();
  if (cameras_.empty()) throw InvalidInput(who + "no cameras: call setCameras with the calibrated views");
  if (template_.V.rows() < 4 || template_.F.rows() < 4) throw InvalidInput(who + "the template is empty: set a closed surface mesh");
  if (!template_.V.allFinite()) throw InvalidInput(who + "the template has non-finite vertices");
  // the template (and given tets) the tracking starts from: as given, or registered to the hull
  TriMesh templ = template_;
  TetMesh given_tets = template_tets_;
  if (registration) {
    templ.V = transform_points(*registration, templ.V);
    if (tets_given_) given_tets.V = transform_points(*registration, given_tets.V);
  }
  impl_.reset(new Impl);
  Impl& I = *impl_;
  report_ = PerformanceCaptureReport{};
  report_progress(progress_, 0.0, "tetrahedralize");
  if (tets_given_) require_valid_tet_mesh(given_tets, who);
  CaptureControlModel cm = build_capture_control_model(templ, options_.tets, options_.handles, tets_given_ ? &given_tets : nullptr);
  report_.per_component_tets = cm.per_component;
  report_.shell_tets = cm.shell;
  I.tets = std::move(cm.tets);
  I.surf_faces = std::move(cm.surface);
  I.surf_vertex = std::move(cm.surface_vertices);
  I.handle_vertex = std::move(cm.handles);
  I.D.setMesh(I.tets);
  for (int v : I.handle_vertex) I.D.addVertexHandle(v, I.tets.V.row(v).transpose());
  std::vector<int> ids(I.handle_vertex.size());
  for (std::size_t h = 0; h < ids.size(); ++h) ids[h] = I.handle_vertex[h];
  const std::vector<int> key_vertices = farthest_point_sample(I.tets.V, ids, options_.key_handles);
  for (int v : key_vertices) I.key.push_back(int(std::find(I.handle_vertex.begin(), I.handle_vertex.end(), v) - I.handle_vertex.begin()));
  report_progress(progress_, 0.0, "transfer");
  DeformationTransferOptions to;
  to.radius = options_.transfer_radius;
  I.transfer.setOptions(to);
  I.transfer.precompute(I.tets, templ.V);
  // How each template vertex moves per unit move of each handle (rotations fixed): the
  // deformer's linear response carried through the transfer, B · ∂X/∂h. Exact for the linear
  // solve of the next deformer iteration, so constraints on template points fit the handles.
  {
    std::vector<int> all(std::size_t(I.tets.V.rows()));
    for (std::size_t v = 0; v < all.size(); ++v) all[v] = int(v);
    I.response = I.transfer.matrix() * I.D.handleResponse(all);  // factorizes
    I.stiffness = detail::handle_stiffness(I.response, unique_edges(templ.F));
  }
  I.X = I.tets.V;
  I.mesh = templ;
  report_.tet_vertices = I.tets.V.rows();
  report_.tets = I.tets.T.rows();
  report_.surface_vertices = templ.V.rows();
  report_.control_surface_vertices = Eigen::Index(I.surf_vertex.size());
  report_.handles = int(I.handle_vertex.size());
  report_.t_setup = seconds_since(t0);
  started_ = true;
}

namespace {

struct FrameMatches {
  int camera = 0;
  detail::FeatureMatch m;
  bool anchor = false;  ///< to the first frame's keypoints
};

double pixel_size(const Camera& cam, const Eigen::Vector3d& X) { return std::max(cam.depth(X), 1e-9) / cam.K()(0, 0); }

}  // namespace

void PerformanceCapture::track(const std::vector<cv::Mat>& images, const std::vector<cv::Mat>& silhouettes, int frame, TriMesh& out) {
  const auto t_frame = Clock::now();
  const std::string where = "[tbsp::PerformanceCapture] frame " + std::to_string(frame) + ": ";
  const int n = int(cameras_.size());
  if (n < 1) throw InvalidInput(where + "no cameras: call setCameras with the calibrated views");
  detail::check_silhouettes(cameras_, silhouettes, where);
  if (options_.features) {
    if (int(images.size()) != n)
      throw InvalidInput(where + "one image per camera is needed (" + std::to_string(n) + " cameras, " + std::to_string(images.size()) + " images)");
    for (int k = 0; k < n; ++k) {
      const cv::Mat& im = images[std::size_t(k)];
      if (im.empty() || im.depth() != CV_8U || (im.channels() != 1 && im.channels() != 3) || im.cols != cameras_[k].width() ||
          im.rows != cameras_[k].height())
        throw InvalidInput(where + "camera '" + cameras_[k].name() + "': the image must be 8-bit grey or BGR and " +
                           std::to_string(cameras_[k].width()) + "x" + std::to_string(cameras_[k].height()) + " (the calibrated size)");
    }
  }
  if (!started_) {
    if (options_.register_to_hull) {
      report_progress(progress_, 0.0, "visual hull");
      VisualHullOptions ho;
      ho.resolution = options_.hull_resolution;
      HullRegistration reg;
      std::string message;
      try {
        reg = register_to_visual_hull(template_, cameras_, silhouettes, ho);
        if (!(reg.iou_before > 0))  // a template nowhere near the performer is an error below, not a start for ICP
          message = "the template covers no silhouette pixel: it was not registered";
        else if (!(reg.iou_after >= reg.iou_before + options_.hull_min_iou_gain))
          message = "the registration did not raise the mean silhouette IoU by " + std::to_string(options_.hull_min_iou_gain) + " (" +
                    std::to_string(reg.iou_before) + " -> " + std::to_string(reg.iou_after) + "): the template was used as given";
      } catch (const InvalidInput& e) {
        message = std::string("no visual hull: ") + e.what() + "; the template was used as given";
      }
      const bool apply = message.empty();
      if (!apply) logger()->info("{}{}", where, message);
      start(apply ? &reg.icp.transform : nullptr);
      report_.hull_tried = true;
      report_.hull_registered = apply;
      report_.hull_message = message;
      report_.hull = reg;
    } else {
      start();
    }
  }
  Impl& I = *impl_;
  const PerformanceCaptureOptions& o = options_;
  const bool first = I.frames == 0;
  CaptureFrameReport fr;
  fr.frame = frame;
  std::vector<detail::SilhouetteView> sv(static_cast<std::size_t>(n));
  for (int k = 0; k < n; ++k) sv[std::size_t(k)].set(silhouettes[std::size_t(k)]);

  // 1. features and matches
  auto t0 = Clock::now();
  std::vector<detail::ViewFeatures> cur(static_cast<std::size_t>(n));
  if (o.features) {
#pragma omp parallel for schedule(dynamic, 1)
    for (int k = 0; k < n; ++k) cur[std::size_t(k)] = detail::detect_features(images[std::size_t(k)], silhouettes[std::size_t(k)], o.max_features);
    for (const auto& c : cur) fr.keypoints += int(c.pixel.size());
  }
  fr.t_features = seconds_since(t0);
  report_progress(progress_, 0.2, "match");
  t0 = Clock::now();
  std::vector<FrameMatches> matches;
  std::vector<std::vector<detail::FeatureMatch>> tracks(static_cast<std::size_t>(n));  // temporal matches per view: tracks go on
  if (o.features && !first) {
    std::vector<std::vector<detail::FeatureMatch>> per(static_cast<std::size_t>(n));
    std::vector<int> nt(static_cast<std::size_t>(n), 0), na(static_cast<std::size_t>(n), 0);
#pragma omp parallel for schedule(dynamic, 1)
    for (int k = 0; k < n; ++k) {
      const std::size_t K = std::size_t(k);
      nt[K] = detail::match_features(I.prev[K], cur[K], I.mesh, cameras_[K], o.ratio, o.max_flow_px, per[K]);
      if (o.anchor_first_frame && I.frames > 1) {
        if (o.anchor_all_views)  // the first frame's keypoints of every view whose surface point faces this camera now
          na[K] = detail::match_features(detail::facing_features(I.anchor, I.mesh, cameras_[K], 0.3), cur[K], I.mesh, cameras_[K], o.ratio,
                                         o.max_flow_px, per[K]);
        else
          na[K] = detail::match_features(I.anchor[K], cur[K], I.mesh, cameras_[K], o.ratio, o.max_flow_px, per[K]);
      }
    }
    for (int k = 0; k < n; ++k) tracks[std::size_t(k)] = per[std::size_t(k)];  // anchors last: they win
    for (int k = 0; k < n; ++k) {
      fr.temporal_matches += nt[std::size_t(k)];
      fr.anchor_matches += na[std::size_t(k)];
      const auto& pk = per[std::size_t(k)];  // temporal matches first, then anchors
      for (std::size_t q = 0; q < pk.size(); ++q) matches.push_back({k, pk[q], int(q) >= nt[std::size_t(k)]});
    }
  }
  fr.t_match = seconds_since(t0);

  // 2.-3. pose rounds: ray constraints -> displacement field -> handles -> TetDeformer
  RasterOptions ro;
  ro.barycentrics = false;
  const Rasterizer coarse(ro);
  detail::RimMatchOptions rmo;
  rmo.search_px = o.search_px;
  rmo.max_distance_px = o.search_px;
  rmo.cos_max = 0.5;
  detail::HandleSolveOptions dopt;
  dopt.smoothness = o.smoothness;
  dopt.robust_px = o.robust_px;
  dopt.reject_px = o.reject_px;
  std::vector<RenderBuffers>& buf = I.buffers;
  auto pose = [&](bool use_features, int rounds) {
    for (int r = 0; r < rounds; ++r) {
      report_progress(progress_, 0.3 + 0.4 * r / rounds, "pose");
      std::vector<detail::RayConstraint> C;
      TriMesh cur_mesh;  // the template at the control mesh's current pose
      cur_mesh.V = I.transfer.apply(I.X);
      cur_mesh.F = template_.F;
      if (use_features && !matches.empty()) {
        C.resize(matches.size());
#pragma omp parallel for schedule(static)
        for (std::size_t i = 0; i < matches.size(); ++i) {
          const Camera& cam = cameras_[std::size_t(matches[i].camera)];
          const detail::FeatureMatch& fm = matches[i].m;
          detail::RayConstraint& c = C[i];
          c.p = detail::surface_point(cur_mesh, fm.face, fm.bary);
          for (int a = 0; a < 3; ++a) {
            c.v[std::size_t(a)] = template_.F(fm.face, a);
            c.w[std::size_t(a)] = fm.bary(a);
          }
          const Ray ray = cam.ray(fm.pixel);
          c.origin = ray.origin;
          c.dir = ray.direction;
          c.pixel_size = pixel_size(cam, c.p);
          if (matches[i].anchor) c.weight = o.anchor_weight;
        }
      }
      int rims = 0;
      if (o.silhouettes) {
        // rims of the template itself (its exact contour), carried by the control surface
        coarse.renderViews(cur_mesh, cameras_, buf);
        for (int k = 0; k < n; ++k) {
          const Camera& cam = cameras_[std::size_t(k)];
          for (const detail::RimMatch& m : detail::match_rims(cur_mesh, cam, buf[std::size_t(k)], sv[std::size_t(k)], rmo)) {
            detail::RayConstraint c;
            c.v[0] = m.vertex;
            c.w[0] = 1;
            c.p = cur_mesh.V.row(m.vertex).transpose();
            const Ray ray = cam.ray(m.pixel);
            c.origin = ray.origin;
            c.dir = ray.direction;
            // the plane through the camera centre and the contour's tangent line at the match
            const Eigen::Vector2d tangent(-m.normal.y(), m.normal.x());
            c.plane_normal = ray.direction.cross(cam.ray(m.pixel + 5.0 * tangent).direction).normalized();
            c.pixel_size = pixel_size(cam, c.p);
            c.weight = o.silhouette_weight;
            c.feature = false;
            C.push_back(c);
            ++rims;
          }
        }
      }
      if (C.empty()) break;
      const detail::HandleSolveResult dr = detail::solve_handles(I.response, I.stiffness, C, dopt);
      fr.inliers = dr.feature_inliers;
      fr.rim_constraints = rims;
      for (std::size_t h = 0; h < I.handle_vertex.size(); ++h) {
        const int v = I.handle_vertex[h];
        I.D.setHandleTarget(int(h), (I.X.row(v) + dr.dh.row(Eigen::Index(h))).transpose());
      }
      for (int it = 0; it < o.deformer_iterations; ++it) I.D.iterate();
      I.X = I.D.inputPositions();
    }
  };
  if (first) {
    TriMesh ctrl;
    ctrl.V = I.X;
    ctrl.F = I.surf_faces;
    coarse.renderViews(ctrl, cameras_, buf);
    bool covered = false;
    for (const auto& b : buf) covered = covered || b.box_x0 <= b.box_x1;
    if (!covered) throw InvalidInput(where + "the template is outside every view (no pixel covered): pose it like the performer in the first frame");
  }
  t0 = Clock::now();
  const Eigen::MatrixX3d X_start = I.X;
  const std::vector<Eigen::Matrix3d> R_start = I.D.rotations();
  pose(!first, first ? 2 * o.pose_rounds : o.pose_rounds);
  fr.t_pose = seconds_since(t0);

  // 4. handle optimization (thesis' black-box step)
  auto optimize = [&]() {
    detail::HandleOptimization ho;
    for (int k = 0; k < n; ++k) {
      ho.cameras.push_back(cameras_[std::size_t(k)].resized(o.optimize_image_scale));
      cv::Mat s;
      cv::resize(sv[std::size_t(k)].mask, s, cv::Size(ho.cameras.back().width(), ho.cameras.back().height()), 0, 0, cv::INTER_AREA);
      ho.silhouettes.push_back(s >= 128);
    }
    ho.surface = I.surf_faces;
    const Eigen::Vector3d lo = I.X.colwise().minCoeff(), hi = I.X.colwise().maxCoeff();
    ho.step = 0.005 * (hi - lo).norm();
    ho.max_evaluations = o.max_evaluations;
    std::vector<Eigen::Vector3d> targets;
    for (int h : I.key) targets.push_back(I.X.row(I.handle_vertex[std::size_t(h)]).transpose());
    fr.evaluations = detail::optimize_handles(I.D, I.key, targets, ho, fr.opt_iou_before, fr.opt_iou_after);
    I.X = I.D.inputPositions();
  };
  t0 = Clock::now();
  if (o.optimize_handles) optimize();
  fr.t_optimize = seconds_since(t0);

  // 5. transfer and refinement
  auto finish = [&](TriMesh& m, SilhouetteRefinementReport& rr) {
    auto t1 = Clock::now();
    m.V = I.transfer.apply(I.X);
    m.F = template_.F;
    fr.t_transfer += seconds_since(t1);
    // Model-guided stereo first: the silhouette refinement after it restores the contour the
    // stereo fit may have moved.
    if (o.stereo_refine) {
      t1 = Clock::now();
      ModelGuidedStereoOptions mo;
      const double diag = (template_.V.colwise().maxCoeff() - template_.V.colwise().minCoeff()).norm();
      mo.search_range = o.stereo_search_range > 0 ? o.stereo_search_range : 0.01 * diag;
      ModelGuidedStereo mgs;
      mgs.setOptions(mo);
      mgs.setInputFrame(cameras_, images, silhouettes, frame);
      mgs.setInputMesh(m);
      TriMesh detailed;
      mgs.refine(detailed);
      fr.stereo_points = int(mgs.report().points);
      m = std::move(detailed);
      fr.t_stereo += seconds_since(t1);
    }
    t1 = Clock::now();
    if (o.refine_iterations > 0) {
      SilhouetteRefinement& sr = I.refinement;
      SilhouetteRefinementOptions so;
      so.max_iterations = o.refine_iterations;
      sr.setOptions(so);
      sr.setInputFrame(cameras_, silhouettes, frame);
      sr.setInputMesh(m);
      TriMesh refined;
      sr.refine(refined);  // also measures the overlap before and after
      rr = sr.report();
      m = std::move(refined);
    } else {  // the overlap only
      coarse.renderViews(m, cameras_, buf);
      rr = SilhouetteRefinementReport{};
      rr.views.resize(static_cast<std::size_t>(n));
      for (int k = 0; k < n; ++k)
        rr.views[std::size_t(k)].iou_before = rr.views[std::size_t(k)].iou_after =
            detail::silhouette_overlap(buf[std::size_t(k)], sv[std::size_t(k)]).iou;
    }
    fr.t_refine += seconds_since(t1);
  };
  report_progress(progress_, 0.8, "refine");
  TriMesh result;
  SilhouetteRefinementReport rr;
  finish(result, rr);
  // iou_after: of the returned mesh (refined, or the transferred pose when refinement is off,
  // then equal to iou_before; after model-guided stereo when it ran)
  auto summarize = [&](const SilhouetteRefinementReport& r, std::vector<double>& iou) {
    iou.clear();
    for (const auto& v : r.views) iou.push_back(v.iou_after);
    return *std::min_element(iou.begin(), iou.end());
  };
  double iou_min = summarize(rr, fr.iou);
  {
    double s = 0;
    for (const auto& v : rr.views) s += v.iou_before;
    fr.iou_pose = s / double(rr.views.size());
  }
  if (iou_min < o.failure_iou && !first) {
    // Tracking failure: a second, silhouette-only pose pass from the previous frame's pose
    // (the features may have been outliers); keep whichever is better.
    fr.retried = true;
    const Eigen::MatrixX3d X_first = I.X;
    const std::vector<Eigen::Matrix3d> R_first = I.D.rotations();
    I.X = X_start;
    I.D.setRotations(R_start);
    if (o.silhouettes) pose(false, 2 * o.pose_rounds);
    TriMesh again;
    SilhouetteRefinementReport rr2;
    finish(again, rr2);
    std::vector<double> iou2;
    const double m2 = summarize(rr2, iou2);
    if (m2 > iou_min) {
      result = std::move(again);
      fr.iou = iou2;
      iou_min = m2;
    } else {
      I.X = X_first;
      I.D.setRotations(R_first);
    }
  }
  fr.iou_min = iou_min;
  double s = 0;
  for (double v : fr.iou) s += v;
  fr.iou_mean = s / double(fr.iou.size());
  fr.failed = iou_min < o.failure_iou;
  // 6. lift this frame's keypoints onto the result (next frame's temporal matches)
  t0 = Clock::now();
  TriMesh model;  // the tracking model of this frame (unrefined): the next frame's matches are gated on it
  model.V = I.transfer.apply(I.X);
  model.F = template_.F;
  if (o.features) {
    // face ids and depth only: lift_features computes the barycentrics at the keypoints' pixels
    // (the same values as a barycentric buffer, without its 8 bytes per pixel in every view)
    const Rasterizer fine(ro);
    std::vector<RenderBuffers>& fb = I.buffers;
    // On the tracking model itself (the transferred control mesh, before refinement): the next
    // frame's constraints move points of that model, so its surface points must be identified on it.
    fine.renderViews(model, cameras_, fb);
    I.prev.assign(std::size_t(n), {});
#pragma omp parallel for schedule(dynamic, 1)
    for (int k = 0; k < n; ++k) {
      const std::size_t K = std::size_t(k);
      I.prev[K] = detail::lift_features(cur[K], fb[K], tracks[K], &model, &cameras_[K]);
    }
    if (first) {
      I.anchor = I.prev;
      I.last_keyframe = I.frames;
    } else if (o.keyframe_interval > 0 && o.anchor_first_frame && o.anchor_all_views && !fr.failed &&
               fr.iou_min >= o.keyframe_iou && I.frames - I.last_keyframe >= o.keyframe_interval) {
      I.anchor.insert(I.anchor.end(), I.prev.begin(), I.prev.end());
      I.last_keyframe = I.frames;
      fr.keyframe = true;
    }
  }
  fr.t_match += seconds_since(t0);
  I.mesh = std::move(model);
  ++I.frames;
  fr.t_total = seconds_since(t_frame);
  report_.failed_frames += fr.failed;
  report_.frames.push_back(fr);
  out = std::move(result);
}

}  // namespace tbsp
