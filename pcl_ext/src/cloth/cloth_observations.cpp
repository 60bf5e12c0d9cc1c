// ClothObservations: construction, queries, serialization (the frames themselves, with SIFT:
// cloth_observations_frames.cpp).
#include "tbsp/cloth/cloth_observations.h"

#include <cassert>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>

#include "cloth_observations_impl.h"
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

using detail::BoundaryTree;
using detail::ViewFrame;

ClothObservations::ClothObservations(std::vector<Camera> cameras, ClothObservationOptions options)
    : cameras_(std::move(cameras)), options_(options), impl_(std::make_unique<Impl>()) {
  std::string why;
  if (!options_.isValid(&why)) throw InvalidInput("[tbsp::ClothObservations] " + why);
  if (cameras_.empty()) throw InvalidInput("[tbsp::ClothObservations] no camera: give the studio's calibrated views");
}
ClothObservations::~ClothObservations() = default;
ClothObservations::ClothObservations(ClothObservations&&) noexcept = default;
ClothObservations& ClothObservations::operator=(ClothObservations&&) noexcept = default;

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
