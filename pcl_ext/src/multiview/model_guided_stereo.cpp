#include "tbsp/multiview/model_guided_stereo.h"

#include <algorithm>
#include <cmath>
#include <exception>
#include <limits>

#include <opencv2/imgproc.hpp>

#include "tbsp/core/error.h"
#include "tbsp/core/timer.h"
#include "tbsp/multiview/rasterizer.h"

namespace tbsp {

bool ModelGuidedStereoOptions::isValid(std::string* why) const {
  auto fail = [&](const std::string& m) {
    if (why) *why = m;
    return false;
  };
  if (!(search_range > 0) || !std::isfinite(search_range)) return fail("search_range must be > 0");
  if (depth_samples < 5 || depth_samples > 201) return fail("depth_samples must be in 5..201");
  if (patch_size < 3 || patch_size > 15 || patch_size % 2 == 0) return fail("patch_size must be odd and in 3..15");
  if (!(image_scale > 0) || image_scale > 1) return fail("image_scale must be in (0, 1]");
  if (pixel_stride < 1 || pixel_stride > 16) return fail("pixel_stride must be in 1..16");
  if (!(min_ncc > -1) || !(min_ncc < 1)) return fail("min_ncc must be in (-1, 1)");
  if (!(distinct_margin >= 0)) return fail("distinct_margin must be >= 0");
  if (min_views < 1) return fail("min_views must be >= 1");
  if (!(max_view_angle_deg > 0) || !(max_view_angle_deg < 90)) return fail("max_view_angle_deg must be in (0, 90)");
  if (!(normal_tilt_deg >= 0) || !(normal_tilt_deg < 60)) return fail("normal_tilt_deg must be in [0, 60)");
  if (!(constraint_weight > 0) || constraint_weight > 10) return fail("constraint_weight must be in (0, 10]");
  if (fit_iterations < 1 || fit_iterations > 100) return fail("fit_iterations must be in 1..100");
  if (detail_rounds < 0 || detail_rounds > 10) return fail("detail_rounds must be in 0..10");
  if (min_agreeing_views < 0) return fail("min_agreeing_views must be >= 0");
  return true;
}

void ModelGuidedStereo::setOptions(const ModelGuidedStereoOptions& o) {
  std::string why;
  if (!o.isValid(&why)) throw InvalidInput("[tbsp::ModelGuidedStereo::setOptions] " + why);
  options_ = o;
}

void ModelGuidedStereo::setInputFrame(std::vector<Camera> cameras, std::vector<cv::Mat> images, std::vector<cv::Mat> silhouettes, int frame) {
  cameras_ = std::move(cameras);
  images_ = std::move(images);
  silhouettes_ = std::move(silhouettes);
  frame_ = frame;
}

namespace {

inline bool bilinear(const cv::Mat& g, const Eigen::Vector2d& p, float& out) {
  const double x = p.x(), y = p.y();
  if (!(x >= 0) || !(y >= 0) || x > g.cols - 1.001 || y > g.rows - 1.001) return false;
  const int x0 = static_cast<int>(x), y0 = static_cast<int>(y);
  const float fx = static_cast<float>(x - x0), fy = static_cast<float>(y - y0);
  const float* r0 = g.ptr<float>(y0);
  const float* r1 = g.ptr<float>(y0 + 1);
  out = (1 - fy) * ((1 - fx) * r0[x0] + fx * r0[x0 + 1]) + fy * ((1 - fx) * r1[x0] + fx * r1[x0 + 1]);
  return true;
}

// A patch plane: normal n and an orthonormal tangent pair (u, v).
struct TangentFrame {
  Eigen::Vector3d n, u, v;
  explicit TangentFrame(const Eigen::Vector3d& normal)
      : n(normal), u((std::abs(normal.x()) < 0.9 ? Eigen::Vector3d::UnitX() : Eigen::Vector3d::UnitY()).cross(normal).normalized()), v(n.cross(u)) {}
};

// A reference patch centred once per depth sample; ncc() against each other view's patch.
struct CenteredPatch {
  std::vector<double> d;  // a[k] - mean
  double ss = 0;          // sum of d²
  void set(const std::vector<float>& a) {
    const std::size_t n = a.size();
    double m = 0;
    for (std::size_t k = 0; k < n; ++k) m += a[k];
    m /= n;
    d.resize(n);
    ss = 0;
    for (std::size_t k = 0; k < n; ++k) {
      d[k] = a[k] - m;
      ss += d[k] * d[k];
    }
  }
};

float ncc(const CenteredPatch& a, const std::vector<float>& b) {
  const std::size_t n = b.size();
  double mb = 0;
  for (std::size_t k = 0; k < n; ++k) mb += b[k];
  mb /= n;
  double sab = 0, sbb = 0;
  for (std::size_t k = 0; k < n; ++k) {
    const double db = b[k] - mb;
    sab += a.d[k] * db;
    sbb += db * db;
  }
  // Textureless patches (grey-level deviation below ~1 level) carry no depth information.
  if (a.ss < n * 1.0 || sbb < n * 1.0) return -1.f;
  return static_cast<float>(sab / std::sqrt(a.ss * sbb));
}

struct ViewData {
  Camera cam;
  cv::Mat grey;  // CV_32F
  RenderBuffers buf;
  cv::Mat sil;   // CV_8U at scale, or empty
};

}  // namespace

void ModelGuidedStereo::computeCloud(Eigen::MatrixX3d& points, Eigen::MatrixX3d& normals) { computeCloud(points, normals, progress_); }

void ModelGuidedStereo::computeCloud(Eigen::MatrixX3d& points, Eigen::MatrixX3d& normals, const ProgressCallback& progress) {
  const auto t0 = Clock::now();
  const ModelGuidedStereoOptions& o = options_;
  const std::string where = "[tbsp::ModelGuidedStereo] frame " + std::to_string(frame_) + ": ";
  const int n = static_cast<int>(cameras_.size());
  if (n < 2) throw InvalidInput(where + "needs at least 2 calibrated views, got " + std::to_string(n));
  if (static_cast<int>(images_.size()) != n) throw InvalidInput(where + "one image per camera is needed");
  if (!silhouettes_.empty() && static_cast<int>(silhouettes_.size()) != n) throw InvalidInput(where + "one silhouette per camera (or none) is needed");
  if (mesh_.V.rows() == 0 || mesh_.F.rows() == 0) throw InvalidInput(where + "the mesh is empty: set a posed mesh with setInputMesh");
  for (int k = 0; k < n; ++k) {
    const cv::Mat& im = images_[k];
    if (im.empty() || im.cols != cameras_[k].width() || im.rows != cameras_[k].height() || im.depth() != CV_8U)
      throw InvalidInput(where + "camera '" + cameras_[k].name() + "': the image must be 8-bit and " + std::to_string(cameras_[k].width()) +
                         "x" + std::to_string(cameras_[k].height()) + " (the calibrated size)");
  }
  report_progress(progress, 0.0, "render");
  // Face normals.
  Eigen::MatrixX3d FN(mesh_.F.rows(), 3);
  for (Eigen::Index f = 0; f < mesh_.F.rows(); ++f) {
    const Eigen::Vector3d a = mesh_.V.row(mesh_.F(f, 0)), b = mesh_.V.row(mesh_.F(f, 1)), c = mesh_.V.row(mesh_.F(f, 2));
    const Eigen::Vector3d nn = (b - a).cross(c - a);
    FN.row(f) = nn.norm() > 0 ? Eigen::Vector3d(nn.normalized()) : Eigen::Vector3d::Zero();
  }
  std::vector<ViewData> views(n);
  RasterOptions ro;
  ro.barycentrics = false;
  const Rasterizer rast(ro);
  int covered_views = 0;
  for (int k = 0; k < n; ++k) {
    ViewData& v = views[k];
    v.cam = cameras_[k].resized(o.image_scale);
    cv::Mat g, small;
    if (images_[k].channels() == 3) cv::cvtColor(images_[k], g, cv::COLOR_BGR2GRAY);
    else g = images_[k];
    cv::resize(g, small, cv::Size(v.cam.width(), v.cam.height()), 0, 0, cv::INTER_AREA);
    small.convertTo(v.grey, CV_32F);
    rast.render(mesh_, v.cam, v.buf);
    if (o.use_silhouettes && !silhouettes_.empty() && !silhouettes_[k].empty())
      cv::resize(silhouettes_[k], v.sil, cv::Size(v.cam.width(), v.cam.height()), 0, 0, cv::INTER_NEAREST);
    if (std::any_of(v.buf.face.begin(), v.buf.face.end(), [](std::int32_t f) { return f >= 0; })) ++covered_views;
  }
  if (covered_views == 0)
    throw InvalidInput(where + "the mesh is outside every view (no pixel covered): pose the mesh in the studio's frame first");

  const int S = o.depth_samples, l = o.patch_size, half = l / 2;
  const double step = 2 * o.search_range / (S - 1);
  const double cos_max = std::cos(o.max_view_angle_deg * M_PI / 180.0);
  std::vector<std::vector<Eigen::Vector3d>> pts(n), nrm(n);
  std::vector<int> samples(n, 0);
  std::vector<double> score_sum(n, 0.0);
  std::vector<std::vector<float>> scores(n);
  // Accepted depths per view on the sample grid (for the cross-view consistency test).
  std::vector<cv::Mat> grid(n);
  for (int i = 0; i < n; ++i)
    grid[i] = cv::Mat((views[i].buf.height + o.pixel_stride - 1) / o.pixel_stride, (views[i].buf.width + o.pixel_stride - 1) / o.pixel_stride,
                      CV_32F, cv::Scalar(std::numeric_limits<float>::quiet_NaN()));
  std::exception_ptr err;
  int done = 0;
#pragma omp parallel for schedule(dynamic, 1)
  for (int i = 0; i < n; ++i) {
    try {
      const ViewData& R = views[i];
      const Camera& cam = R.cam;
      const double f = cam.K()(0, 0);
      std::vector<float> ref(static_cast<std::size_t>(l) * l), oth(ref.size());
      CenteredPatch ref_c;
      std::vector<float> score(S);
      std::vector<int> others;
      std::vector<Eigen::Vector3d> patch(ref.size());
      for (int y = 0; y < R.buf.height; y += o.pixel_stride)
        for (int x = 0; x < R.buf.width; x += o.pixel_stride) {
          const std::size_t pix = static_cast<std::size_t>(y) * R.buf.width + x;
          const int face = R.buf.face[pix];
          if (face < 0) continue;
          if (!R.sil.empty() && R.sil.at<std::uint8_t>(y, x) < 128) continue;
          const double d0 = R.buf.depth[pix];
          const Eigen::Vector3d X0 = cam.backProject(Eigen::Vector2d(x, y), d0);
          Eigen::Vector3d nn = FN.row(face).transpose();
          if (nn.dot(cam.center() - X0) < 0) nn = -nn;
          if (nn.dot((cam.center() - X0).normalized()) < cos_max) continue;  // grazing in the reference view
          // Other views that see the patch: front-facing, not hidden by the mesh.
          others.clear();
          for (int j = 0; j < n; ++j) {
            if (j == i) continue;
            const ViewData& V = views[j];
            const Eigen::Vector3d toC = V.cam.center() - X0;
            if (nn.dot(toC.normalized()) < cos_max) continue;
            const Eigen::Vector2d q = V.cam.project(X0);
            const int qx = static_cast<int>(std::lround(q.x())), qy = static_cast<int>(std::lround(q.y()));
            if (qx < half + 1 || qy < half + 1 || qx >= V.buf.width - half - 1 || qy >= V.buf.height - half - 1) continue;
            const float zr = V.buf.depth[static_cast<std::size_t>(qy) * V.buf.width + qx];
            if (V.cam.depth(X0) > zr + 1.5 * o.search_range) continue;  // hidden behind another part of the mesh
            others.push_back(j);
          }
          if (static_cast<int>(others.size()) < o.min_views) continue;
          ++samples[i];
          const double h = d0 / f;  // one reference pixel per patch step at the initial depth
          // Mean NCC over the other views of the l×l patch at depth d0 + t, spanned by the
          // tangent frame `tf`.
          auto score_at = [&](double t, const TangentFrame& tf) -> float {
            const Eigen::Vector3d X = cam.backProject(Eigen::Vector2d(x, y), d0 + t);
            for (int b = -half, k = 0; b <= half; ++b)
              for (int a = -half; a <= half; ++a, ++k) patch[k] = X + (a * tf.u + b * tf.v) * h;
            for (std::size_t k = 0; k < patch.size(); ++k)
              if (!bilinear(R.grey, cam.project(patch[k]), ref[k])) return -1.f;
            ref_c.set(ref);
            float sum = 0;
            int cnt = 0;
            for (int j : others) {
              const ViewData& V = views[j];
              bool okj = true;
              for (std::size_t k = 0; k < patch.size() && okj; ++k) okj = bilinear(V.grey, V.cam.project(patch[k]), oth[k]);
              if (!okj) continue;
              sum += ncc(ref_c, oth);
              ++cnt;
            }
            return cnt >= o.min_views ? sum / static_cast<float>(cnt) : -1.f;
          };
          const TangentFrame mesh_frame(nn);
          for (int s = 0; s < S; ++s) score[s] = score_at(-o.search_range + s * step, mesh_frame);
          int best = static_cast<int>(std::max_element(score.begin(), score.end()) - score.begin());
          if (best == 0 || best == S - 1 || score[best] < o.min_ncc) continue;  // no interior maximum
          float rest = -1.f;
          for (int s = 0; s < S; ++s)
            if (std::abs(s - best) > 2) rest = std::max(rest, score[s]);
          if (score[best] - rest < o.distinct_margin) continue;  // not distinct
          // Patch orientation: the mesh normal tilted by normal_tilt_deg in 8 directions when
          // that correlates better at the maximum (a fold the mesh does not have yet); then the
          // depth again around the maximum with the chosen normal.
          TangentFrame best_frame = mesh_frame;
          if (o.normal_tilt_deg > 0) {
            const double tb = -o.search_range + best * step, ta = std::tan(o.normal_tilt_deg * M_PI / 180.0);
            float sbest = score[best];
            for (int dir = 0; dir < 8; ++dir) {
              const double phi = dir * M_PI / 4;
              const TangentFrame cand((nn + ta * (std::cos(phi) * mesh_frame.u + std::sin(phi) * mesh_frame.v)).normalized());
              if (cand.n.dot((cam.center() - cam.backProject(Eigen::Vector2d(x, y), d0 + tb)).normalized()) < cos_max) continue;
              const float sc = score_at(tb, cand);
              if (sc > sbest) {
                sbest = sc;
                best_frame = cand;
              }
            }
            if (best_frame.n != nn)
              for (int s = std::max(0, best - 2); s <= std::min(S - 1, best + 2); ++s) score[s] = score_at(-o.search_range + s * step, best_frame);
            best = static_cast<int>(std::max_element(score.begin() + std::max(0, best - 2), score.begin() + std::min(S, best + 3)) - score.begin());
            if (best == 0 || best == S - 1 || score[best] < o.min_ncc) continue;
          }
          const double sa = score[best - 1], sb = score[best], sc = score[best + 1];
          const double den = sa - 2 * sb + sc;
          const double off = den < 0 ? std::clamp(0.5 * (sa - sc) / den, -0.5, 0.5) : 0.0;
          const double t = -o.search_range + (best + off) * step;
          pts[i].push_back(cam.backProject(Eigen::Vector2d(x, y), d0 + t));
          nrm[i].push_back(best_frame.n);
          scores[i].push_back(static_cast<float>(sb));
          grid[i].at<float>(y / o.pixel_stride, x / o.pixel_stride) = static_cast<float>(d0 + t);
        }
#pragma omp critical(tbsp_mvs_progress)
      {
        ++done;
        if (!err) report_progress(progress, 0.8 * done / n, "photo-consistency");
      }
    } catch (...) {
#pragma omp critical(tbsp_mvs_progress)
      if (!err) err = std::current_exception();
    }
  }
  if (err) std::rethrow_exception(err);
  // Cross-view consistency: a depth is kept when another view's search found the same surface
  // (its accepted depth near the point's projection, within two depth steps). A maximum of one
  // view alone is often a match on the wrong surface (a hidden leg behind a skirt).
  ModelGuidedStereoReport rep;
  if (o.min_agreeing_views > 0) {
    const double tol = 2 * step;
    std::vector<std::vector<Eigen::Vector3d>> kp(n), kn(n);
    std::vector<std::vector<float>> ks(n);
#pragma omp parallel for schedule(dynamic, 1)
    for (int i = 0; i < n; ++i)
      for (std::size_t k = 0; k < pts[i].size(); ++k) {
        const Eigen::Vector3d& X = pts[i][k];
        int agree = 0;
        for (int j = 0; j < n && agree < o.min_agreeing_views; ++j) {
          if (j == i) continue;
          const Camera& cj = views[j].cam;
          const double z = cj.depth(X);
          if (!(z > 0)) continue;
          const Eigen::Vector2d q = cj.project(X);
          if (!cj.inImage(q)) continue;
          const int gx = static_cast<int>(std::lround(q.x() / o.pixel_stride)), gy = static_cast<int>(std::lround(q.y() / o.pixel_stride));
          bool ok = false;
          for (int dy = -1; dy <= 1 && !ok; ++dy)
            for (int dx = -1; dx <= 1 && !ok; ++dx) {
              const int a = gx + dx, b = gy + dy;
              if (a < 0 || b < 0 || a >= grid[j].cols || b >= grid[j].rows) continue;
              const float zj = grid[j].at<float>(b, a);
              ok = !std::isnan(zj) && std::abs(zj - z) <= tol;
            }
          agree += ok;
        }
        if (agree < o.min_agreeing_views) continue;
        kp[i].push_back(X);
        kn[i].push_back(nrm[i][k]);
        ks[i].push_back(scores[i][k]);
      }
    pts.swap(kp);
    nrm.swap(kn);
    scores.swap(ks);
  }
  for (int i = 0; i < n; ++i)
    for (float v : scores[i]) score_sum[i] += v;
  rep.views = n;
  long total = 0;
  double ssum = 0;
  for (int i = 0; i < n; ++i) {
    rep.samples_per_view.push_back(samples[i]);
    rep.points_per_view.push_back(static_cast<int>(pts[i].size()));
    rep.samples += samples[i];
    total += static_cast<long>(pts[i].size());
    ssum += score_sum[i];
  }
  rep.points = total;
  rep.mean_score = total ? ssum / total : 0.0;
  Eigen::MatrixX3d P(total, 3), N(total, 3);
  long r = 0;
  for (int i = 0; i < n; ++i)
    for (std::size_t k = 0; k < pts[i].size(); ++k, ++r) {
      P.row(r) = pts[i][k].transpose();
      N.row(r) = nrm[i][k].transpose();
    }
  rep.seconds_stereo = seconds_since(t0);
  rep.seconds_total = rep.seconds_stereo;
  report_ = rep;
  points.swap(P);
  normals.swap(N);
}

FitReport refine_mesh_to_cloud(const TriMesh& mesh, const Eigen::MatrixX3d& points, const Eigen::MatrixX3d& normals,
                               const ModelGuidedStereoOptions& o, TriMesh& refined, const ProgressCallback& progress) {
  if (points.rows() == 0) throw InvalidInput("[tbsp::refine_mesh_to_cloud] the cloud is empty: no constraint to refine with");
  std::string why;
  if (!o.isValid(&why)) throw InvalidInput("[tbsp::refine_mesh_to_cloud] " + why);
  FitParameters p;
  p.match_weight = o.constraint_weight;
  p.max_match_distance = o.search_range;
  p.initial_match_distance = o.search_range;
  p.detail_rounds = o.detail_rounds;
  p.estimate_scale = false;
  p.rotation_field = false;
  p.auto_markers = 0;
  p.align_without_markers = false;  // the mesh is posed already
  p.max_iterations = o.fit_iterations;
  TriMesh out;
  std::vector<VertexStatus> status;
  const FitReport r = fit_template(mesh, points, normals, {}, {}, p, out, status, progress, false);
  refined = std::move(out);
  return r;
}

void ModelGuidedStereo::refine(TriMesh& refined) {
  const auto t0 = Clock::now();
  Eigen::MatrixX3d P, N;
  computeCloud(P, N, [&](double f, const std::string& s) { return !progress_ || progress_(0.8 * f, s); });
  if (P.rows() == 0)
    throw InvalidInput("[tbsp::ModelGuidedStereo] frame " + std::to_string(frame_) +
                       ": no pixel found a distinct, confirmed photo-consistency maximum (textureless images, or the mesh is not where the subject is)");
  ModelGuidedStereoReport rep = report_;
  const auto tf = Clock::now();
  TriMesh out;
  rep.fit = refine_mesh_to_cloud(mesh_, P, N, options_, out,
                                 [&](double f, const std::string& s) { return !progress_ || progress_(0.8 + 0.2 * f, "fit: " + s); });
  rep.seconds_fit = seconds_since(tf);
  const Eigen::VectorXd mv = (out.V - mesh_.V).rowwise().norm();
  rep.mean_vertex_move = mv.mean();
  rep.max_vertex_move = mv.maxCoeff();
  rep.seconds_total = seconds_since(t0);
  report_ = rep;
  refined = std::move(out);
}

}  // namespace tbsp
