#pragma once
/// \file trajectory_smoother.h
/// \brief Temporal smoothing of the vertex trajectories of a mesh sequence with constant
/// connectivity (performance capture's optional last step, thesis §9.2): each vertex's position
/// is convolved over time with a Gaussian of `sigma` frames, truncated at r = ceil(3 σ) frames
/// and renormalised where the sequence ends (the first and last r frames use the frames that
/// exist).
///
/// Streaming: push() takes frames in order and returns those whose window is complete — the
/// output lags the input by r frames; flush() returns the rest at the end of the sequence. Memory:
/// 2 r + 1 frames. Cost: O((2 r + 1) · #V) per frame. Deterministic (fixed summation order).
///
/// Trade-off: smoothing removes frame-to-frame jitter but also flattens fast motion; a motion of
/// frequency f (cycles per frame) keeps exp(-2 π² σ² f²) of its amplitude (σ = 1 frame: 97 % of
/// a 1 Hz swing at 25 frames/s). σ = 0 passes frames through unchanged.
///
/// Errors (InvalidInput): σ negative or not finite, or > 50; a frame whose vertex count differs
/// from the first one's, or with non-finite coordinates (the message names the frame).

#include <deque>
#include <utility>
#include <vector>

#include <Eigen/Core>

namespace tbsp {

class TrajectorySmoother {
public:
  /// One smoothed frame: the caller's frame number and the vertex positions.
  using Frame = std::pair<int, Eigen::MatrixX3d>;

  /// \param sigma Gaussian standard deviation in frames, [0, 50]; 0 = pass-through.
  explicit TrajectorySmoother(double sigma);
  double sigma() const { return sigma_; }
  /// Window half-width r = ceil(3 σ): the output lag in frames.
  int radius() const { return radius_; }

  /// Adds the next frame (`frame` is carried through, any numbering); returns the frames that
  /// are final now, oldest first (none while the first r frames are buffered).
  std::vector<Frame> push(int frame, const Eigen::MatrixX3d& V);
  /// The remaining frames at the end of the sequence, oldest first; the smoother is then empty
  /// and can take a new sequence.
  std::vector<Frame> flush();

private:
  Frame smoothed(std::size_t centre) const;  ///< frame `centre` of the buffer over the frames present
  double sigma_ = 0;
  int radius_ = 0;
  std::vector<double> kernel_;  ///< weights for offsets -r..r
  std::deque<Frame> buf_;       ///< the last frames, at most 2 r + 1
  std::size_t next_ = 0;        ///< index in buf_ of the next frame to emit
  Eigen::Index vertices_ = -1;
};

/// Smooths a whole sequence at once (TrajectorySmoother over all frames).
std::vector<Eigen::MatrixX3d> smooth_trajectories(const std::vector<Eigen::MatrixX3d>& frames, double sigma);

}  // namespace tbsp
