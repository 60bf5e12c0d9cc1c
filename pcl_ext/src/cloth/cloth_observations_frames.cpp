// ClothObservations, the frames: silhouette boundaries and SIFT correspondences (addFrame,
// primeFrame). Construction, queries and serialization: cloth_observations.cpp.
#include <string>
#include <vector>

#include <opencv2/features2d.hpp>

#include "cloth_observations_impl.h"
#include "tbsp/core/error.h"

namespace tbsp {

using detail::BoundaryTree;
using detail::ViewFrame;

namespace {

// Foreground pixels with a background (or out-of-image) 4-neighbour.
void boundary_pixels(const cv::Mat& sil, std::vector<Eigen::Vector2f>& out) {
  out.clear();
  auto fg = [&](int x, int y) { return x >= 0 && y >= 0 && x < sil.cols && y < sil.rows && sil.at<std::uint8_t>(y, x) >= 128; };
  for (int y = 0; y < sil.rows; ++y)
    for (int x = 0; x < sil.cols; ++x)
      if (fg(x, y) && (!fg(x - 1, y) || !fg(x + 1, y) || !fg(x, y - 1) || !fg(x, y + 1))) out.emplace_back(float(x), float(y));
}

// Mutual-best SIFT matches from `a` to `b` passing the ratio test and the motion gate.
std::vector<FeaturePair> match_pairs(const detail::ViewFeatures& a, const detail::ViewFeatures& b, const ClothObservationOptions& o) {
  std::vector<FeaturePair> out;
  if (a.desc.rows < 2 || b.desc.rows < 2) return out;
  cv::BFMatcher matcher(cv::NORM_L2);
  std::vector<std::vector<cv::DMatch>> ab, ba;
  matcher.knnMatch(a.desc, b.desc, ab, 2);
  matcher.knnMatch(b.desc, a.desc, ba, 1);
  for (std::size_t i = 0; i < ab.size(); ++i) {
    if (ab[i].size() < 2 || ab[i][0].distance > o.ratio * ab[i][1].distance) continue;
    const int j = ab[i][0].trainIdx;
    if (ba[std::size_t(j)].empty() || ba[std::size_t(j)][0].trainIdx != int(i)) continue;  // mutual best
    const Eigen::Vector2d& p = a.pixel[i];
    const Eigen::Vector2d& q = b.pixel[std::size_t(j)];
    if ((q - p).norm() > o.max_motion_px) continue;
    out.push_back({p.cast<float>(), q.cast<float>()});
  }
  return out;
}

}  // namespace

void ClothObservations::checkFrame(const std::vector<cv::Mat>& images, const std::vector<cv::Mat>& silhouettes, const std::string& w) const {
  const std::size_t k = cameras_.size();
  if (images.size() != k || silhouettes.size() != k)
    throw InvalidInput(w + "one image and one silhouette per camera are needed (" + std::to_string(k) + " cameras, " + std::to_string(images.size()) +
                       " images, " + std::to_string(silhouettes.size()) + " silhouettes)");
  for (std::size_t c = 0; c < k; ++c) {
    const Camera& cam = cameras_[c];
    const std::string size = std::to_string(cam.width()) + "x" + std::to_string(cam.height());
    if (images[c].empty() || images[c].cols != cam.width() || images[c].rows != cam.height() || (images[c].type() != CV_8UC3 && images[c].type() != CV_8U))
      throw InvalidInput(w + "camera '" + cam.name() + "': the image must be 8-bit (grey or BGR) and " + size + " (the calibrated size)");
    if (silhouettes[c].empty() || silhouettes[c].cols != cam.width() || silhouettes[c].rows != cam.height() || silhouettes[c].type() != CV_8U)
      throw InvalidInput(w + "camera '" + cam.name() + "': the silhouette must be 8-bit and " + size + " (the calibrated size)");
  }
}

void ClothObservations::primeFrame(const std::vector<cv::Mat>& images, const std::vector<cv::Mat>& silhouettes) {
  const std::string w = "[tbsp::ClothObservations] primeFrame: ";
  if (numFrames() > 0 || impl_->assembled) throw InvalidInput(w + "only before the first addFrame (it is the frame before the first one)");
  checkFrame(images, silhouettes, w);
  const std::size_t k = cameras_.size();
  std::vector<detail::ViewFeatures> feats(k);
#pragma omp parallel for schedule(dynamic)
  for (long c = 0; c < long(k); ++c)
    feats[std::size_t(c)] = detail::detect_features(images[std::size_t(c)], silhouettes[std::size_t(c)], options_.max_features);
  impl_->last_features = std::move(feats);
}

void ClothObservations::addFrame(const std::vector<cv::Mat>& images, const std::vector<cv::Mat>& silhouettes) {
  const int n = numFrames();
  const std::string w = "[tbsp::ClothObservations] frame " + std::to_string(n) + ": ";
  if (impl_->assembled) throw InvalidInput(w + "frames cannot be added after append(): add the frames to the parts, then append the parts");
  checkFrame(images, silhouettes, w);
  const std::size_t k = cameras_.size();
  const bool match = !impl_->last_features.empty();  // the previous frame (or the primed one)
  std::vector<ViewFrame> views(k);
  std::vector<detail::ViewFeatures> feats(k);
  std::vector<std::string> errors(k);
#pragma omp parallel for schedule(dynamic)
  for (long c = 0; c < long(k); ++c) {
    ViewFrame& vf = views[std::size_t(c)];
    boundary_pixels(silhouettes[std::size_t(c)], vf.boundary.pts);
    if (vf.boundary.pts.empty()) {
      errors[std::size_t(c)] = w + "camera '" + cameras_[std::size_t(c)].name() +
                               "': the silhouette is empty: the performer must be seen in every view (leave the camera out or fix the segmentation)";
      continue;
    }
    vf.tree = std::make_unique<BoundaryTree>(2, vf.boundary, nanoflann::KDTreeSingleIndexAdaptorParams(16));
    vf.tree->buildIndex();
    feats[std::size_t(c)] = detail::detect_features(images[std::size_t(c)], silhouettes[std::size_t(c)], options_.max_features);
    if (match) vf.pairs = match_pairs(impl_->last_features[std::size_t(c)], feats[std::size_t(c)], options_);
  }
  for (const std::string& e : errors)
    if (!e.empty()) throw InvalidInput(e);
  impl_->frames.push_back(std::move(views));
  impl_->last_features = std::move(feats);
}

}  // namespace tbsp
