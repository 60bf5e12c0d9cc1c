#include "tbsp/cloth/cloth_observations.h"

#include <cassert>
#include <cstdint>
#include <cstring>
#include <cmath>
#include <limits>

#include <nanoflann.hpp>
#include <opencv2/features2d.hpp>

#include "../multiview/capture_features.h"
#include "tbsp/core/error.h"

namespace tbsp {

bool ClothObservationOptions::isValid(std::string* why) const {
  auto fail = [&](const char* m) {
    if (why) *why = m;
    return false;
  };
  if (max_features < 1 || max_features > 100000) return fail("max_features must be in 1..100000");
  if (!(ratio > 0 && ratio <= 1)) return fail("ratio must be in (0, 1]");
  if (!(max_motion_px > 0) || !std::isfinite(max_motion_px)) return fail("max_motion_px must be positive");
  return true;
}

namespace {

struct Boundary {
  std::vector<Eigen::Vector2f> pts;
  std::size_t kdtree_get_point_count() const { return pts.size(); }
  float kdtree_get_pt(std::size_t i, std::size_t d) const { return pts[i](static_cast<Eigen::Index>(d)); }
  template <class B>
  bool kdtree_get_bbox(B&) const { return false; }
};
using BoundaryTree = nanoflann::KDTreeSingleIndexAdaptor<nanoflann::L2_Simple_Adaptor<float, Boundary>, Boundary, 2, std::size_t>;

struct ViewFrame {
  Boundary boundary;
  std::unique_ptr<BoundaryTree> tree;
  std::vector<FeaturePair> pairs;
};

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

struct ClothObservations::Impl {
  std::vector<std::vector<ViewFrame>> frames;       // [frame][view]
  std::vector<detail::ViewFeatures> last_features;  // of the last frame added (or primed), per view
  bool assembled = false;                           // frames were appended (append)
};

ClothObservations::ClothObservations(std::vector<Camera> cameras, ClothObservationOptions options)
    : cameras_(std::move(cameras)), options_(options), impl_(std::make_unique<Impl>()) {
  std::string why;
  if (!options_.isValid(&why)) throw InvalidInput("[tbsp::ClothObservations] " + why);
  if (cameras_.empty()) throw InvalidInput("[tbsp::ClothObservations] no camera: give the studio's calibrated views");
}
ClothObservations::~ClothObservations() = default;
ClothObservations::ClothObservations(ClothObservations&&) noexcept = default;
ClothObservations& ClothObservations::operator=(ClothObservations&&) noexcept = default;

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

int ClothObservations::numFrames() const { return static_cast<int>(impl_->frames.size()); }

double ClothObservations::boundaryDistance(int frame, int view, const Eigen::Vector2d& p) const {
  assert(frame >= 0 && frame < numFrames() && view >= 0 && view < numViews());
  const ViewFrame& vf = impl_->frames[std::size_t(frame)][std::size_t(view)];
  const float q[2] = {float(p.x()), float(p.y())};
  std::size_t idx = 0;
  float d2 = std::numeric_limits<float>::infinity();
  nanoflann::KNNResultSet<float, std::size_t> rs(1);
  rs.init(&idx, &d2);
  vf.tree->findNeighbors(rs, q, nanoflann::SearchParams());
  return std::sqrt(double(d2));
}

const std::vector<FeaturePair>& ClothObservations::correspondences(int frame, int view) const {
  assert(frame >= 0 && frame < numFrames() && view >= 0 && view < numViews());
  return impl_->frames[std::size_t(frame)][std::size_t(view)].pairs;
}

std::size_t ClothObservations::numBoundaryPixels() const {
  std::size_t s = 0;
  for (const auto& f : impl_->frames)
    for (const auto& v : f) s += v.boundary.pts.size();
  return s;
}

std::size_t ClothObservations::numCorrespondences() const {
  std::size_t s = 0;
  for (const auto& f : impl_->frames)
    for (const auto& v : f) s += v.pairs.size();
  return s;
}

std::size_t ClothObservations::memoryBytes() const {
  // boundary points + the k-d tree's index (~1 index per point plus nodes) + pairs
  return numBoundaryPixels() * (sizeof(Eigen::Vector2f) + 2 * sizeof(std::size_t)) + numCorrespondences() * sizeof(FeaturePair);
}

namespace {

constexpr char kMagic[8] = {'T', 'B', 'S', 'P', 'O', 'B', 'S', '1'};

template <class T>
void put(std::string& out, const T& v) {
  out.append(reinterpret_cast<const char*>(&v), sizeof v);
}

// Reads from a byte string with bounds checks; every failure is one InvalidInput.
struct Reader {
  const std::string& s;
  std::size_t at = 0;
  template <class T>
  T get(const char* what) {
    T v;
    if (s.size() - at < sizeof v)
      throw InvalidInput("[tbsp::ClothObservations] append: the bytes end inside " + std::string(what) + " (at byte " + std::to_string(at) + " of " +
                         std::to_string(s.size()) + "): not a complete serialization");
    std::memcpy(&v, s.data() + at, sizeof v);
    at += sizeof v;
    return v;
  }
  // a count of items of `item_bytes` each that must fit in the rest of the bytes
  std::uint32_t count(std::size_t item_bytes, const char* what) {
    const std::uint32_t n = get<std::uint32_t>(what);
    if (std::size_t(n) > (s.size() - at) / item_bytes)
      throw InvalidInput("[tbsp::ClothObservations] append: " + std::string(what) + " count " + std::to_string(n) + " is beyond the " +
                         std::to_string(s.size() - at) + " bytes left: not a serialization of ClothObservations");
    return n;
  }
};

}  // namespace

std::string ClothObservations::serialize() const {
  std::string out(kMagic, sizeof kMagic);
  put(out, std::uint32_t(numViews()));
  put(out, std::uint32_t(numFrames()));
  for (const auto& f : impl_->frames)
    for (const ViewFrame& v : f) {
      put(out, std::uint32_t(v.boundary.pts.size()));
      for (const Eigen::Vector2f& p : v.boundary.pts) put(out, p.x()), put(out, p.y());
      put(out, std::uint32_t(v.pairs.size()));
      for (const FeaturePair& q : v.pairs) put(out, q.from.x()), put(out, q.from.y()), put(out, q.to.x()), put(out, q.to.y());
    }
  return out;
}

void ClothObservations::append(const std::string& bytes) {
  const std::string w = "[tbsp::ClothObservations] append: ";
  if (bytes.size() < sizeof kMagic || std::memcmp(bytes.data(), kMagic, sizeof kMagic) != 0)
    throw InvalidInput(w + "the bytes do not start with the ClothObservations header: not a serialization of ClothObservations");
  Reader r{bytes, sizeof kMagic};
  const std::uint32_t views = r.get<std::uint32_t>("the view count");
  if (int(views) != numViews())
    throw InvalidInput(w + "the bytes hold " + std::to_string(views) + " views, these observations " + std::to_string(numViews()) +
                       ": append parts of the same studio");
  const std::uint32_t frames = r.count(std::size_t(views) * 2 * sizeof(std::uint32_t), "frame");
  std::vector<std::vector<ViewFrame>> add(frames);
  for (auto& f : add) {
    f.resize(views);
    for (ViewFrame& v : f) {
      const std::uint32_t nb = r.count(2 * sizeof(float), "boundary pixel");
      if (nb == 0) throw InvalidInput(w + "a view without boundary pixels: not a serialization of ClothObservations (every view has some)");
      v.boundary.pts.resize(nb);
      for (Eigen::Vector2f& p : v.boundary.pts) {
        p.x() = r.get<float>("a boundary pixel");
        p.y() = r.get<float>("a boundary pixel");
      }
      const std::uint32_t np = r.count(4 * sizeof(float), "correspondence");
      v.pairs.resize(np);
      for (FeaturePair& q : v.pairs) {
        q.from.x() = r.get<float>("a correspondence");
        q.from.y() = r.get<float>("a correspondence");
        q.to.x() = r.get<float>("a correspondence");
        q.to.y() = r.get<float>("a correspondence");
      }
    }
  }
  if (r.at != bytes.size())
    throw InvalidInput(w + std::to_string(bytes.size() - r.at) + " bytes after the last frame: not a serialization of ClothObservations");
  for (auto& f : add)
    for (ViewFrame& v : f) {
      for (const Eigen::Vector2f& p : v.boundary.pts)
        if (!p.allFinite()) throw InvalidInput(w + "a boundary pixel is not finite: not a serialization of ClothObservations");
      v.tree = std::make_unique<BoundaryTree>(2, v.boundary, nanoflann::KDTreeSingleIndexAdaptorParams(16));
      v.tree->buildIndex();
    }
  for (auto& f : add) impl_->frames.push_back(std::move(f));
  impl_->last_features.clear();
  impl_->assembled = true;
}

}  // namespace tbsp
