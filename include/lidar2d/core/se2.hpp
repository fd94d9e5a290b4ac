#pragma once
/// @file
/// The one rigid-body pose type of lidar2d.
///
/// Conventions used everywhere in the project:
/// - `T_a_b` is the pose of frame b expressed in frame a; it maps a point from frame b to frame a:
///   `p_a = T_a_b * p_b`.
/// - Poses compose left to right along the frame names: `T_a_c = T_a_b * T_b_c`.
/// - Angles are in radians and wrapped to (-pi, pi].
/// - The tangent vector (Lie algebra) is `xi = (rho_x, rho_y, omega)`, translation part first,
///   and `exp(xi)` integrates the constant twist xi for unit time (Barfoot, "State Estimation for
///   Robotics", section 7.1.9, specialised to the plane).
/// - Pose parameters `(x, y, theta)` are what the Jacobians below differentiate with respect to.

#include <Eigen/Core>
#include <cmath>
#include <numbers>

namespace lidar2d {

/// Wraps an angle to (-pi, pi]. Non-finite input is returned unchanged (NaN stays NaN).
inline double wrapAngle(double a) {
  if (!std::isfinite(a)) return a;
  constexpr double kPi = std::numbers::pi;
  if (a > -kPi && a <= kPi) return a;
  a = std::remainder(a, 2.0 * kPi);  // in [-pi, pi]
  if (a <= -kPi) a += 2.0 * kPi;
  return a;
}

/// Signed smallest difference a - b of two angles, in (-pi, pi].
inline double angleDiff(double a, double b) { return wrapAngle(a - b); }

/// A rigid transform of the plane (rotation theta, then translation (x, y)).
class SE2 {
 public:
  using Vector3 = Eigen::Vector3d;
  using Matrix3 = Eigen::Matrix3d;

  /// Identity.
  SE2() = default;
  /// From parameters; theta is wrapped to (-pi, pi].
  SE2(double x, double y, double theta)
      : x_(x), y_(y), theta_(wrapAngle(theta)), c_(std::cos(theta_)), s_(std::sin(theta_)) {}
  SE2(const Eigen::Vector2d& t, double theta) : SE2(t.x(), t.y(), theta) {}

  static SE2 identity() { return {}; }
  /// From `(x, y, theta)`.
  static SE2 fromVector(const Vector3& v) { return {v.x(), v.y(), v.z()}; }

  double x() const { return x_; }
  double y() const { return y_; }
  double theta() const { return theta_; }
  Eigen::Vector2d translation() const { return {x_, y_}; }
  /// `(x, y, theta)`.
  Vector3 vector() const { return {x_, y_, theta_}; }
  Eigen::Matrix2d rotation() const {
    Eigen::Matrix2d r;
    r << c_, -s_, s_, c_;
    return r;
  }
  /// Homogeneous 3x3 matrix.
  Matrix3 matrix() const {
    Matrix3 m;
    m << c_, -s_, x_, s_, c_, y_, 0, 0, 1;
    return m;
  }
  /// True when all parameters are finite.
  bool isFinite() const { return std::isfinite(x_) && std::isfinite(y_) && std::isfinite(theta_); }

  /// Composition: `T_a_c = T_a_b * T_b_c`.
  SE2 operator*(const SE2& o) const {
    return {x_ + c_ * o.x_ - s_ * o.y_, y_ + s_ * o.x_ + c_ * o.y_, theta_ + o.theta_};
  }
  SE2& operator*=(const SE2& o) { return *this = *this * o; }
  /// Applies the transform to a point: `p_a = T_a_b * p_b`.
  Eigen::Vector2d operator*(const Eigen::Vector2d& p) const {
    return {x_ + c_ * p.x() - s_ * p.y(), y_ + s_ * p.x() + c_ * p.y()};
  }
  /// `T_b_a` for `T_a_b`.
  SE2 inverse() const { return {-c_ * x_ - s_ * y_, s_ * x_ - c_ * y_, -theta_}; }

  /// Exponential map of the tangent vector `xi = (rho_x, rho_y, omega)`.
  static SE2 exp(const Vector3& xi);
  /// Logarithm, the inverse of `exp` for omega in (-pi, pi].
  Vector3 log() const;
  /// Adjoint: `T * exp(xi) * T.inverse() == exp(T.adjoint() * xi)`.
  Matrix3 adjoint() const {
    Matrix3 a;
    a << c_, -s_, y_, s_, c_, -x_, 0, 0, 1;
    return a;
  }

  /// d(T * p) / d(x, y, theta): the 2x3 Jacobian of a transformed point w.r.t. this pose's
  /// parameters.
  Eigen::Matrix<double, 2, 3> pointJacobian(const Eigen::Vector2d& p) const {
    Eigen::Matrix<double, 2, 3> j;
    j << 1, 0, -s_ * p.x() - c_ * p.y(), 0, 1, c_ * p.x() - s_ * p.y();
    return j;
  }
  /// d(params of this * o) / d(params of this).
  Matrix3 composeJacobianLeft(const SE2& o) const {
    Matrix3 j = Matrix3::Identity();
    j(0, 2) = -s_ * o.x_ - c_ * o.y_;
    j(1, 2) = c_ * o.x_ - s_ * o.y_;
    return j;
  }
  /// d(params of this * o) / d(params of o).
  Matrix3 composeJacobianRight() const {
    Matrix3 j = Matrix3::Identity();
    j.topLeftCorner<2, 2>() = rotation();
    return j;
  }
  /// d(params of this->inverse()) / d(params of this).
  Matrix3 inverseJacobian() const {
    Matrix3 j;
    j << -c_, -s_, s_ * x_ - c_ * y_,  //
        s_, -c_, c_ * x_ + s_ * y_,     //
        0, 0, -1;
    return j;
  }
  /// d(params of exp(xi)) / d(xi).
  static Matrix3 expJacobian(const Vector3& xi);

  /// True when translations differ by at most `tol_m` and angles by at most `tol_rad`.
  bool isApprox(const SE2& o, double tol_m = 1e-9, double tol_rad = 1e-9) const {
    return std::hypot(x_ - o.x_, y_ - o.y_) <= tol_m && std::abs(angleDiff(theta_, o.theta_)) <= tol_rad;
  }

 private:
  double x_ = 0.0;
  double y_ = 0.0;
  double theta_ = 0.0;
  double c_ = 1.0;  // cached cos(theta_)
  double s_ = 0.0;  // cached sin(theta_)
};

/// Linear interpolation of two poses at fraction `f` in [0, 1] (translation linear, angle along the
/// shorter arc). Used to interpolate odometry at a scan's timestamp.
SE2 interpolate(const SE2& a, const SE2& b, double f);

}  // namespace lidar2d
