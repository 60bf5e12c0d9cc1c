#include "stereo_pairs.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include <opencv2/calib3d.hpp>
#include <opencv2/core/eigen.hpp>
#include <opencv2/features2d.hpp>
#include <opencv2/imgproc.hpp>

#include "tbsp/core/error.h"
#include "tbsp/core/timer.h"

namespace tbsp::stereo_detail {

namespace {

constexpr float kNoDisparity = std::numeric_limits<float>::quiet_NaN();

cv::Mat to_cv(const Eigen::Matrix3d& m) {
  cv::Mat r;
  cv::eigen2cv(m, r);
  return r;
}
cv::Mat dist_cv(const Distortion& d) { return (cv::Mat_<double>(1, 5) << d.k1, d.k2, d.p1, d.p2, d.k3); }

// The canonical orientation of a rectified pair: transposed (vertical baseline) and/or mirrored
// (reference camera on the right), so that the reference is the left image of a standard pair.
struct Canon {
  bool transpose = false, flip = false;
  cv::Mat apply(const cv::Mat& m) const {
    cv::Mat r = m;
    if (transpose) cv::transpose(r, r);
    if (flip) cv::flip(r, r, 1);
    return r;
  }
  // rectified (u, v) -> canonical (x, y) for an image of canonical width cw.
  cv::Point2f toCanon(cv::Point2f p, int cw) const {
    if (transpose) std::swap(p.x, p.y);
    if (flip) p.x = static_cast<float>(cw - 1) - p.x;
    return p;
  }
};

// Disparity range from sparse ORB matches between the canonical images. Returns false when
// there are too few matches (the views do not overlap).
bool sparse_disparity_range(const cv::Mat& L, const cv::Mat& R, const cv::Mat& mL, const cv::Mat& mR, int& dmin, int& dmax,
                            int& matches) {
  cv::Mat gl = L, gr = R;
  if (L.channels() == 3) {
    cv::cvtColor(L, gl, cv::COLOR_BGR2GRAY);
    cv::cvtColor(R, gr, cv::COLOR_BGR2GRAY);
  }
  auto orb = cv::ORB::create(3000);
  std::vector<cv::KeyPoint> kl, kr;
  cv::Mat dl, dr;
  orb->detectAndCompute(gl, mL, kl, dl);
  orb->detectAndCompute(gr, mR, kr, dr);
  matches = 0;
  if (kl.empty() || kr.empty()) return false;
  cv::BFMatcher bf(cv::NORM_HAMMING, /*crossCheck*/ true);
  std::vector<cv::DMatch> m;
  bf.match(dl, dr, m);
  std::vector<float> d;
  for (const auto& x : m) {
    const cv::Point2f a = kl[x.queryIdx].pt, b = kr[x.trainIdx].pt;
    if (std::abs(a.y - b.y) <= 1.5f && x.distance < 64) d.push_back(a.x - b.x);
  }
  matches = static_cast<int>(d.size());
  if (d.size() < 12) return false;
  std::sort(d.begin(), d.end());
  const float lo = d[d.size() * 2 / 100], hi = d[std::min(d.size() - 1, d.size() * 98 / 100)];
  const float margin = 0.15f * (hi - lo) + 6.0f;
  dmin = static_cast<int>(std::floor(lo - margin));
  dmax = static_cast<int>(std::ceil(hi + margin));
  return true;
}

}  // namespace

std::vector<std::pair<int, int>> select_pairs(const std::vector<Camera>& cameras, const StereoFusionOptions& o) {
  const int n = static_cast<int>(cameras.size());
  std::vector<std::pair<int, int>> pairs;
  const double lo = o.min_pair_angle_deg * M_PI / 180.0, hi = o.max_pair_angle_deg * M_PI / 180.0;
  for (int i = 0; i < n; ++i) {
    std::vector<std::pair<double, int>> cand;
    for (int j = 0; j < n; ++j) {
      if (j == i) continue;
      const double c = std::clamp(cameras[i].viewDirection().dot(cameras[j].viewDirection()), -1.0, 1.0);
      const double a = std::acos(c);
      if (a >= lo && a <= hi && (cameras[i].center() - cameras[j].center()).norm() > 0) cand.push_back({a, j});
    }
    std::sort(cand.begin(), cand.end());
    for (int k = 0; k < std::min<int>(o.partners, static_cast<int>(cand.size())); ++k)
      pairs.push_back({std::min(i, cand[k].second), std::max(i, cand[k].second)});
  }
  std::sort(pairs.begin(), pairs.end());
  pairs.erase(std::unique(pairs.begin(), pairs.end()), pairs.end());
  return pairs;
}

PairDepth match_pair(const Camera& ci, const Camera& cj, int i, int j, const cv::Mat& img_i, const cv::Mat& img_j,
                     const cv::Mat& sil_i, const cv::Mat& sil_j, const StereoFusionOptions& o) {
  PairDepth out;
  const auto t0 = Clock::now();
  const double s = o.image_scale;
  const cv::Size full(ci.width(), ci.height());
  const cv::Size work(std::max(16, static_cast<int>(std::lround(ci.width() * s))), std::max(16, static_cast<int>(std::lround(ci.height() * s))));
  const Eigen::Matrix3d Rrel = cj.R() * ci.R().transpose();
  const Eigen::Vector3d Trel = cj.t() - Rrel * ci.t();
  cv::Mat K1 = to_cv(ci.K()), K2 = to_cv(cj.K()), D1 = dist_cv(ci.distortion()), D2 = dist_cv(cj.distortion());
  cv::Mat R = to_cv(Rrel), T = (cv::Mat_<double>(3, 1) << Trel.x(), Trel.y(), Trel.z());
  cv::Mat R1, R2, P1, P2, Q;
  cv::stereoRectify(K1, D1, K2, D2, full, R, T, R1, R2, P1, P2, Q, cv::CALIB_ZERO_DISPARITY, -1, work);
  const bool horizontal = std::abs(P2.at<double>(0, 3)) >= std::abs(P2.at<double>(1, 3));
  const double tsign = horizontal ? P2.at<double>(0, 3) : P2.at<double>(1, 3);
  const double f = P1.at<double>(0, 0);
  const double fB = std::abs(tsign);  // f * baseline (rectified pixels * world units)
  if (!(f > 0) || !(fB > 0) || !std::isfinite(fB)) {
    out.skipped = "rectification failed (degenerate baseline)";
    return out;
  }
  Canon canon;
  canon.transpose = !horizontal;
  canon.flip = tsign > 0;
  // Verging cameras: OpenCV's common principal point (CALIB_ZERO_DISPARITY) can push the
  // subject out of one rectified image. Re-centre each image on the subject (the silhouette
  // centroid, else the image centre) along the baseline axis; the other axis keeps one common
  // value (rows must stay aligned). The disparity offset this adds is `doffs` below.
  {
    auto subject = [&](const Camera& cam, const cv::Mat& sil) {
      cv::Point2f c(static_cast<float>(cam.width() - 1) / 2, static_cast<float>(cam.height() - 1) / 2);
      if (!sil.empty()) {
        const cv::Moments mo = cv::moments(sil >= 128, true);
        if (mo.m00 > 0) c = cv::Point2f(static_cast<float>(mo.m10 / mo.m00), static_cast<float>(mo.m01 / mo.m00));
      }
      return c;
    };
    std::vector<cv::Point2f> a{subject(ci, sil_i)}, b{subject(cj, sil_j)}, ra, rb;
    cv::undistortPoints(a, ra, K1, D1, R1, P1);
    cv::undistortPoints(b, rb, K2, D2, R2, P2);
    const int along = horizontal ? 0 : 1, across = 1 - along;
    const double half_along = ((horizontal ? work.width : work.height) - 1) / 2.0;
    const double half_across = ((horizontal ? work.height : work.width) - 1) / 2.0;
    const double ra_along = horizontal ? ra[0].x : ra[0].y, rb_along = horizontal ? rb[0].x : rb[0].y;
    const double ra_across = horizontal ? ra[0].y : ra[0].x, rb_across = horizontal ? rb[0].y : rb[0].x;
    P1.at<double>(along, 2) += half_along - ra_along;
    P2.at<double>(along, 2) += half_along - rb_along;
    const double shift = half_across - 0.5 * (ra_across + rb_across);
    P1.at<double>(across, 2) += shift;
    P2.at<double>(across, 2) += shift;
    // P2's translation column holds f * T (unchanged by principal-point shifts of a rectified pair).
  }
  const int ax = horizontal ? 0 : 1;
  const double doffs = canon.flip ? P2.at<double>(ax, 2) - P1.at<double>(ax, 2) : P1.at<double>(ax, 2) - P2.at<double>(ax, 2);

  cv::Mat m1x, m1y, m2x, m2y;
  cv::initUndistortRectifyMap(K1, D1, R1, P1, work, CV_32FC1, m1x, m1y);
  cv::initUndistortRectifyMap(K2, D2, R2, P2, work, CV_32FC1, m2x, m2y);
  cv::Mat ri, rj, si, sj;
  cv::remap(img_i, ri, m1x, m1y, cv::INTER_LINEAR, cv::BORDER_CONSTANT);
  cv::remap(img_j, rj, m2x, m2y, cv::INTER_LINEAR, cv::BORDER_CONSTANT);
  if (!sil_i.empty()) cv::remap(sil_i, si, m1x, m1y, cv::INTER_NEAREST, cv::BORDER_CONSTANT);
  if (!sil_j.empty()) cv::remap(sil_j, sj, m2x, m2y, cv::INTER_NEAREST, cv::BORDER_CONSTANT);
  const cv::Mat L = canon.apply(ri), Rr = canon.apply(rj);
  const cv::Mat mL = si.empty() ? cv::Mat() : canon.apply(si), mR = sj.empty() ? cv::Mat() : canon.apply(sj);
  out.seconds_rectify = seconds_since(t0);

  // Disparity range.
  int dmin = 0, dmax = 0;
  if (o.near > 0 && o.far > o.near) {
    dmin = static_cast<int>(std::floor(fB / o.far + doffs)) - 2;
    dmax = static_cast<int>(std::ceil(fB / o.near + doffs)) + 2;
  } else {
    int nm = 0;
    if (!sparse_disparity_range(L, Rr, mL, mR, dmin, dmax, nm)) {
      out.skipped = "the views do not overlap (" + std::to_string(nm) +
                    " sparse matches after rectification; need 12): choose other partners or give near/far";
      return out;
    }
  }
  int num = ((dmax - dmin + 15) / 16) * 16;
  if (num > o.max_disparities) {
    const int mid = (dmin + dmax) / 2;
    num = (o.max_disparities / 16) * 16;
    dmin = mid - num / 2;
  }
  if (num < 16) num = 16;
  StereoMatchOptions mo = o.match;
  mo.min_disparity = dmin;
  mo.num_disparities = num;
  mo.fill_invalid = false;
  mo.left_right_check = true;
  const auto t1 = Clock::now();
  const DisparityMap dm = compute_disparity(L, Rr, mo);
  cv::Mat dL = dm.disparity.clone(), dR = dm.right_disparity.clone();
  if (!mL.empty()) dL.setTo(kNoDisparity, mL < 128);
  if (!mR.empty()) dR.setTo(kNoDisparity, mR < 128);
  out.seconds_match = seconds_since(t1);

  // Depth maps in each camera's own grid (at scale s): inverse lookup through the rectification.
  auto depth_map = [&](const Camera& cam, const cv::Mat& K, const cv::Mat& D, const cv::Mat& Rr_, const cv::Mat& P,
                       const cv::Mat& disp, int self, int other) {
    ViewDepth v;
    v.camera = self;
    v.partner = other;
    v.scale = s;
    v.disparity_min = dmin;
    v.disparity_count = num;
    const int w = std::max(1, static_cast<int>(std::lround(cam.width() * s))), h = std::max(1, static_cast<int>(std::lround(cam.height() * s)));
    v.depth = cv::Mat(h, w, CV_32F, cv::Scalar(kNoDisparity));
    std::vector<cv::Point2f> px;
    px.reserve(static_cast<std::size_t>(w) * h);
    const double sx = static_cast<double>(w) / cam.width(), sy = static_cast<double>(h) / cam.height();
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x) px.emplace_back(static_cast<float>((x + 0.5) / sx - 0.5), static_cast<float>((y + 0.5) / sy - 0.5));
    std::vector<cv::Point2f> rect;
    cv::undistortPoints(px, rect, K, D, Rr_, P);
    const double cx = P.at<double>(0, 2), cy = P.at<double>(1, 2);
    cv::Matx33d Rt;
    for (int a = 0; a < 3; ++a)
      for (int b = 0; b < 3; ++b) Rt(a, b) = Rr_.at<double>(b, a);
    const int cw = disp.cols;
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x) {
        const cv::Point2f r = rect[static_cast<std::size_t>(y) * w + x];
        const cv::Point2f c = canon.toCanon(r, cw);
        const int xi = static_cast<int>(std::lround(c.x)), yi = static_cast<int>(std::lround(c.y));
        if (xi < 0 || yi < 0 || xi >= disp.cols || yi >= disp.rows) continue;
        const float d = disp.at<float>(yi, xi);
        if (!(d - doffs > 0)) continue;
        const double Z = fB / (d - doffs);
        const cv::Vec3d Xr(Z * (r.x - cx) / f, Z * (r.y - cy) / f, Z);
        const cv::Vec3d Xc = Rt * Xr;
        if (Xc[2] <= 0) continue;
        v.depth.at<float>(y, x) = static_cast<float>(Xc[2]);
        ++v.valid_pixels;
      }
    return v;
  };
  out.first = depth_map(ci, K1, D1, R1, P1, dL, i, j);
  out.second = depth_map(cj, K2, D2, R2, P2, dR, j, i);
  return out;
}

}  // namespace tbsp::stereo_detail
