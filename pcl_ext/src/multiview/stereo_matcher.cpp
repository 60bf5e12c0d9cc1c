#include "tbsp/multiview/stereo_matcher.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <utility>
#include <vector>

#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

#include "tbsp/core/error.h"
#include "tbsp/core/timer.h"

namespace tbsp {

bool StereoMatchOptions::isValid(std::string* why) const {
  auto fail = [&](const std::string& m) {
    if (why) *why = m;
    return false;
  };
  if (num_disparities <= 0 || num_disparities % 16 != 0)
    return fail("num_disparities = " + std::to_string(num_disparities) + " must be a positive multiple of 16");
  if (block_size < 1 || block_size > 11 || block_size % 2 == 0)
    return fail("block_size = " + std::to_string(block_size) + " must be odd and in 1..11");
  if (!(p1_factor > 0) || !(p2_factor > p1_factor) || !std::isfinite(p2_factor))
    return fail("need 0 < p1_factor < p2_factor (finite); got " + std::to_string(p1_factor) + ", " + std::to_string(p2_factor));
  if (uniqueness_ratio < 0 || uniqueness_ratio > 100) return fail("uniqueness_ratio must be in 0..100");
  if (!(lr_tolerance > 0) || !std::isfinite(lr_tolerance)) return fail("lr_tolerance must be > 0 pixels");
  if (speckle_window < 0 || speckle_range < 0) return fail("speckle_window and speckle_range must be >= 0");
  if (median_radius < 0 || median_radius > 25) return fail("median_radius must be in 0..25");
  return true;
}

namespace {

constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();

// One SGBM pass with `left` as reference; returns CV_32F disparities, NaN where SGBM gave none.
cv::Mat sgbm_pass(const cv::Mat& left, const cv::Mat& right, const StereoMatchOptions& o) {
  const int channels = left.channels();
  const int bs2 = o.block_size * o.block_size;
  auto sgbm = cv::StereoSGBM::create(o.min_disparity, o.num_disparities, o.block_size,
                                     static_cast<int>(std::lround(o.p1_factor * channels * bs2)),
                                     static_cast<int>(std::lround(o.p2_factor * channels * bs2)),
                                     /*disp12MaxDiff*/ -1, /*preFilterCap*/ 63, o.uniqueness_ratio, o.speckle_window,
                                     o.speckle_range, o.full_dp ? cv::StereoSGBM::MODE_HH : cv::StereoSGBM::MODE_SGBM_3WAY);
  // Pad on the left so that columns x < min_disparity + num_disparities can be searched.
  const int pad = o.pad_border ? std::max(0, o.min_disparity + o.num_disparities) : 0;
  cv::Mat L = left, R = right;
  if (pad > 0) {
    cv::copyMakeBorder(left, L, 0, 0, pad, 0, cv::BORDER_REPLICATE);
    cv::copyMakeBorder(right, R, 0, 0, pad, 0, cv::BORDER_REPLICATE);
  }
  cv::Mat d16;
  sgbm->compute(L, R, d16);
  if (pad > 0) d16 = d16.colRange(pad, pad + left.cols);
  // OpenCV marks invalid pixels with (min_disparity - 1) * 16.
  const int invalid = (o.min_disparity - 1) * 16;
  cv::Mat d(left.size(), CV_32F);
  for (int y = 0; y < d.rows; ++y) {
    const short* s = d16.ptr<short>(y);
    float* t = d.ptr<float>(y);
    for (int x = 0; x < d.cols; ++x) t[x] = s[x] <= invalid ? kNaN : s[x] / 16.0f;
  }
  return d;
}

// Occluded / invalid runs take the farther (smaller-disparity) of their two row neighbours.
void background_fill(cv::Mat& d) {
  for (int y = 0; y < d.rows; ++y) {
    float* r = d.ptr<float>(y);
    for (int x = 0; x < d.cols; ++x) {
      if (!std::isnan(r[x])) continue;
      int b = x;
      while (b < d.cols && std::isnan(r[b])) ++b;
      const float va = x > 0 ? r[x - 1] : std::numeric_limits<float>::infinity();
      const float vb = b < d.cols ? r[b] : std::numeric_limits<float>::infinity();
      float v = std::min(va, vb);
      if (std::isinf(v)) v = kNaN;  // the whole row is invalid: left for the column pass
      for (int k = x; k < b; ++k) r[k] = v;
      x = b - 1;
    }
  }
  // Rows that were entirely invalid: copy the nearest valid row above or below.
  for (int y = 0; y < d.rows; ++y) {
    if (!std::isnan(d.at<float>(y, 0))) continue;
    int src = -1;
    for (int k = 1; k < d.rows && src < 0; ++k) {
      if (y - k >= 0 && !std::isnan(d.at<float>(y - k, 0))) src = y - k;
      else if (y + k < d.rows && !std::isnan(d.at<float>(y + k, 0))) src = y + k;
    }
    if (src >= 0) d.row(src).copyTo(d.row(y));
    else d.setTo(0.0f);  // no valid pixel anywhere: a flat zero map
  }
}

// Joint weighted median of d over a (2r+1)² window: weight exp(-|I_p - I_q|² / (2 σ²)) from
// the guide's colour (8-bit, 1 or 3 channels). Written by hand because OpenCV's
// ximgproc::weightedMedianFilter gave a different result on each call with the same input
// (measured: ~5k of 110k pixels changed between calls on tsukuba); this one is a pure
// function of its input, rows in parallel. O(pixels · r² log r).
cv::Mat joint_weighted_median(const cv::Mat& guide, const cv::Mat& d, int r, double sigma) {
  const int ch = guide.channels();
  // 8-bit guide: the squared colour distance is an integer, so the weights come from a table.
  std::vector<float> wt(static_cast<std::size_t>(ch) * 255 * 255 + 1);
  for (std::size_t k = 0; k < wt.size(); ++k) wt[k] = static_cast<float>(std::exp(-double(k) / (2.0 * sigma * sigma)));
  cv::Mat out(d.size(), CV_32F);
#pragma omp parallel for schedule(static)
  for (int y = 0; y < d.rows; ++y) {
    std::vector<std::pair<float, float>> vw;  // (value, weight)
    vw.reserve(static_cast<std::size_t>((2 * r + 1) * (2 * r + 1)));
    const std::uint8_t* gp = guide.ptr<std::uint8_t>(y);
    for (int x = 0; x < d.cols; ++x) {
      vw.clear();
      float total = 0;
      for (int yy = std::max(0, y - r); yy <= std::min(d.rows - 1, y + r); ++yy) {
        const std::uint8_t* gq = guide.ptr<std::uint8_t>(yy);
        const float* dq = d.ptr<float>(yy);
        for (int xx = std::max(0, x - r); xx <= std::min(d.cols - 1, x + r); ++xx) {
          if (std::isnan(dq[xx])) continue;
          int dist2 = 0;
          for (int c = 0; c < ch; ++c) {
            const int e = int(gp[x * ch + c]) - int(gq[xx * ch + c]);
            dist2 += e * e;
          }
          const float w = wt[static_cast<std::size_t>(dist2)];
          vw.emplace_back(dq[xx], w);
          total += w;
        }
      }
      if (vw.empty()) {
        out.at<float>(y, x) = d.at<float>(y, x);
        continue;
      }
      std::sort(vw.begin(), vw.end());
      float acc = 0;
      std::size_t k = 0;
      while (k + 1 < vw.size() && (acc += vw[k].second) < 0.5f * total) ++k;
      out.at<float>(y, x) = vw[k].first;
    }
  }
  return out;
}

}  // namespace

DisparityMap compute_disparity(const cv::Mat& left, const cv::Mat& right, const StereoMatchOptions& o) {
  const auto t0 = Clock::now();
  std::string why;
  if (!o.isValid(&why)) throw InvalidInput("[tbsp::compute_disparity] invalid options: " + why);
  if (left.empty() || right.empty()) throw InvalidInput("[tbsp::compute_disparity] empty image (left or right): load both images of the pair");
  if (left.size() != right.size())
    throw InvalidInput("[tbsp::compute_disparity] the images differ in size (left " + std::to_string(left.cols) + "x" +
                       std::to_string(left.rows) + ", right " + std::to_string(right.cols) + "x" + std::to_string(right.rows) +
                       "): a rectified pair has one size");
  if (left.type() != right.type() || left.depth() != CV_8U || (left.channels() != 1 && left.channels() != 3))
    throw InvalidInput("[tbsp::compute_disparity] images must both be 8-bit grey or 8-bit BGR");
  if (left.cols <= o.num_disparities / 2 && !o.pad_border)
    throw InvalidInput("[tbsp::compute_disparity] image width " + std::to_string(left.cols) + " is too small for " +
                       std::to_string(o.num_disparities) + " disparities: reduce num_disparities or enable pad_border");

  DisparityMap out;
  out.pixels = left.cols * left.rows;
  cv::Mat dl = sgbm_pass(left, right, o);
  out.matched = cv::Mat(left.size(), CV_8U, cv::Scalar(0));
  for (int y = 0; y < dl.rows; ++y)
    for (int x = 0; x < dl.cols; ++x)
      if (!std::isnan(dl.at<float>(y, x))) ++out.matched_pixels;

  if (o.left_right_check) {
    const cv::Mat dl_raw = dl.clone();
    // Right-reference disparities: match the mirrored pair (mirrored right as the reference).
    cv::Mat lf, rf;
    cv::flip(left, lf, 1);
    cv::flip(right, rf, 1);
    cv::Mat drf = sgbm_pass(rf, lf, o);
    cv::Mat dr;
    cv::flip(drf, dr, 1);  // dr(x): right(x) matches left(x + dr)
    for (int y = 0; y < dl.rows; ++y) {
      float* l = dl.ptr<float>(y);
      const float* r = dr.ptr<float>(y);
      for (int x = 0; x < dl.cols; ++x) {
        if (std::isnan(l[x])) continue;
        const int xr = static_cast<int>(std::lround(x - l[x]));
        if (xr < 0 || xr >= dl.cols || std::isnan(r[xr]) || std::abs(r[xr] - l[x]) > o.lr_tolerance) l[x] = kNaN;
      }
    }
    // The same check from the right view (against the unchecked left map, kept in dl_raw).
    for (int y = 0; y < dr.rows; ++y) {
      float* r = dr.ptr<float>(y);
      const float* l = dl_raw.ptr<float>(y);
      for (int x = 0; x < dr.cols; ++x) {
        if (std::isnan(r[x])) continue;
        const int xl = static_cast<int>(std::lround(x + r[x]));
        if (xl < 0 || xl >= dr.cols || std::isnan(l[xl]) || std::abs(l[xl] - r[x]) > o.lr_tolerance) r[x] = kNaN;
      }
    }
    out.right_disparity = dr;
  }
  for (int y = 0; y < dl.rows; ++y)
    for (int x = 0; x < dl.cols; ++x)
      if (!std::isnan(dl.at<float>(y, x))) {
        out.matched.at<std::uint8_t>(y, x) = 255;
        ++out.consistent_pixels;
      }

  if (o.fill_invalid) {
    background_fill(dl);
    if (o.median_radius > 0) {
      dl = joint_weighted_median(left, dl, o.median_radius, 25.5);
    }
  }
  out.disparity = dl;
  out.seconds = seconds_since(t0);
  return out;
}

double bad_pixel_rate(const cv::Mat& disparity, const cv::Mat& gt, double gt_scale, double threshold, const cv::Mat& mask) {
  if (disparity.size() != gt.size() || disparity.type() != CV_32F)
    throw InvalidInput("[tbsp::bad_pixel_rate] the disparity map must be CV_32F and the size of the ground truth");
  if (gt.type() != CV_8U && gt.type() != CV_16U) throw InvalidInput("[tbsp::bad_pixel_rate] ground truth must be 8- or 16-bit single channel");
  if (!mask.empty() && (mask.size() != gt.size() || mask.type() != CV_8U))
    throw InvalidInput("[tbsp::bad_pixel_rate] the mask must be CV_8U and the size of the ground truth");
  if (!(gt_scale > 0)) throw InvalidInput("[tbsp::bad_pixel_rate] gt_scale must be > 0");
  long known = 0, bad = 0;
  for (int y = 0; y < gt.rows; ++y)
    for (int x = 0; x < gt.cols; ++x) {
      const double g = gt.type() == CV_8U ? gt.at<std::uint8_t>(y, x) : gt.at<std::uint16_t>(y, x);
      if (g <= 0 || (!mask.empty() && mask.at<std::uint8_t>(y, x) == 0)) continue;
      ++known;
      const float d = disparity.at<float>(y, x);
      if (std::isnan(d) || std::abs(d - g / gt_scale) > threshold) ++bad;
    }
  if (known == 0) throw InvalidInput("[tbsp::bad_pixel_rate] the ground truth has no known pixel (all 0)");
  return 100.0 * static_cast<double>(bad) / static_cast<double>(known);
}

}  // namespace tbsp
