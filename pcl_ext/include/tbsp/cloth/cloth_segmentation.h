#pragma once
/// \file cloth_segmentation.h
/// \brief Cloth segmentation of a mesh sequence (thesis §10.3): which surface regions deform
/// like loose apparel and which move (nearly) rigidly with the body.
///
/// For every vertex v_i of the first frame a ray is shot along −n_i to the opposite surface; the
/// hit p_i is kept in barycentric coordinates of its face. Over the sequence the standard
/// deviation σ_i of |v_i − p_i| measures how much the cross-section through v_i changes; the
/// clothness is δ_i = clamp((σ_i − t_rigid) / (t_cloth − t_rigid), 0, 1) (eq. 10.1), cleaned by
/// one-ring median filters, then diffused on the surface (which also fills vertices whose ray
/// found no opposite surface).
///
/// \code
/// tbsp::ClothSegmentation seg;
/// seg.begin(frame0.V, frame0.F);
/// for (frame : sequence) seg.addFrame(frame.V);   // streams: frames are not kept
/// tbsp::ClothSegmentation::Result r = seg.finish();
/// \endcode

#include <Eigen/Core>
#include <Eigen/SparseCore>

namespace tbsp {

/// Parameters of ClothSegmentation.
struct ClothSegmentationOptions {
  /// t_rigid of eq. 10.1 as a fraction of the first frame's bounding-box diagonal: σ below it is
  /// body (δ = 0). Default 0.002 (4 mm on a 2 m person), range [0, t_cloth).
  double t_rigid = 0.002;
  /// t_cloth of eq. 10.1, same unit: σ above it is fully cloth (δ = 1). Default 0.008 (16 mm on a
  /// 2 m person).
  double t_cloth = 0.008;
  /// One-ring median filters of eq. 10.1's values before the diffusion (0 = none), 0..10.
  /// Default 2: removes isolated vertices whose ray left through a hole and met a moving part.
  int median_passes = 2;
  /// Diffusion of δ on the surface: implicit heat step of time `diffusion` · (mean edge length)²
  /// (0 = none, only vertices without a ray hit are filled harmonically). Default 2, range [0, 1e4].
  double diffusion = 2.0;
};

class ClothSegmentation {
public:
  struct Result {
    Eigen::VectorXd sigma;      ///< σ_i, units of V; NaN where the ray found no opposite surface
    Eigen::VectorXd raw;        ///< eq. 10.1 before diffusion (NaN where no hit)
    Eigen::VectorXd clothness;  ///< δ_i ∈ [0, 1] after diffusion; values below 0.01 are 0, above 0.99 are 1
    Eigen::VectorXi opposite_face;  ///< face hit by vertex i's ray in frame 1 (-1: none)
    Eigen::MatrixX3d opposite_bary; ///< barycentric coordinates of the hit
    int frames = 0;             ///< frames accumulated (frame 1 included)
    double t_rigid = 0, t_cloth = 0;  ///< the thresholds used, in units of V
    /// Vertices with δ > 0.5 (cloth).
    Eigen::VectorXi clothLabels() const { return (clothness.array() > 0.5).cast<int>(); }
  };

  void setOptions(const ClothSegmentationOptions& o);
  const ClothSegmentationOptions& options() const { return options_; }

  /// \brief Starts a sequence with its first frame: casts the rays (Embree, hits refined in
  /// double precision) and accumulates frame 1. O(#V log #F).
  /// \throws InvalidInput for an empty mesh, bad face indices or non-finite coordinates.
  void begin(const Eigen::MatrixX3d& V0, const Eigen::MatrixX3i& F);
  /// \brief Accumulates one more frame (same connectivity). O(#V).
  /// \throws InvalidInput when the vertex count differs from frame 1 or a coordinate is NaN/Inf
  /// (the message names the frame and vertex); the frame is then not counted.
  void addFrame(const Eigen::MatrixX3d& V);
  /// \brief σ, eq. 10.1 and the diffusion. \throws InvalidInput before begin() or with fewer
  /// than 2 frames; NumericalFailure if the diffusion system cannot be factorized.
  Result finish() const;

private:
  ClothSegmentationOptions options_;
  Eigen::MatrixX3d V0_;
  Eigen::MatrixX3i F_;
  Eigen::VectorXi face_;
  Eigen::MatrixX3d bary_;
  Eigen::VectorXd mean_, m2_;
  int frames_ = 0;
};

}  // namespace tbsp
