#pragma once
// Internal (not installed): the pose side of PerformanceCapture — the robust displacement field
// on the control surface that satisfies ray constraints, and the black-box handle optimization.

#include <array>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "tbsp/deform/tet_deformer.h"
#include "tbsp/mesh/tri_mesh.h"
#include "tbsp/multiview/camera.h"

namespace tbsp::detail {

/// "The point Σ_k w_k (x_{v_k} + d_{v_k}) lies on the ray (origin, dir)": the point's current
/// position is `p` (it moves with the weighted displacement of up to 4 control vertices).
struct RayConstraint {
  std::array<int, 4> v{{-1, -1, -1, -1}};
  std::array<double, 4> w{{0, 0, 0, 0}};
  Eigen::Vector3d p, origin, dir;
  double pixel_size = 1;  ///< world units per pixel at the point's depth (residuals are in pixels)
  double weight = 1;
  bool feature = true;    ///< feature (true) or silhouette rim (false)
  /// Plane instead of ray: the point must lie on the plane through `origin` with this unit
  /// normal (a silhouette rim: only the contour's normal direction is known, the rim slides along
  /// the contour). Zero = a ray constraint.
  Eigen::Vector3d plane_normal = Eigen::Vector3d::Zero();
};
/// P (3x3) of a constraint: I - d dᵀ for a ray, n nᵀ for a plane.
Eigen::Matrix3d constraint_projector(const RayConstraint& c);
/// Orthonormal directions u with P = Σ u uᵀ: one for a plane, two for a ray. Returns how many.
int constraint_projector_basis(const RayConstraint& c, Eigen::Vector3d u[2]);
/// Σ_i ω_i / s_i² · P_i ⊗ m_i m_iᵀ (3·#cols square; block (c, q) = Σ_i ω_i P_i(c, q) / s_i² m_i m_iᵀ)
/// for the rows m_i of M: the constraints' part of solve_handles' normal equations, by BLAS
/// symmetric rank-k updates. O(#rows · 9 · #cols²).
Eigen::MatrixXd assemble_constraint_normals(const Eigen::MatrixXd& M, const std::vector<RayConstraint>& constraints,
                                            const std::vector<double>& omega);

struct HandleSolveOptions {
  double smoothness = 0.2;  ///< weight of the handle stiffness (per template edge, pixels²)
  double robust_px = 2.0;   ///< Huber scale
  double reject_px = 40.0;  ///< outlier threshold after the first solve (PerformanceCaptureOptions::reject_px)
  double prior = 1e-3;      ///< pull of every handle move to 0 (keeps handles without data where they are)
  int reweights = 2;        ///< robust re-solves after the first
};

/// Handle moves Δh (#handles × 3) that best satisfy the constraints through the linear response
/// `response` (#template vertices × #handles: TetDeformer::handleResponse carried through the
/// transfer, rotations fixed; a constraint's v/w index its rows): min Σ_i ρ(|P_i (p_i + Σ_k w_k R_{v_k} Δh − o_i)| / s_i) + prior Σ |Δh|² / s̄².
/// Dense normal equations (3·#handles unknowns), Huber reweighted, then hard rejection.
struct HandleSolveResult {
  Eigen::MatrixX3d dh;
  int feature_inliers = 0, rim_inliers = 0;
  double median_residual_px = 0;
};
/// `stiffness` (#handles²): Σ over template edges of |u_a − u_b|² for the template motion
/// u = response · Δh (handle_stiffness), weighted by o.smoothness / s̄².
HandleSolveResult solve_handles(const Eigen::MatrixXd& response, const Eigen::MatrixXd& stiffness, const std::vector<RayConstraint>& constraints,
                                const HandleSolveOptions& o);
/// Σ_edges (R_a − R_b)ᵀ (R_a − R_b) for the rows a, b of `response` joined by `edges`.
Eigen::MatrixXd handle_stiffness(const Eigen::MatrixXd& response, const Eigen::MatrixX2i& edges);

/// The thesis' handle optimization (§9.2): moves the `key` handles of `deformer` (ids, with
/// their current targets `targets`) to maximize the silhouette overlap of the control surface
/// (`surface`: faces over the tet vertices) in the (downscaled) views, penalizing E_nonrigid
/// and the handles' distance to their starting targets. NLopt BOBYQA; the deformer's rotations
/// are restored before every evaluation, so the objective is a function of the offsets only.
/// On return the deformer has the best targets and has iterated from them. Returns the number of
/// evaluations; `overlap_before/after` get the mean IoU.
struct HandleOptimization {
  std::vector<Camera> cameras;     ///< downscaled
  std::vector<cv::Mat> silhouettes;  ///< downscaled, 255 foreground
  Eigen::MatrixX3i surface;        ///< control surface faces (tet vertex indices)
  double step = 0.01;              ///< initial trust-region radius, world units
  double nonrigid_weight = 0.1;
  double distance_weight = 1.0;    ///< per (offset / step)²
  int max_evaluations = 200;
};
int optimize_handles(TetDeformer& deformer, const std::vector<int>& key, const std::vector<Eigen::Vector3d>& targets,
                     const HandleOptimization& o, double& overlap_before, double& overlap_after);

}  // namespace tbsp::detail
