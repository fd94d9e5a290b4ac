#pragma once
// Closed-form eigen-decomposition of a symmetric 2x2 matrix [[a, b], [b, c]] (a scatter or
// information matrix). Library-private: modules that may use geometry include it as
// "src/geometry/eigen2.hpp".

#include <Eigen/Core>
#include <cmath>
#include <numbers>

#include "lidar2d/core/se2.hpp"

namespace lidar2d::geometry {

// Eigenvalues lo <= hi and the axis angle of the eigenvector of lo, in (-pi/2, pi/2] [rad].
struct SymEigen2Angle {
  double lo = 0.0, hi = 0.0, lo_angle = 0.0;
};
inline SymEigen2Angle symEigen2Angle(double a, double b, double c) {
  const double m = 0.5 * (a + c);
  const double d = std::hypot(0.5 * (a - c), b);
  const double hi_angle = 0.5 * std::atan2(2.0 * b, a - c);
  return {m - d, m + d, 0.5 * wrapAngle(2.0 * (hi_angle + 0.5 * std::numbers::pi))};
}

// The same without trigonometry (hot loops): eigenvalues lo <= hi and the unit eigenvector of lo
// (the x axis for a multiple of the identity, whose every vector is one).
struct SymEigen2 {
  double lo = 0.0, hi = 0.0;
  Eigen::Vector2d lo_vec = Eigen::Vector2d::UnitX();
};
inline SymEigen2 symEigen2(double a, double b, double c) {
  const double m = 0.5 * (a + c);
  const double h = 0.5 * (a - c);
  const double d = std::sqrt(h * h + b * b);
  SymEigen2 e{m - d, m + d, Eigen::Vector2d::UnitX()};
  // (A - lo I) v = 0: v = (b, lo - a) or (lo - c, b); take the longer for accuracy.
  const Eigen::Vector2d v1(b, e.lo - a), v2(e.lo - c, b);
  const Eigen::Vector2d& v = v1.squaredNorm() >= v2.squaredNorm() ? v1 : v2;
  const double n = v.norm();
  if (n > 0.0)
    e.lo_vec = v / n;
  else
    e.lo_vec = a <= c ? Eigen::Vector2d::UnitX() : Eigen::Vector2d::UnitY();  // isotropic or diagonal
  return e;
}

}  // namespace lidar2d::geometry
