#include "tbsp/multiview/stereo_depth_fusion.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include <opencv2/imgproc.hpp>
#include <pcl/common/io.h>
#include <pcl/filters/statistical_outlier_removal.h>

#include "stereo_pairs.h"
#include "tbsp/core/error.h"
#include "tbsp/core/timer.h"

namespace tbsp {

bool StereoFusionOptions::isValid(std::string* why) const {
  auto fail = [&](const std::string& m) {
    if (why) *why = m;
    return false;
  };
  StereoMatchOptions m = match;
  m.num_disparities = 16;  // set per pair
  std::string w;
  if (!m.isValid(&w)) return fail("match: " + w);
  if (partners < 1 || partners > 8) return fail("partners must be in 1..8");
  if (!(min_pair_angle_deg > 0) || !(max_pair_angle_deg > min_pair_angle_deg) || max_pair_angle_deg > 120)
    return fail("need 0 < min_pair_angle_deg < max_pair_angle_deg <= 120");
  if (!(image_scale > 0) || image_scale > 1) return fail("image_scale must be in (0, 1]");
  if (near < 0 || far < 0 || (far > 0 && !(far > near)) || (near > 0 && far == 0))
    return fail("near/far: both 0 (automatic) or 0 < near < far");
  if (max_disparities < 16 || max_disparities > 1024) return fail("max_disparities must be in 16..1024");
  if (min_agreeing_views < 1) return fail("min_agreeing_views must be >= 1");
  if (silhouette_margin_px < 0) return fail("silhouette_margin_px must be >= 0");
  if (!(depth_tolerance > 0) || depth_tolerance > 0.2) return fail("depth_tolerance must be in (0, 0.2]");
  if (outlier_neighbours < 0 || (outlier_neighbours > 0 && !(outlier_stddev > 0)))
    return fail("outlier_neighbours >= 0 and outlier_stddev > 0");
  return true;
}

void StereoFusionEngine::setOptions(const StereoFusionOptions& o) {
  std::string why;
  if (!o.isValid(&why)) throw InvalidInput("[tbsp::StereoDepthFusion::setOptions] " + why);
  options_ = o;
}

namespace {

constexpr float kNoDepth = std::numeric_limits<float>::quiet_NaN();

struct MapPoints {
  const ViewDepth* view = nullptr;
  int w = 0, h = 0;
  std::vector<Eigen::Vector3f> X;  // world point per pixel (NaN where none)
  std::vector<Eigen::Vector3f> N;  // normal per pixel (zero where none)
};

// Pixel of the depth map grid -> camera pixel coordinates.
inline Eigen::Vector2d grid_to_camera(const Camera& cam, const ViewDepth& v, int x, int y) {
  const double sx = static_cast<double>(v.depth.cols) / cam.width(), sy = static_cast<double>(v.depth.rows) / cam.height();
  return {(x + 0.5) / sx - 0.5, (y + 0.5) / sy - 0.5};
}

MapPoints back_project(const Camera& cam, const ViewDepth& v) {
  MapPoints m;
  m.view = &v;
  m.w = v.depth.cols;
  m.h = v.depth.rows;
  const std::size_t n = static_cast<std::size_t>(m.w) * m.h;
  m.X.assign(n, Eigen::Vector3f::Constant(kNoDepth));
  m.N.assign(n, Eigen::Vector3f::Zero());
  for (int y = 0; y < m.h; ++y)
    for (int x = 0; x < m.w; ++x) {
      const float z = v.depth.at<float>(y, x);
      if (std::isnan(z)) continue;
      m.X[static_cast<std::size_t>(y) * m.w + x] = cam.backProject(grid_to_camera(cam, v, x, y), z).cast<float>();
    }
  const Eigen::Vector3f C = cam.center().cast<float>();
  for (int y = 0; y < m.h; ++y)
    for (int x = 0; x < m.w; ++x) {
      const auto at = [&](int a, int b) -> const Eigen::Vector3f& { return m.X[static_cast<std::size_t>(b) * m.w + a]; };
      const Eigen::Vector3f& p = at(x, y);
      if (std::isnan(p.x())) continue;
      // Central differences where both neighbours exist, else one-sided.
      auto diff = [&](int dx, int dy) -> Eigen::Vector3f {
        const int xa = x - dx, ya = y - dy, xb = x + dx, yb = y + dy;
        const bool a = xa >= 0 && ya >= 0 && !std::isnan(at(xa, ya).x());
        const bool b = xb < m.w && yb < m.h && !std::isnan(at(xb, yb).x());
        if (a && b) return at(xb, yb) - at(xa, ya);
        if (b) return at(xb, yb) - p;
        if (a) return p - at(xa, ya);
        return Eigen::Vector3f::Constant(kNoDepth);
      };
      const Eigen::Vector3f du = diff(1, 0), dv = diff(0, 1);
      if (std::isnan(du.x()) || std::isnan(dv.x())) continue;
      Eigen::Vector3f nrm = du.cross(dv);
      const float len = nrm.norm();
      if (!(len > 0)) continue;
      nrm /= len;
      if (nrm.dot(C - p) < 0) nrm = -nrm;
      m.N[static_cast<std::size_t>(y) * m.w + x] = nrm;
    }
  return m;
}

// A world point seen from one camera: pixel and depth (ok = in front and inside the image).
struct Projection {
  bool ok = false;
  Eigen::Vector2d p;
  float z = 0;
};
inline Projection project_point(const Camera& cam, const Eigen::Vector3f& X) {
  Projection r;
  const Eigen::Vector3d Xd = X.cast<double>();
  const double z = cam.depth(Xd);
  if (!(z > 0)) return r;
  r.p = cam.project(Xd);
  r.z = static_cast<float>(z);
  r.ok = cam.inImage(r.p);
  return r;
}

// Where a projected point falls in one of the camera's depth maps: grid pixel and map depth.
inline bool lookup(const Camera& cam, const MapPoints& m, const Projection& pr, int& idx, float& z_map) {
  if (!pr.ok) return false;
  const double sx = static_cast<double>(m.w) / cam.width(), sy = static_cast<double>(m.h) / cam.height();
  const int x = static_cast<int>(std::floor((pr.p.x() + 0.5) * sx)), y = static_cast<int>(std::floor((pr.p.y() + 0.5) * sy));
  if (x < 0 || y < 0 || x >= m.w || y >= m.h) return false;
  idx = y * m.w + x;
  z_map = m.view->depth.at<float>(y, x);
  return true;
}

cv::Vec3f sample_bgr(const cv::Mat& img, const Eigen::Vector2d& p) {
  if (img.empty()) return {128, 128, 128};
  const int x = std::clamp(static_cast<int>(std::lround(p.x())), 0, img.cols - 1);
  const int y = std::clamp(static_cast<int>(std::lround(p.y())), 0, img.rows - 1);
  if (img.channels() == 1) {
    const float g = img.at<std::uint8_t>(y, x);
    return {g, g, g};
  }
  const cv::Vec3b c = img.at<cv::Vec3b>(y, x);
  return {static_cast<float>(c[0]), static_cast<float>(c[1]), static_cast<float>(c[2])};
}

}  // namespace

void StereoFusionEngine::compute(const std::vector<Camera>& cameras, const std::vector<cv::Mat>& images,
                                 const std::vector<cv::Mat>& silhouettes, pcl::PointCloud<pcl::PointXYZRGBNormal>& cloud,
                                 std::vector<float>& confidence, int frame) {
  const auto t0 = Clock::now();
  const std::string where = "[tbsp::StereoDepthFusion::compute] frame " + std::to_string(frame) + ": ";
  const int n = static_cast<int>(cameras.size());
  if (n < 2) throw InvalidInput(where + "needs at least 2 calibrated views, got " + std::to_string(n));
  if (static_cast<int>(images.size()) != n)
    throw InvalidInput(where + std::to_string(images.size()) + " images for " + std::to_string(n) + " cameras: give one image per camera");
  if (!silhouettes.empty() && static_cast<int>(silhouettes.size()) != n)
    throw InvalidInput(where + std::to_string(silhouettes.size()) + " silhouettes for " + std::to_string(n) + " cameras");
  const bool use_sil = options_.use_silhouettes && !silhouettes.empty();
  for (int k = 0; k < n; ++k) {
    const Camera& c = cameras[k];
    const cv::Mat& im = images[k];
    if (im.empty()) throw InvalidInput(where + "camera '" + c.name() + "' has no image");
    if (im.cols != c.width() || im.rows != c.height())
      throw InvalidInput(where + "camera '" + c.name() + "': image is " + std::to_string(im.cols) + "x" + std::to_string(im.rows) +
                         " but the calibration says " + std::to_string(c.width()) + "x" + std::to_string(c.height()) +
                         ": use the images the calibration was made for (or rescale K)");
    if (im.depth() != CV_8U || (im.channels() != 1 && im.channels() != 3))
      throw InvalidInput(where + "camera '" + c.name() + "': images must be 8-bit grey or BGR");
    if (use_sil && !silhouettes[k].empty()) {
      const cv::Mat& s = silhouettes[k];
      if (s.size() != im.size() || s.type() != CV_8U)
        throw InvalidInput(where + "camera '" + c.name() + "': the silhouette must be 8-bit and the image size");
      if (cv::countNonZero(s >= 128) == 0)
        throw InvalidInput(where + "camera '" + c.name() + "': the silhouette is empty (no foreground pixel): fix the mask or run without silhouettes");
    }
  }
  StereoFusionReport rep;
  rep.views = n;
  report_progress(progress_, 0.0, "pairs");
  const auto pairs = stereo_detail::select_pairs(cameras, options_);
  if (pairs.empty())
    throw InvalidInput(where + "no camera pair has viewing directions within " + std::to_string(options_.min_pair_angle_deg) + ".." +
                       std::to_string(options_.max_pair_angle_deg) + " degrees: the views do not overlap (widen max_pair_angle_deg)");

  // Pairs in parallel; results stored by pair index (deterministic order).
  std::vector<stereo_detail::PairDepth> pd(pairs.size());
  std::exception_ptr err;
  int done = 0;
#pragma omp parallel for schedule(dynamic, 1)
  for (int p = 0; p < static_cast<int>(pairs.size()); ++p) {
    try {
      const auto [i, j] = pairs[p];
      const cv::Mat none;
      pd[p] = stereo_detail::match_pair(cameras[i], cameras[j], i, j, images[i], images[j], use_sil ? silhouettes[i] : none,
                                        use_sil ? silhouettes[j] : none, options_);
#pragma omp critical(tbsp_stereo_progress)
      {
        ++done;
        if (!err) report_progress(progress_, 0.7 * done / static_cast<double>(pairs.size()), "depth maps");
      }
    } catch (...) {
#pragma omp critical(tbsp_stereo_progress)
      if (!err) err = std::current_exception();
    }
  }
  if (err) std::rethrow_exception(err);

  std::vector<ViewDepth> maps;
  for (std::size_t p = 0; p < pairs.size(); ++p) {
    const std::string name = cameras[pairs[p].first].name() + "-" + cameras[pairs[p].second].name();
    rep.seconds_rectify += pd[p].seconds_rectify;
    rep.seconds_match += pd[p].seconds_match;
    if (!pd[p].skipped.empty()) {
      rep.skipped_pairs.push_back(name + ": " + pd[p].skipped);
      continue;
    }
    rep.pair_names.push_back(name);
    maps.push_back(std::move(pd[p].first));
    maps.push_back(std::move(pd[p].second));
  }
  rep.pairs = static_cast<int>(rep.pair_names.size());
  if (maps.empty())
    throw InvalidInput(where + "no pair produced depth (" + (rep.skipped_pairs.empty() ? std::string("?") : rep.skipped_pairs.front()) +
                       "): the views do not overlap enough; give near/far or other cameras");

  // Fusion.
  const auto tf = Clock::now();
  report_progress(progress_, 0.75, "fusion");
  const int M = static_cast<int>(maps.size());
  std::vector<MapPoints> mp(M);
#pragma omp parallel for schedule(dynamic, 1)
  for (int m = 0; m < M; ++m) mp[m] = back_project(cameras[maps[m].camera], maps[m]);
  for (const auto& m : maps) rep.depth_points += m.valid_pixels;

  const float tol = static_cast<float>(options_.depth_tolerance);
  // Visual-hull test: a point must project inside (or within the margin of) every silhouette
  // of a camera it falls into. Distance-to-foreground maps make the margin a lookup.
  std::vector<cv::Mat> sil_dist(n);
  if (use_sil)
    for (int k = 0; k < n; ++k)
      if (!silhouettes[k].empty()) cv::distanceTransform(silhouettes[k] < 128, sil_dist[k], cv::DIST_L2, 3);
  auto inside_silhouettes = [&](const Eigen::Vector3f& X) {
    for (int k = 0; k < n; ++k) {
      if (sil_dist[k].empty()) continue;
      const Eigen::Vector2d p = cameras[k].project(X.cast<double>());
      if (!cameras[k].inImage(p)) continue;
      const int x = std::clamp(static_cast<int>(std::lround(p.x())), 0, sil_dist[k].cols - 1);
      const int y = std::clamp(static_cast<int>(std::lround(p.y())), 0, sil_dist[k].rows - 1);
      if (sil_dist[k].at<float>(y, x) > options_.silhouette_margin_px) return false;
    }
    return true;
  };
  // The two maps of one pair come from one (left-right checked) match: they always agree, so
  // they are not evidence for each other. Agreement counts maps of other pairs only.
  auto same_pair = [&](int a, int b) { return maps[a].camera == maps[b].partner && maps[a].partner == maps[b].camera; };
  // Phase 1 (parallel, read-only): agreeing cameras per pixel.
  std::vector<std::vector<std::uint8_t>> agree(M);
  for (int m = 0; m < M; ++m) agree[m].assign(mp[m].X.size(), 0);
#pragma omp parallel for schedule(dynamic, 1)
  for (int m = 0; m < M; ++m) {
    const int cam = maps[m].camera;
    std::vector<char> seen(n), projected(n);
    std::vector<Projection> proj(n);
    for (std::size_t q = 0; q < mp[m].X.size(); ++q) {
      const Eigen::Vector3f& X = mp[m].X[q];
      if (std::isnan(X.x())) continue;
      std::fill(seen.begin(), seen.end(), 0);
      std::fill(projected.begin(), projected.end(), 0);
      int count = 0;
      for (int o = 0; o < M; ++o) {
        const int k = maps[o].camera;
        if (k == cam || seen[k] || same_pair(m, o)) continue;
        if (!projected[k]) {  // once per camera, whatever the number of its maps
          proj[k] = project_point(cameras[k], X);
          projected[k] = 1;
        }
        int idx;
        float zm;
        if (!lookup(cameras[k], mp[o], proj[k], idx, zm) || std::isnan(zm)) continue;
        const float zp = proj[k].z;
        if (std::abs(zm - zp) <= tol * zp) {
          seen[k] = 1;
          ++count;
        }
      }
      if (count > 0 && use_sil && !inside_silhouettes(X)) count = 0;
      agree[m][q] = static_cast<std::uint8_t>(std::min(count, 255));
    }
  }
  // Phase 2 (serial, map order): merge each consistent pixel with its agreeing pixels and
  // consume them, so a surface patch seen by several maps makes one point.
  std::vector<std::vector<char>> used(M);
  for (int m = 0; m < M; ++m) used[m].assign(mp[m].X.size(), 0);
  pcl::PointCloud<pcl::PointXYZRGBNormal> fused;
  std::vector<float> conf;
  for (int m = 0; m < M; ++m) {
    const int cam = maps[m].camera;
    for (std::size_t q = 0; q < mp[m].X.size(); ++q) {
      if (used[m][q] || agree[m][q] < options_.min_agreeing_views) continue;
      ++rep.consistent_points;
      const Eigen::Vector3f X = mp[m].X[q];
      Eigen::Vector3f sumX = X, sumN = mp[m].N[q];
      const int qx = static_cast<int>(q % mp[m].w), qy = static_cast<int>(q / mp[m].w);
      cv::Vec3f sumC = sample_bgr(images[cam], grid_to_camera(cameras[cam], maps[m], qx, qy));
      int cnt = 1;
      used[m][q] = 1;
      std::vector<char> agreeing(n, 0), seeing(n, 0);
      std::vector<Projection> proj(n);
      for (int k = 0; k < n; ++k)
        if (k != cam) proj[k] = project_point(cameras[k], X);
      for (int o = 0; o < M; ++o) {
        const int k = maps[o].camera;
        int idx;
        float zm;
        if (k == cam || !lookup(cameras[k], mp[o], proj[k], idx, zm)) continue;
        const float zp = proj[k].z;
        seeing[k] = 1;
        if (std::isnan(zm) || std::abs(zm - zp) > tol * zp) continue;
        if (!same_pair(m, o)) agreeing[k] = 1;
        if (used[o][idx]) continue;
        used[o][idx] = 1;
        sumX += mp[o].X[idx];
        sumN += mp[o].N[idx];
        sumC += sample_bgr(images[k], proj[k].p);
        ++cnt;
      }
      int na = 0, ns = 0;
      for (int k = 0; k < n; ++k) {
        na += agreeing[k];
        ns += seeing[k];
      }
      pcl::PointXYZRGBNormal pt;
      const Eigen::Vector3f P = sumX / static_cast<float>(cnt);
      pt.x = P.x();
      pt.y = P.y();
      pt.z = P.z();
      Eigen::Vector3f N = sumN;
      if (N.norm() > 0) N.normalize();
      pt.normal_x = N.x();
      pt.normal_y = N.y();
      pt.normal_z = N.z();
      pt.curvature = 0;
      const cv::Vec3f c = sumC / static_cast<float>(cnt);
      pt.b = static_cast<std::uint8_t>(std::lround(std::clamp(c[0], 0.f, 255.f)));
      pt.g = static_cast<std::uint8_t>(std::lround(std::clamp(c[1], 0.f, 255.f)));
      pt.r = static_cast<std::uint8_t>(std::lround(std::clamp(c[2], 0.f, 255.f)));
      pt.a = 255;
      fused.push_back(pt);
      conf.push_back(ns > 0 ? static_cast<float>(na) / static_cast<float>(ns) : 0.f);
    }
  }
  rep.fused_points = static_cast<long>(fused.size());
  rep.seconds_fusion = seconds_since(tf);

  // Outliers.
  report_progress(progress_, 0.9, "outliers");
  const auto to = Clock::now();
  if (options_.outlier_neighbours > 0 && static_cast<int>(fused.size()) > options_.outlier_neighbours) {
    pcl::StatisticalOutlierRemoval<pcl::PointXYZRGBNormal> sor;
    auto in = fused.makeShared();
    sor.setInputCloud(in);
    sor.setMeanK(options_.outlier_neighbours);
    sor.setStddevMulThresh(options_.outlier_stddev);
    pcl::Indices keep;
    sor.filter(keep);
    std::sort(keep.begin(), keep.end());
    pcl::PointCloud<pcl::PointXYZRGBNormal> kept;
    std::vector<float> kc;
    kept.reserve(keep.size());
    kc.reserve(keep.size());
    for (const auto i : keep) {
      kept.push_back(fused[i]);
      kc.push_back(conf[i]);
    }
    fused.swap(kept);
    conf.swap(kc);
  }
  rep.seconds_outliers = seconds_since(to);
  rep.output_points = static_cast<long>(fused.size());
  fused.width = static_cast<std::uint32_t>(fused.size());
  fused.height = 1;
  fused.is_dense = true;
  rep.seconds_total = seconds_since(t0);
  report_progress(progress_, 1.0, "done");
  cloud.swap(fused);
  confidence.swap(conf);
  depth_ = std::move(maps);
  report_ = rep;
}

template <typename PointT>
void StereoDepthFusion<PointT>::compute(pcl::PointCloud<PointT>& output) {
  pcl::PointCloud<pcl::PointXYZRGBNormal> c;
  std::vector<float> conf;
  engine_.compute(cameras_, images_, silhouettes_, c, conf, frame_);
  pcl::PointCloud<PointT> out;
  pcl::copyPointCloud(c, out);
  output.swap(out);
  confidence_.swap(conf);
}

template class StereoDepthFusion<pcl::PointXYZ>;
template class StereoDepthFusion<pcl::PointNormal>;
template class StereoDepthFusion<pcl::PointXYZRGB>;
template class StereoDepthFusion<pcl::PointXYZRGBNormal>;

}  // namespace tbsp
