#include "tbsp/mesh/radius_grid.h"

#include <algorithm>
#include <limits>
#include <string>
#include <utility>

#include "tbsp/core/error.h"

namespace tbsp {

namespace {
constexpr std::int64_t kMaxCells = std::int64_t(1) << 20;  // per axis: keys fit in 60 bits

// Fibonacci hashing: the top `bits` bits of key × 2^64/φ (the table size is 2^bits)
std::uint64_t grid_hash(std::uint64_t key, int bits) { return (key * 0x9E3779B97F4A7C15ull) >> (64 - bits); }
}  // namespace

RadiusGrid::RadiusGrid(const Eigen::MatrixX3d& P, double radius) : radius_(radius) {
  if (!(radius > 0) || !std::isfinite(radius))
    throw InvalidInput("[tbsp::RadiusGrid] the search radius must be positive and finite, got " + std::to_string(radius));
  if (P.rows() >= Eigen::Index(std::numeric_limits<std::uint32_t>::max()))
    throw InvalidInput("[tbsp::RadiusGrid] too many points: " + std::to_string(P.rows()));
  std::vector<std::uint32_t> rows;
  rows.reserve(std::size_t(P.rows()));
  Eigen::Vector3d lo = Eigen::Vector3d::Constant(std::numeric_limits<double>::infinity());
  Eigen::Vector3d hi = -lo;
  for (Eigen::Index i = 0; i < P.rows(); ++i) {
    if (!P.row(i).allFinite()) continue;
    rows.push_back(std::uint32_t(i));
    lo = lo.cwiseMin(P.row(i).transpose());
    hi = hi.cwiseMax(P.row(i).transpose());
  }
  if (rows.empty()) return;
  lo_ = lo;
  cell_ = radius;
  for (int d = 0; d < 3; ++d) cell_ = std::max(cell_, (hi(d) - lo(d)) / double(kMaxCells - 1));
  for (int d = 0; d < 3; ++d) dims_[d] = std::min(kMaxCells, std::int64_t(std::floor((hi(d) - lo(d)) / cell_)) + 1);
  // cell key of every point, sorted (ties by row: a fixed order)
  std::vector<std::uint64_t> key(rows.size());
  for (std::size_t k = 0; k < rows.size(); ++k) {
    std::int64_t c[3];
    for (int d = 0; d < 3; ++d)
      c[d] = std::min<std::int64_t>(dims_[d] - 1, std::int64_t(std::floor((P(rows[k], d) - lo(d)) / cell_)));
    key[k] = std::uint64_t((c[2] * dims_[1] + c[1]) * dims_[0] + c[0]);
  }
  std::vector<std::pair<std::uint64_t, std::uint32_t>> kr(rows.size());
  const std::uint64_t cells = std::uint64_t(dims_[0]) * std::uint64_t(dims_[1]) * std::uint64_t(dims_[2]);
  if (cells <= std::max<std::uint64_t>(4 * rows.size(), std::uint64_t(1) << 16)) {
    // a counting sort over the cells (the grid is rebuilt every iteration of the fitter's
    // detail rounds: O(n + cells) instead of a comparison sort's O(n log n)); stable, and the
    // rows come in ascending order, so the order is the (key, row) order the sort gives
    std::vector<std::uint32_t> first(std::size_t(cells) + 1, 0);
    for (std::uint64_t k : key) ++first[std::size_t(k) + 1];
    for (std::size_t c = 0; c < std::size_t(cells); ++c) first[c + 1] += first[c];
    for (std::size_t k = 0; k < rows.size(); ++k) kr[first[std::size_t(key[k])]++] = {key[k], rows[k]};
  } else {
    for (std::size_t k = 0; k < rows.size(); ++k) kr[k] = {key[k], rows[k]};
    std::sort(kr.begin(), kr.end());
  }
  xyz_.resize(3 * kr.size());
  index_.resize(kr.size());
  for (std::size_t k = 0; k < kr.size(); ++k) {
    index_[k] = kr[k].second;
    for (int d = 0; d < 3; ++d) xyz_[3 * k + std::size_t(d)] = P(kr[k].second, d);
    if (k == 0 || kr[k].first != kr[k - 1].first) {
      keys_.push_back(kr[k].first);
      start_.push_back(std::uint32_t(k));
    }
  }
  start_.push_back(std::uint32_t(kr.size()));
  std::size_t size = 16;
  bits_ = 4;
  while (size < 2 * keys_.size()) {
    size *= 2;
    ++bits_;
  }
  mask_ = size - 1;
  table_.assign(size, -1);
  for (std::size_t cell = 0; cell < keys_.size(); ++cell) {
    std::uint64_t h = grid_hash(keys_[cell], bits_);
    while (table_[h] >= 0) h = (h + 1) & mask_;
    table_[h] = std::int64_t(cell);
  }
}

std::int64_t RadiusGrid::find(std::int64_t x, std::int64_t y, std::int64_t z) const {
  if (x < 0 || y < 0 || z < 0 || x >= dims_[0] || y >= dims_[1] || z >= dims_[2]) return -1;
  const std::uint64_t key = std::uint64_t((z * dims_[1] + y) * dims_[0] + x);
  for (std::uint64_t h = grid_hash(key, bits_);; h = (h + 1) & mask_) {
    const std::int64_t cell = table_[h];
    if (cell < 0) return -1;
    if (keys_[std::size_t(cell)] == key) return cell;
  }
}

}  // namespace tbsp
