#pragma once
/// \file radius_grid.h
/// \brief Fixed-radius neighbour search over a static point set: a uniform grid whose cells are
/// one search radius wide, the points stored cell by cell.
///
/// For loops that rebuild the search after every step and ask every query with the same radius
/// (the fitter's detail rounds: ~90k points indexed and ~43k queries per iteration). Against
/// PointSearch (nanoflann's k-d tree) it builds in O(n) where the points are dense (a counting
/// sort over the cells; else one sort of 64-bit cell keys; no tree) and answers a query by
/// scanning the 27 cells around it, contiguous in memory. Written by hand: the k-d trees and
/// octrees of nanoflann, FLANN and PCL answer any radius; none offers a fixed-radius grid rebuilt
/// by one sort, with a fixed visiting order.

#include <Eigen/Core>
#include <cmath>
#include <cstdint>
#include <vector>

namespace tbsp {

class RadiusGrid {
public:
  RadiusGrid() = default;
  /// \brief Indexes the rows of P (copied) for queries of radius `radius` (> 0, in P's units).
  /// Non-finite rows are left out. O(n + cells) time (a counting sort over the cells) where the
  /// points' box holds at most max(4n, 65536) cells, else O(n log n) (one sort of the cell keys);
  /// O(n) memory beyond those cells' counters. The cells are `radius` wide, or
  /// wider where that would make more than 2^20 cells along an axis (a radius below a millionth
  /// of the points' extent: still correct, the queries scan more points).
  /// \throws InvalidInput for radius ≤ 0 or non-finite, or 2^32 − 1 points or more.
  RadiusGrid(const Eigen::MatrixX3d& P, double radius);

  /// The radius the grid was built for.
  double radius() const { return radius_; }
  /// Number of indexed (finite) points.
  std::size_t size() const { return index_.size(); }

  /// \brief Calls f(i, d2) for every indexed point i (row of P) with squared distance
  /// d2 < radius² to q, cell by cell in a fixed order (the same on every run and thread count).
  /// Thread-safe (const). q may be anywhere, also outside the points' bounding box.
  template <class Fn>
  void forEachWithin(const Eigen::Vector3d& q, Fn&& f) const {
    forEachSlotWithin(q, [&](std::size_t slot, double d2) { f(Eigen::Index(index_[slot]), d2); });
  }

  /// The rows of P in the order the grid stores them (cell by cell): slot s holds row rows()[s].
  const std::vector<std::uint32_t>& rows() const { return index_; }

  /// \brief As forEachWithin, but calls f(slot, d2) with the point's slot in rows(): data the
  /// caller keeps in slot order are read in the order the grid scans them (cache-friendly).
  template <class Fn>
  void forEachSlotWithin(const Eigen::Vector3d& q, Fn&& f) const {
    if (index_.empty() || !q.allFinite()) return;
    const double r2 = radius_ * radius_;
    std::int64_t c[3];
    for (int d = 0; d < 3; ++d) {
      const double x = std::floor((q(d) - lo_(d)) / cell_);
      if (x < -1 || x > double(dims_[d])) return;  // no cell within one radius
      c[d] = std::int64_t(x);
    }
    for (std::int64_t z = c[2] - 1; z <= c[2] + 1; ++z)
      for (std::int64_t y = c[1] - 1; y <= c[1] + 1; ++y)
        for (std::int64_t x = c[0] - 1; x <= c[0] + 1; ++x) {
          const std::int64_t cell = find(x, y, z);
          if (cell < 0) continue;
          for (std::uint32_t k = start_[std::size_t(cell)]; k < start_[std::size_t(cell) + 1]; ++k) {
            const double dx = xyz_[3 * k] - q(0), dy = xyz_[3 * k + 1] - q(1), dz = xyz_[3 * k + 2] - q(2);
            const double d2 = dx * dx + dy * dy + dz * dz;
            if (d2 < r2) f(std::size_t(k), d2);
          }
        }
  }

private:
  std::int64_t find(std::int64_t x, std::int64_t y, std::int64_t z) const;

  double radius_ = 0;
  double cell_ = 0;  // cell width: radius_, or wider for very small radii
  Eigen::Vector3d lo_ = Eigen::Vector3d::Zero();
  std::int64_t dims_[3] = {0, 0, 0};
  std::vector<double> xyz_;            // the points, cell by cell
  std::vector<std::uint32_t> index_;   // their rows of P
  std::vector<std::uint32_t> start_;   // first point of each occupied cell (+ one past the last)
  std::vector<std::uint64_t> keys_;    // each occupied cell's key, ascending
  std::vector<std::int64_t> table_;    // open-addressing hash: key -> cell, -1 empty
  std::uint64_t mask_ = 0;
  int bits_ = 0;
};

}  // namespace tbsp
