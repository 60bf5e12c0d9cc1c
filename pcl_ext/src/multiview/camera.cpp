#include "tbsp/multiview/camera.h"

#include <algorithm>
#include <cmath>
#include <sstream>

#include <Eigen/Dense>

#include "tbsp/core/error.h"

namespace tbsp {

namespace {
std::string cam_label(const std::string& name) { return name.empty() ? std::string("(unnamed)") : "'" + name + "'"; }
}  // namespace

Camera::Camera(std::string name, int width, int height, const Eigen::Matrix3d& K, const Eigen::Matrix3d& R,
               const Eigen::Vector3d& t, const Distortion& dist)
    : name_(std::move(name)), width_(width), height_(height), K_(K), R_(R), t_(t), dist_(dist) {
  validate();
}

void Camera::validate() const {
  const std::string who = "[tbsp::Camera] camera " + cam_label(name_) + ": ";
  if (width_ <= 0 || height_ <= 0)
    throw InvalidInput(who + "image size " + std::to_string(width_) + "x" + std::to_string(height_) +
                       " is not positive; give the width and height in pixels");
  if (!K_.allFinite() || !R_.allFinite() || !t_.allFinite())
    throw InvalidInput(who + "K, R or t holds NaN/Inf");
  if (!std::isfinite(dist_.k1) || !std::isfinite(dist_.k2) || !std::isfinite(dist_.p1) ||
      !std::isfinite(dist_.p2) || !std::isfinite(dist_.k3))
    throw InvalidInput(who + "distortion holds NaN/Inf");
  if (K_(1, 0) != 0 || K_(2, 0) != 0 || K_(2, 1) != 0 || std::abs(K_(2, 2) - 1.0) > 1e-12)
    throw InvalidInput(who + "K must be upper triangular with K(2,2) = 1 (got row 3 = [" +
                       std::to_string(K_(2, 0)) + " " + std::to_string(K_(2, 1)) + " " + std::to_string(K_(2, 2)) +
                       "]); use Camera::fromProjection for a general 3x4 P");
  if (!(K_(0, 0) > 0) || !(K_(1, 1) > 0))
    throw InvalidInput(who + "focal lengths must be positive (fx = " + std::to_string(K_(0, 0)) +
                       ", fy = " + std::to_string(K_(1, 1)) + ")");
  const double orth = (R_.transpose() * R_ - Eigen::Matrix3d::Identity()).norm();
  if (orth > 1e-6 || R_.determinant() < 0) {
    std::ostringstream os;
    os << who << "R is not a rotation (|RᵀR - I| = " << orth << ", det = " << R_.determinant()
       << "); give an orthonormal right-handed world->camera rotation";
    throw InvalidInput(os.str());
  }
}

Camera Camera::fromProjection(std::string name, int width, int height, const Matrix34d& P_in) {
  const std::string who = "[tbsp::Camera::fromProjection] camera " + cam_label(name) + ": ";
  if (!P_in.allFinite()) throw InvalidInput(who + "P holds NaN/Inf");
  Matrix34d P = P_in;
  Eigen::Matrix3d M = P.leftCols<3>();
  Eigen::JacobiSVD<Eigen::Matrix3d> svd(M);
  const auto s = svd.singularValues();
  if (!(s(0) > 0) || s(2) < 1e-12 * s(0)) {
    std::ostringstream os;
    os << who << "the left 3x3 block of P is singular (rank < 3; singular values " << s.transpose()
       << "); P must be K[R|t] of a finite camera";
    throw InvalidInput(os.str());
  }
  if (M.determinant() < 0) {
    P = -P;
    M = -M;
  }
  // RQ decomposition via QR of the row-reversed transpose.
  Eigen::Matrix3d J = Eigen::Matrix3d::Zero();
  J(0, 2) = J(1, 1) = J(2, 0) = 1;
  Eigen::HouseholderQR<Eigen::Matrix3d> qr((J * M).transpose());
  Eigen::Matrix3d Q = qr.householderQ();
  Eigen::Matrix3d U = qr.matrixQR().triangularView<Eigen::Upper>();
  Eigen::Matrix3d K = J * U.transpose() * J;
  Eigen::Matrix3d R = J * Q.transpose();
  for (int i = 0; i < 3; ++i) {
    if (K(i, i) < 0) {
      K.col(i) *= -1;
      R.row(i) *= -1;
    }
  }
  if (R.determinant() < 0) {  // cannot happen when det(M) > 0 and diag(K) > 0, kept for safety
    throw InvalidInput(who + "P does not decompose into a right-handed camera");
  }
  Eigen::Vector3d t = K.inverse() * P.col(3);
  K /= K(2, 2);
  K(1, 0) = K(2, 0) = K(2, 1) = 0;
  K(2, 2) = 1;
  // Re-orthonormalise R against round-off.
  Eigen::JacobiSVD<Eigen::Matrix3d> rsvd(R, Eigen::ComputeFullU | Eigen::ComputeFullV);
  R = rsvd.matrixU() * rsvd.matrixV().transpose();
  return Camera(std::move(name), width, height, K, R, t);
}

Matrix34d Camera::P() const {
  Matrix34d Rt;
  Rt.leftCols<3>() = R_;
  Rt.col(3) = t_;
  return K_ * Rt;
}

Eigen::Vector2d Camera::distortNormalized(const Eigen::Vector2d& xn) const {
  if (dist_.isZero()) return xn;
  const double x = xn.x(), y = xn.y();
  const double r2 = x * x + y * y;
  const double radial = 1 + r2 * (dist_.k1 + r2 * (dist_.k2 + r2 * dist_.k3));
  const double xd = x * radial + 2 * dist_.p1 * x * y + dist_.p2 * (r2 + 2 * x * x);
  const double yd = y * radial + dist_.p1 * (r2 + 2 * y * y) + 2 * dist_.p2 * x * y;
  return {xd, yd};
}

Eigen::Vector2d Camera::undistortNormalized(const Eigen::Vector2d& xd) const {
  if (dist_.isZero()) return xd;
  Eigen::Vector2d x = xd;
  for (int it = 0; it < 50; ++it) {
    const Eigen::Vector2d err = distortNormalized(x) - xd;
    if (err.norm() < 1e-14) break;
    // Newton step with a numerical Jacobian (2x2).
    const double h = 1e-7;
    Eigen::Matrix2d Jm;
    Jm.col(0) = (distortNormalized(x + Eigen::Vector2d(h, 0)) - distortNormalized(x - Eigen::Vector2d(h, 0))) / (2 * h);
    Jm.col(1) = (distortNormalized(x + Eigen::Vector2d(0, h)) - distortNormalized(x - Eigen::Vector2d(0, h))) / (2 * h);
    const double det = Jm.determinant();
    if (std::abs(det) < 1e-12) x -= err;  // fall back to fixed-point
    else x -= Jm.inverse() * err;
  }
  return x;
}

Eigen::Vector2d Camera::project(const Eigen::Vector3d& Xw) const {
  const Eigen::Vector3d Xc = toCamera(Xw);
  Eigen::Vector2d xn(Xc.x() / Xc.z(), Xc.y() / Xc.z());
  xn = distortNormalized(xn);
  return {K_(0, 0) * xn.x() + K_(0, 1) * xn.y() + K_(0, 2), K_(1, 1) * xn.y() + K_(1, 2)};
}

Eigen::Vector3d Camera::backProject(const Eigen::Vector2d& pixel, double depth) const {
  const double yn = (pixel.y() - K_(1, 2)) / K_(1, 1);
  const double xn = (pixel.x() - K_(0, 2) - K_(0, 1) * yn) / K_(0, 0);
  const Eigen::Vector2d u = undistortNormalized({xn, yn});
  const Eigen::Vector3d Xc(u.x() * depth, u.y() * depth, depth);
  return R_.transpose() * (Xc - t_);
}

Ray Camera::ray(const Eigen::Vector2d& pixel) const {
  const Eigen::Vector3d c = center();
  const Eigen::Vector3d p = backProject(pixel, 1.0);
  return {c, (p - c).normalized()};
}

double Camera::horizontalFov() const { return 2.0 * std::atan(0.5 * width_ / K_(0, 0)); }

Camera Camera::resized(double s) const {
  if (!(s > 0) || !std::isfinite(s))
    throw InvalidInput("[tbsp::Camera::resized] camera '" + name_ + "': scale " + std::to_string(s) + " is not positive; pass a factor > 0");
  const int w = std::max(1, static_cast<int>(std::lround(width_ * s))), h = std::max(1, static_cast<int>(std::lround(height_ * s)));
  const double sx = static_cast<double>(w) / width_, sy = static_cast<double>(h) / height_;
  Eigen::Matrix3d K = K_;
  K.row(0) *= sx;
  K.row(1) *= sy;
  K(0, 2) += 0.5 * sx - 0.5;  // pixel centres at integers
  K(1, 2) += 0.5 * sy - 0.5;
  K(2, 2) = 1;
  return Camera(name_, w, h, K, R_, t_, dist_);
}

Camera Camera::cropped(int x, int y, int width, int height) const {
  if (width <= 0 || height <= 0)
    throw InvalidInput("[tbsp::Camera::cropped] camera '" + name_ + "': crop " + std::to_string(width) + "x" + std::to_string(height) +
                       " is empty; pass a positive width and height");
  Eigen::Matrix3d K = K_;
  K(0, 2) -= x;
  K(1, 2) -= y;
  return Camera(name_, width, height, K, R_, t_, dist_);
}

Camera Camera::lookAt(std::string name, int width, int height, double hfov, const Eigen::Vector3d& eye,
                      const Eigen::Vector3d& target, const Eigen::Vector3d& up) {
  const Eigen::Vector3d z = (target - eye).normalized();
  Eigen::Vector3d x = (-up).cross(z);  // x = y × z with y (image down) ~ -up
  if (x.norm() < 1e-12) throw InvalidInput("[tbsp::Camera::lookAt] camera '" + name + "': up is parallel to the view direction");
  x.normalize();
  const Eigen::Vector3d y = z.cross(x);
  Eigen::Matrix3d R;
  R.row(0) = x.transpose();
  R.row(1) = y.transpose();
  R.row(2) = z.transpose();
  const double f = 0.5 * width / std::tan(0.5 * hfov);
  Eigen::Matrix3d K;
  K << f, 0, 0.5 * (width - 1), 0, f, 0.5 * (height - 1), 0, 0, 1;
  return Camera(std::move(name), width, height, K, R, -R * eye);
}

Eigen::Vector3d triangulate(const std::vector<Camera>& cams, const std::vector<Eigen::Vector2d>& px) {
  if (cams.size() != px.size())
    throw InvalidInput("[tbsp::triangulate] " + std::to_string(cams.size()) + " cameras but " +
                       std::to_string(px.size()) + " pixels; give one pixel per camera");
  if (cams.size() < 2) throw InvalidInput("[tbsp::triangulate] needs at least two views");
  // DLT on undistorted normalised coordinates (uses [R|t] only, well conditioned).
  Eigen::MatrixXd A(2 * cams.size(), 4);
  for (std::size_t i = 0; i < cams.size(); ++i) {
    const Camera& c = cams[i];
    const Eigen::Matrix3d& K = c.K();
    const double yn = (px[i].y() - K(1, 2)) / K(1, 1);
    const double xn = (px[i].x() - K(0, 2) - K(0, 1) * yn) / K(0, 0);
    const Eigen::Vector2d u = c.undistortNormalized({xn, yn});
    Matrix34d Rt;
    Rt.leftCols<3>() = c.R();
    Rt.col(3) = c.t();
    A.row(2 * i) = u.x() * Rt.row(2) - Rt.row(0);
    A.row(2 * i + 1) = u.y() * Rt.row(2) - Rt.row(1);
  }
  Eigen::JacobiSVD<Eigen::MatrixXd> svd(A, Eigen::ComputeFullV);
  Eigen::Vector4d Xh = svd.matrixV().col(3);
  Eigen::Vector3d X = Xh.head<3>() / Xh(3);
  // Gauss-Newton refinement on pixel reprojection error.
  for (int it = 0; it < 10; ++it) {
    Eigen::MatrixXd Jm(2 * cams.size(), 3);
    Eigen::VectorXd r(2 * cams.size());
    for (std::size_t i = 0; i < cams.size(); ++i) {
      const Eigen::Vector2d p0 = cams[i].project(X);
      r.segment<2>(2 * i) = p0 - px[i];
      const double h = 1e-6 * std::max(1.0, X.norm());
      for (int d = 0; d < 3; ++d) {
        Eigen::Vector3d Xp = X;
        Xp(d) += h;
        Jm.block<2, 1>(2 * i, d) = (cams[i].project(Xp) - p0) / h;
      }
    }
    const Eigen::Vector3d dx = (Jm.transpose() * Jm).ldlt().solve(-Jm.transpose() * r);
    if (!dx.allFinite()) break;
    X += dx;
    if (dx.norm() < 1e-12 * std::max(1.0, X.norm())) break;
  }
  return X;
}

double reprojection_rms(const std::vector<Camera>& cams, const std::vector<Eigen::Vector2d>& px,
                        const Eigen::Vector3d& X) {
  double s = 0;
  for (std::size_t i = 0; i < cams.size(); ++i) s += (cams[i].project(X) - px[i]).squaredNorm();
  return cams.empty() ? 0.0 : std::sqrt(s / cams.size());
}

}  // namespace tbsp
