#include "tbsp/mesh/point_search.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <nanoflann.hpp>

namespace tbsp {

namespace {
struct Cloud {
  Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor> P;
  std::size_t kdtree_get_point_count() const { return std::size_t(P.rows()); }
  double kdtree_get_pt(std::size_t i, std::size_t d) const { return P(Eigen::Index(i), Eigen::Index(d)); }
  template <class BBOX>
  bool kdtree_get_bbox(BBOX&) const { return false; }
};
using Tree = nanoflann::KDTreeSingleIndexAdaptor<nanoflann::L2_Simple_Adaptor<double, Cloud>, Cloud, 3, Eigen::Index>;
}  // namespace

struct PointSearch::Impl {
  Cloud cloud;
  Eigen::MatrixX3d points;
  std::unique_ptr<Tree> tree;
};

PointSearch::PointSearch() : impl_(std::make_unique<Impl>()) {}
PointSearch::~PointSearch() = default;
PointSearch::PointSearch(PointSearch&&) noexcept = default;
PointSearch& PointSearch::operator=(PointSearch&&) noexcept = default;
PointSearch::PointSearch(const Eigen::MatrixX3d& P) : PointSearch() { build(P); }

void PointSearch::build(const Eigen::MatrixX3d& P) {
  impl_->points = P;
  impl_->cloud.P = P;
  impl_->tree = std::make_unique<Tree>(3, impl_->cloud, nanoflann::KDTreeSingleIndexAdaptorParams(16));
  impl_->tree->buildIndex();
}

Eigen::Index PointSearch::size() const { return impl_->points.rows(); }
const Eigen::MatrixX3d& PointSearch::points() const { return impl_->points; }

void PointSearch::radius(const Eigen::Vector3d& q, double r, std::vector<std::pair<Eigen::Index, double>>& out) const {
  out.clear();
  if (!impl_->tree || size() == 0) return;
  nanoflann::SearchParams params;
  params.sorted = false;
  impl_->tree->radiusSearch(q.data(), r * r, out, params);
}

Eigen::Index PointSearch::nearest(const Eigen::Vector3d& q, double* dist2) const {
  if (!impl_->tree || size() == 0) return -1;
  Eigen::Index idx = -1;
  double d2 = 0;
  impl_->tree->knnSearch(q.data(), 1, &idx, &d2);
  if (dist2) *dist2 = d2;
  return idx;
}

void PointSearch::knn(const Eigen::Vector3d& q, int k, std::vector<Eigen::Index>& idx, std::vector<double>& dist2) const {
  const std::size_t n = std::size_t(std::min<Eigen::Index>(k, size()));
  idx.resize(n);
  dist2.resize(n);
  if (n == 0) return;
  const std::size_t got = impl_->tree->knnSearch(q.data(), n, idx.data(), dist2.data());
  idx.resize(got);
  dist2.resize(got);
}

double median_spacing(const PointSearch& tree, int samples) {
  const Eigen::Index n = tree.size();
  if (n < 2) return 0;
  const Eigen::Index step = std::max<Eigen::Index>(1, n / std::max(samples, 1));
  std::vector<double> d;
  std::vector<Eigen::Index> idx;
  std::vector<double> d2;
  for (Eigen::Index i = 0; i < n; i += step) {
    tree.knn(tree.points().row(i).transpose(), 2, idx, d2);
    if (d2.size() == 2) d.push_back(std::sqrt(d2[1]));
  }
  if (d.empty()) return 0;
  std::nth_element(d.begin(), d.begin() + long(d.size() / 2), d.end());
  return d[d.size() / 2];
}

std::vector<int> farthest_point_sample(const Eigen::MatrixX3d& V, const std::vector<int>& candidates, int k) {
  std::vector<int> picked;
  if (candidates.empty() || k <= 0) return picked;
  const Eigen::RowVector3d c = V.colwise().mean();
  std::size_t first = 0;
  double best = std::numeric_limits<double>::infinity();
  for (std::size_t i = 0; i < candidates.size(); ++i) {
    const double d = (V.row(candidates[i]) - c).squaredNorm();
    if (d < best) { best = d; first = i; }
  }
  std::vector<double> dist(candidates.size(), std::numeric_limits<double>::infinity());
  std::size_t next = first;
  while (int(picked.size()) < k) {
    picked.push_back(candidates[next]);
    double far = -1;
    std::size_t arg = next;
    for (std::size_t i = 0; i < candidates.size(); ++i) {
      dist[i] = std::min(dist[i], (V.row(candidates[i]) - V.row(candidates[next])).squaredNorm());
      if (dist[i] > far) { far = dist[i]; arg = i; }
    }
    if (far <= 0) break;  // every candidate picked
    next = arg;
  }
  return picked;
}

}  // namespace tbsp
