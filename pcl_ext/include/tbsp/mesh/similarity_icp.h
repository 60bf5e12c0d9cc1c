#pragma once
/// \file similarity_icp.h
/// \brief Trimmed ICP with a uniform scale: the rotation, scale and translation that move a
/// source point set (e.g. a template's vertices) onto a target point set (a scan, a visual hull).
///
/// Method: closest-point pairs (nanoflann k-d trees), the farthest `trim` fraction dropped each
/// iteration (Chetverikov et al. 2002's trimmed ICP: outliers, parts one set has and the other
/// does not), then the closed-form similarity of the kept pairs (Umeyama 1991, Eigen::umeyama).
/// Pairs go from every used target point to its nearest source point; with `symmetric`, also
/// from every used source point to its nearest target point (for two sets that each have parts
/// the other lacks, e.g. a template and a visual hull, which is larger than the object in
/// concavities). Local: it converges to the nearest minimum, so the source must start roughly in
/// place (within ~20–30° and ~20 % of the target's size for compact shapes). Point-to-point
/// steps on a smooth shape slide slowly, and with trimming they can stop short of the optimum (the
/// farthest pairs dropped are the ones pulling along the surface); with target normals
/// (point-to-plane steps) the same cases converge in a few iterations (tests/mesh/test_similarity_icp.cpp).
///
/// Written by hand rather than with PCL's IterativeClosestPoint: it runs on the Eigen matrices the
/// callers have, with our k-d tree and no point-type conversions; PCL offers the same pieces
/// (TransformationEstimationSVDScale, CorrespondenceRejectorTrimmed).
///
/// Complexity O(iterations · m log n) for m used points. Deterministic (fixed strides, no random
/// choice; parallel loops write per-index results only).

#include <Eigen/Core>

namespace tbsp {

/// Options of similarity_icp(); see isValid() for the ranges.
struct SimilarityIcpOptions {
  bool estimate_scale = true;  ///< estimate a uniform scale (false: rigid)
  /// Fraction of the pairs with the largest distances dropped per iteration, [0, 0.9].
  double trim = 0.1;
  int max_iterations = 60;     ///< 1..10000
  /// Stop when an iteration moves no source point by more than this, world units; 0 = 1e-6 of
  /// the target's bounding-box diagonal. >= 0.
  double tolerance = 0;
  int max_points = 20000;      ///< at most this many points of each set are used (a fixed stride), >= 10
  /// Stop when the RMS of the kept pairs has not fallen by more than 1e-4 (relative) for this
  /// many iterations: trimming can make the pair set flip between two states near the optimum
  /// (real silhouettes), and the transform then never settles. 0 = off; 0..1000.
  int stall_iterations = 10;
  bool symmetric = false;      ///< also pair source points with their nearest target points

  bool isValid(const char** why = nullptr) const;
};

struct SimilarityIcpResult {
  Eigen::Matrix4d transform = Eigen::Matrix4d::Identity();  ///< source -> target: x' = s R x + t
  double scale = 1;              ///< s
  double rotation_deg = 0;       ///< angle of R, degrees
  Eigen::Vector3d translation = Eigen::Vector3d::Zero();  ///< t
  double rms = 0;                ///< RMS distance of the kept pairs at the last iteration, world units
  int iterations = 0;
  bool converged = false;        ///< stopped by `tolerance` or by a stalled RMS before max_iterations
  bool stalled = false;          ///< ... by a stalled RMS
};

/// \brief Aligns `source` to `target` by trimmed ICP with scale, starting from the identity.
/// \param source #S by 3 points (moved), at least 3.
/// \param target #T by 3 points (fixed), at least 3.
/// \param target_normals optional #T by 3 unit normals of the target: given, each step minimises
///        the point-to-plane distances (Chen & Medioni 1992; linearised, a scale about the
///        centroid) instead of Umeyama's point-to-point: smooth surfaces slide into place in tens
///        of iterations instead of hundreds.
/// \throws InvalidInput naming the problem: fewer than 3 points, non-finite coordinates,
///         invalid options.
SimilarityIcpResult similarity_icp(const Eigen::MatrixX3d& source, const Eigen::MatrixX3d& target,
                                   const SimilarityIcpOptions& options = {}, const Eigen::MatrixX3d* target_normals = nullptr);

/// Applies a 4x4 similarity (or any affine transform) to the rows of V.
Eigen::MatrixX3d transform_points(const Eigen::Matrix4d& T, const Eigen::MatrixX3d& V);

}  // namespace tbsp
