#pragma once
/// \file point_search.h
/// \brief Static 3D k-d tree over an Eigen point set (nanoflann), thread-safe queries.
/// Used per element in parallel loops (matching, normal orientation, metrics).

#include <Eigen/Core>
#include <memory>
#include <utility>
#include <vector>

namespace tbsp {

class PointSearch {
public:
  PointSearch();
  ~PointSearch();
  PointSearch(PointSearch&&) noexcept;
  PointSearch& operator=(PointSearch&&) noexcept;

  /// \brief Builds the tree over the rows of P (copied). O(n log n).
  explicit PointSearch(const Eigen::MatrixX3d& P);
  void build(const Eigen::MatrixX3d& P);
  Eigen::Index size() const;
  const Eigen::MatrixX3d& points() const;

  /// Points within `radius` of q: (index, squared distance), unsorted. Thread-safe.
  void radius(const Eigen::Vector3d& q, double radius, std::vector<std::pair<Eigen::Index, double>>& out) const;
  /// Index of the nearest point (and its squared distance); -1 when empty. Thread-safe.
  Eigen::Index nearest(const Eigen::Vector3d& q, double* dist2 = nullptr) const;
  /// k nearest neighbours (fewer if the set is smaller). Thread-safe.
  void knn(const Eigen::Vector3d& q, int k, std::vector<Eigen::Index>& idx, std::vector<double>& dist2) const;

private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

/// Median distance from a point to its nearest neighbour, over up to `samples` evenly spaced
/// points (deterministic): the typical sample spacing of a cloud.
double median_spacing(const PointSearch& tree, int samples = 2000);

/// Farthest-point sampling of `k` of the `candidates` (row indices of V), starting from the
/// candidate nearest V's centroid: deterministic, spread evenly over the points. Returns fewer
/// than k when the candidates run out (or only coincident ones are left). O(k · #candidates).
std::vector<int> farthest_point_sample(const Eigen::MatrixX3d& V, const std::vector<int>& candidates, int k);

}  // namespace tbsp
