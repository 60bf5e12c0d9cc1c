#pragma once
/// \file camera.h
/// \brief A calibrated pinhole camera with optional lens distortion (thesis §6.1: the 3x4
/// calibration matrix C_k of each studio camera).
///
/// Conventions (the same as OpenCV, Middlebury and COLMAP):
/// - world -> camera: X_c = R X_w + t; the camera looks along +z_c, x_c right, y_c down;
/// - pixel coordinates (u, v) with u to the right, v down and the *centre* of the top-left pixel
///   at (0, 0); a pixel (i, j) covers [i-0.5, i+0.5] x [j-0.5, j+0.5];
/// - K = [fx s cx; 0 fy cy; 0 0 1]; distortion is OpenCV's (k1, k2, p1, p2, k3) applied to the
///   normalised coordinates x_c/z_c, y_c/z_c before K;
/// - P = K [R | t] (3x4) when there is no distortion.
/// Units: whatever the world uses (metres, millimetres); pixels for image coordinates.

#include <array>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

namespace tbsp {

using Matrix34d = Eigen::Matrix<double, 3, 4>;

/// OpenCV-order distortion coefficients (k1, k2, p1, p2, k3). All zero = no distortion.
struct Distortion {
  double k1 = 0, k2 = 0, p1 = 0, p2 = 0, k3 = 0;
  bool isZero() const { return k1 == 0 && k2 == 0 && p1 == 0 && p2 == 0 && k3 == 0; }
};

/// A ray in world coordinates: origin (the camera centre) and unit direction.
struct Ray {
  Eigen::Vector3d origin;
  Eigen::Vector3d direction;
};

class Camera {
public:
  Camera() = default;
  /// From intrinsics and pose. Throws tbsp::InvalidInput when K is not upper triangular with
  /// positive focal lengths, R is not a rotation (|RᵀR - I| > 1e-6 or det < 0), a value is not
  /// finite or the size is not positive. The message names the camera.
  Camera(std::string name, int width, int height, const Eigen::Matrix3d& K,
         const Eigen::Matrix3d& R, const Eigen::Vector3d& t, const Distortion& dist = {});

  /// Decomposes a 3x4 projection matrix P ~ K [R | t] (any scale, either sign) by RQ
  /// decomposition. Throws tbsp::InvalidInput when the left 3x3 block has rank < 3 (the
  /// message gives its smallest singular value relative to the largest) or P is not finite.
  static Camera fromProjection(std::string name, int width, int height, const Matrix34d& P);

  const std::string& name() const { return name_; }
  void setName(std::string n) { name_ = std::move(n); }
  int width() const { return width_; }
  int height() const { return height_; }
  const Eigen::Matrix3d& K() const { return K_; }
  const Eigen::Matrix3d& R() const { return R_; }
  const Eigen::Vector3d& t() const { return t_; }
  const Distortion& distortion() const { return dist_; }
  /// P = K [R | t] (ignores distortion).
  Matrix34d P() const;
  /// Camera centre in world coordinates: -Rᵀ t.
  Eigen::Vector3d center() const { return -R_.transpose() * t_; }
  /// Viewing direction (+z of the camera) in world coordinates.
  Eigen::Vector3d viewDirection() const { return R_.row(2).transpose(); }

  /// World point -> camera coordinates.
  Eigen::Vector3d toCamera(const Eigen::Vector3d& Xw) const { return R_ * Xw + t_; }
  /// World point -> pixel (with distortion). Points with z_c <= 0 give non-finite pixels;
  /// check depth() first when that matters.
  Eigen::Vector2d project(const Eigen::Vector3d& Xw) const;
  /// Depth z_c of a world point (distance along the optical axis).
  double depth(const Eigen::Vector3d& Xw) const { return R_.row(2).dot(Xw) + t_.z(); }
  /// Pixel + depth z_c -> world point (inverse of project for points in front of the camera).
  Eigen::Vector3d backProject(const Eigen::Vector2d& pixel, double depth) const;
  /// The ray through a pixel (distortion removed), unit direction.
  Ray ray(const Eigen::Vector2d& pixel) const;
  /// True when the pixel lies inside the image ([-0.5, w-0.5) x [-0.5, h-0.5)).
  bool inImage(const Eigen::Vector2d& pixel) const {
    return pixel.x() >= -0.5 && pixel.y() >= -0.5 && pixel.x() < width_ - 0.5 && pixel.y() < height_ - 0.5;
  }

  /// Normalised (x_c/z_c, y_c/z_c) -> distorted normalised coordinates.
  Eigen::Vector2d distortNormalized(const Eigen::Vector2d& xn) const;
  /// Inverse of distortNormalized by fixed-point iteration (converges for the usual
  /// |k| < 1 lenses; accuracy < 1e-12 after at most 50 steps).
  Eigen::Vector2d undistortNormalized(const Eigen::Vector2d& xd) const;

  /// Horizontal field of view in radians (from fx and the width).
  double horizontalFov() const;

  /// The camera of this image resized by `scale` (> 0) to round(w·s) × round(h·s) pixels (at
  /// least 1 × 1), as cv::resize makes it: pixel centres at integers, u' = s_x (u + 0.5) − 0.5
  /// with s_x = w'/w (and s_y alike), so a rounded size stays exact. Distortion unchanged (it acts
  /// on normalised coordinates). Throws tbsp::InvalidInput when scale is not positive and finite.
  Camera resized(double scale) const;
  /// The camera of the sub-image [x, x + width) × [y, y + height) of this one: the same projection
  /// with the principal point shifted by (−x, −y), so a pixel p of this image is p − (x, y) in the
  /// crop. The window may reach outside the image (pixels there simply see nothing). Throws
  /// tbsp::InvalidInput when width or height is not positive.
  Camera cropped(int x, int y, int width, int height) const;

  /// A camera at `eye` looking at `target` with `up` roughly up in the image (-y), focal length
  /// from the horizontal field of view, principal point at the image centre.
  static Camera lookAt(std::string name, int width, int height, double hfov_radians,
                       const Eigen::Vector3d& eye, const Eigen::Vector3d& target,
                       const Eigen::Vector3d& up);

private:
  void validate() const;
  std::string name_;
  int width_ = 0, height_ = 0;
  Eigen::Matrix3d K_ = Eigen::Matrix3d::Identity();
  Eigen::Matrix3d R_ = Eigen::Matrix3d::Identity();
  Eigen::Vector3d t_ = Eigen::Vector3d::Zero();
  Distortion dist_;
};

/// Linear (DLT) triangulation of one point from >= 2 views, refined by a few Gauss-Newton
/// steps on the reprojection error (distortion respected). Throws tbsp::InvalidInput with fewer
/// than two observations or mismatched sizes.
Eigen::Vector3d triangulate(const std::vector<Camera>& cameras, const std::vector<Eigen::Vector2d>& pixels);

/// Convenience: RMS reprojection error (pixels) of a world point over the given views.
double reprojection_rms(const std::vector<Camera>& cameras, const std::vector<Eigen::Vector2d>& pixels,
                        const Eigen::Vector3d& X);

}  // namespace tbsp
