#include "tbsp/mesh/trajectory_smoother.h"

#include <cmath>
#include <string>

#include "tbsp/core/error.h"

namespace tbsp {

TrajectorySmoother::TrajectorySmoother(double sigma) : sigma_(sigma) {
  if (!std::isfinite(sigma) || sigma < 0 || sigma > 50)
    throw InvalidInput("[tbsp::TrajectorySmoother] sigma " + std::to_string(sigma) + " frames is outside [0, 50]");
  radius_ = sigma > 0 ? int(std::ceil(3 * sigma)) : 0;
  for (int d = -radius_; d <= radius_; ++d) kernel_.push_back(sigma > 0 ? std::exp(-0.5 * d * d / (sigma * sigma)) : 1.0);
}

TrajectorySmoother::Frame TrajectorySmoother::smoothed(std::size_t centre) const {
  Eigen::MatrixX3d sum = Eigen::MatrixX3d::Zero(vertices_, 3);
  double wsum = 0;
  for (int d = -radius_; d <= radius_; ++d) {
    const long i = long(centre) + d;
    if (i < 0 || i >= long(buf_.size())) continue;
    const double w = kernel_[std::size_t(d + radius_)];
    sum += w * buf_[std::size_t(i)].second;
    wsum += w;
  }
  return {buf_[centre].first, sum / wsum};
}

std::vector<TrajectorySmoother::Frame> TrajectorySmoother::push(int frame, const Eigen::MatrixX3d& V) {
  if (vertices_ < 0) vertices_ = V.rows();
  if (V.rows() != vertices_)
    throw InvalidInput("[tbsp::TrajectorySmoother] frame " + std::to_string(frame) + " has " + std::to_string(V.rows()) +
                       " vertices, the sequence " + std::to_string(vertices_) + ": trajectories need constant connectivity");
  if (!V.allFinite()) throw InvalidInput("[tbsp::TrajectorySmoother] frame " + std::to_string(frame) + " has non-finite vertex coordinates");
  buf_.emplace_back(frame, V);
  std::vector<Frame> out;
  // Emit every frame whose window [centre - r, centre + r] is in the buffer.
  while (next_ < buf_.size() && next_ + std::size_t(radius_) < buf_.size()) out.push_back(smoothed(next_++));
  // Keep only the r frames before the next one to emit (its window's left half).
  while (next_ > std::size_t(radius_)) {
    buf_.pop_front();
    --next_;
  }
  return out;
}

std::vector<TrajectorySmoother::Frame> TrajectorySmoother::flush() {
  std::vector<Frame> out;
  while (next_ < buf_.size()) out.push_back(smoothed(next_++));
  buf_.clear();
  next_ = 0;
  vertices_ = -1;
  return out;
}

std::vector<Eigen::MatrixX3d> smooth_trajectories(const std::vector<Eigen::MatrixX3d>& frames, double sigma) {
  TrajectorySmoother s(sigma);
  std::vector<Eigen::MatrixX3d> out;
  out.reserve(frames.size());
  for (std::size_t i = 0; i < frames.size(); ++i)
    for (auto& f : s.push(int(i), frames[i])) out.push_back(std::move(f.second));
  for (auto& f : s.flush()) out.push_back(std::move(f.second));
  return out;
}

}  // namespace tbsp
