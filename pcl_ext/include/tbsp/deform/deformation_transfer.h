#pragma once
/// \file deformation_transfer.h
/// \brief Transfer of a tet-mesh deformation to a high-resolution surface, thesis §7.3
/// (eq. 7.11–7.13).
///
/// Every high-resolution vertex v_i is written as a combination of the tet-mesh vertices:
/// for all tetrahedra t_j whose barycenter lies within r of v_i, the (possibly negative,
/// extrapolating) barycentric coordinates c_i(j) of v_i w.r.t. t_j are blended with the
/// Wendland weights φ(d) = (1 − d/r)⁴ (4d/r + 1), d = ‖v_i − center(t_j)‖ (eq. 7.12), and
/// normalized (eq. 7.11). The coefficients form one sparse row-major matrix B (#high-res × #tet
/// vertices), and the deformed surface is V' = B X (eq. 7.13), a sparse product.
///
/// Exactness: each c_i(j) reproduces affine maps and the weights sum to one, so identity and
/// rigid (indeed any affine) motions of the tet mesh are reproduced to rounding error. The
/// blend is C¹ in v_i (Wendland C² weights of smoothly varying barycentric coordinates), so
/// the result has no per-tet kinks ("dents") of the nearest-tet transfer.
/// A vertex with no tetrahedron within r uses its nearest tetrahedron (by barycenter) alone.
/// A tet mesh of several vertex-connected parts (a template of overlapping closed bodies, or a
/// shell of several surfaces): a vertex blends only the tets of the part its nearest tetrahedron
/// belongs to, so parts do not drag each other along.
///
/// Cost: precompute O(N · k) with k tets per ball (parallel over vertices, OpenMP); apply
/// O(nnz(B)) (parallel over rows). Memory: nnz(B) · 12 bytes.

#include <Eigen/Core>
#include <Eigen/SparseCore>
#include <memory>
#include <string>

#include "tbsp/core/progress.h"
#include "tbsp/mesh/tet_mesh.h"

namespace tbsp {

/// Options of DeformationTransfer (docs/conventions.md).
struct DeformationTransferOptions {
  /// Wendland support radius r (model units); 0 = 5 % of the tet mesh's bounding-box diagonal
  /// (the thesis' value). Range ≥ 0, finite. Default 0.
  double radius = 0.0;
  /// True when every field is in range; else false and, if given, `why` says which and why.
  bool isValid(std::string* why = nullptr) const;
};

/// What the last precompute() did.
struct DeformationTransferReport {
  Eigen::Index vertices = 0;        ///< high-resolution vertices (rows of B)
  double radius = 0;                ///< r used (model units)
  double mean_tets_per_vertex = 0;  ///< tetrahedra blended per vertex, mean
  Eigen::Index fallback_vertices = 0;  ///< vertices without a tet within r (nearest tet used)
  double t_precompute = 0;          ///< seconds
};

class DeformationTransfer {
public:
  using Ptr = std::shared_ptr<DeformationTransfer>;
  using ConstPtr = std::shared_ptr<const DeformationTransfer>;
  using Options = DeformationTransferOptions;

  /// \throws InvalidInput when !o.isValid().
  void setOptions(const DeformationTransferOptions& o);
  const DeformationTransferOptions& options() const { return options_; }
  /// Progress of precompute() (stage "transfer"); returning false cancels (tbsp::Cancelled).
  void setProgressCallback(ProgressCallback cb) { progress_ = std::move(cb); }
  const DeformationTransferReport& report() const { return report_; }

  /// \brief Builds B for the high-resolution vertices `hires` (#N by 3) against the rest tet
  /// mesh. `radius` > 0 overrides options().radius for this call; 0 uses the options (whose 0
  /// means 5 % of the tet mesh's bounding-box diagonal). On failure B is left as it was.
  /// \throws InvalidInput for an invalid tet mesh, an empty or non-finite `hires`, a negative
  /// radius; Cancelled when the progress callback returns false.
  void precompute(const TetMesh& tets, const Eigen::MatrixX3d& hires, double radius = 0.0);

  /// \brief V' = B X for deformed tet-vertex positions X (#tet vertices by 3).
  /// \throws InvalidInput when X has the wrong size, or precompute() was not called.
  Eigen::MatrixX3d apply(const Eigen::MatrixX3d& X) const;

  const Eigen::SparseMatrix<double, Eigen::RowMajor>& matrix() const { return B_; }
  double radius() const { return radius_; }
  /// Mean number of tetrahedra blended per vertex.
  double meanTetsPerVertex() const { return mean_tets_; }
  /// Vertices that had no tetrahedron within the radius (nearest tet used).
  Eigen::Index fallbackVertices() const { return fallback_; }
  double precomputeSeconds() const { return t_precompute_; }

private:
  DeformationTransferOptions options_;
  ProgressCallback progress_;
  DeformationTransferReport report_;
  Eigen::SparseMatrix<double, Eigen::RowMajor> B_;
  double radius_ = 0, mean_tets_ = 0, t_precompute_ = 0;
  Eigen::Index fallback_ = 0;
};

}  // namespace tbsp
