#pragma once
// Internal (not installed): what ClothObservations' two files share — the per-view, per-frame
// data (boundary pixels with their k-d tree, correspondences) and the implementation struct.
// cloth_observations.cpp: construction, queries, serialization (no OpenCV features, so the fuzz
// build can take it alone); cloth_observations_frames.cpp: addFrame / primeFrame (SIFT).
#include <memory>
#include <vector>

#include <Eigen/Core>
#include <nanoflann.hpp>

#include "../multiview/capture_features.h"
#include "tbsp/cloth/cloth_observations.h"

namespace tbsp {
namespace detail {

// The boundary pixels of one view and frame, as nanoflann's dataset.
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

}  // namespace detail

struct ClothObservations::Impl {
  std::vector<std::vector<detail::ViewFrame>> frames;  // [frame][view]
  std::vector<detail::ViewFeatures> last_features;     // of the last frame added (or primed), per view
  bool assembled = false;                              // frames were appended (append)
};

}  // namespace tbsp
