#include "lidar2d/core/se2.hpp"

namespace lidar2d {
namespace {

// A(w) = sin(w)/w and B(w) = (1 - cos(w))/w, the entries of the SE(2) "V" matrix
// V = A*I + B*J (J = 90 degree rotation); Taylor series near 0 avoid 0/0.
void vCoefficients(double w, double& a, double& b) {
  if (std::abs(w) < 1e-6) {
    const double w2 = w * w;
    a = 1.0 - w2 / 6.0;
    b = w / 2.0 - w * w2 / 24.0;
  } else {
    const double h = std::sin(0.5 * w);
    a = std::sin(w) / w;
    b = 2.0 * h * h / w;  // = (1 - cos w) / w without the cancellation of 1 - cos w
  }
}

}  // namespace

SE2 SE2::exp(const Vector3& xi) {
  double a = 0, b = 0;
  vCoefficients(xi.z(), a, b);
  // t = V * rho with V = [[a, -b], [b, a]].
  return {a * xi.x() - b * xi.y(), b * xi.x() + a * xi.y(), xi.z()};
}

SE2::Vector3 SE2::log() const {
  double a = 0, b = 0;
  vCoefficients(theta_, a, b);
  // V^-1 = (a*I - b*J) / (a^2 + b^2), since I and J commute and J^2 = -I.
  const double d = a * a + b * b;
  return {(a * x_ + b * y_) / d, (-b * x_ + a * y_) / d, theta_};
}

SE2::Matrix3 SE2::expJacobian(const Vector3& xi) {
  const double w = xi.z();
  double a = 0, b = 0, da = 0, db = 0;
  vCoefficients(w, a, b);
  if (std::abs(w) < 1e-2) {
    // Derivatives of the Taylor series of A and B (the closed forms cancel badly near 0).
    const double w2 = w * w;
    da = -w / 3.0 + w * w2 / 30.0;
    db = 0.5 - w2 / 8.0 + w2 * w2 / 144.0;
  } else {
    da = (w * std::cos(w) - std::sin(w)) / (w * w);
    db = (w * std::sin(w) - (1.0 - std::cos(w))) / (w * w);
  }
  Matrix3 j;
  j << a, -b, da * xi.x() - db * xi.y(),  //
      b, a, db * xi.x() + da * xi.y(),    //
      0, 0, 1;
  return j;
}

SE2 interpolate(const SE2& a, const SE2& b, double f) {
  return {a.x() + f * (b.x() - a.x()), a.y() + f * (b.y() - a.y()),
          a.theta() + f * angleDiff(b.theta(), a.theta())};
}

}  // namespace lidar2d
