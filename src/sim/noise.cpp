#include "lidar2d/sim/noise.hpp"

#include <cmath>
#include <numbers>

#include "lidar2d/core/error.hpp"

namespace lidar2d::sim {

double Rng::gaussian() {
  if (has_spare_) {
    has_spare_ = false;
    return spare_;
  }
  // Box-Muller (Box & Muller 1958): u1 in (0, 1] so that log(u1) is finite.
  const double u1 = 1.0 - uniform();
  const double u2 = uniform();
  const double r = std::sqrt(-2.0 * std::log(u1));
  const double a = 2.0 * std::numbers::pi * u2;
  spare_ = r * std::sin(a);
  has_spare_ = true;
  return r * std::cos(a);
}

bool OdometryNoise::isZero() const {
  return sigma_x_m == 0 && sigma_y_m == 0 && sigma_theta_rad == 0 && trans_sigma_per_m == 0 &&
         rot_sigma_per_rad == 0 && rot_sigma_per_m == 0 && scale_bias == 0 && heading_bias_per_m == 0;
}

void OdometryNoise::validate() const {
  const double sigmas[] = {sigma_x_m, sigma_y_m, sigma_theta_rad, trans_sigma_per_m, rot_sigma_per_rad, rot_sigma_per_m};
  for (double s : sigmas)
    if (!std::isfinite(s) || s < 0) throw invalidArgument("odometry noise standard deviations must be finite and >= 0");
  if (!std::isfinite(scale_bias) || scale_bias <= -1 || !std::isfinite(heading_bias_per_m))
    throw invalidArgument("odometry biases must be finite and scale_bias > -1");
}

SE2 noisyOdometryStep(const SE2& T_prev_cur, const OdometryNoise& n, Rng& rng) {
  const double dx = T_prev_cur.x(), dy = T_prev_cur.y(), dth = T_prev_cur.theta();
  const double d = std::hypot(dx, dy);
  const double sx = n.sigma_x_m + n.trans_sigma_per_m * d;
  const double sy = n.sigma_y_m + n.trans_sigma_per_m * d;
  const double sth = n.sigma_theta_rad + n.rot_sigma_per_rad * std::abs(dth) + n.rot_sigma_per_m * d;
  // Draw in a fixed order (x, y, theta) so that a seed gives the same sequence everywhere.
  const double ex = rng.gaussian(sx);
  const double ey = rng.gaussian(sy);
  const double eth = rng.gaussian(sth);
  const SE2 biased(dx * (1.0 + n.scale_bias), dy * (1.0 + n.scale_bias), dth + n.heading_bias_per_m * d);
  if (ex == 0.0 && ey == 0.0 && eth == 0.0) return biased;
  return biased * SE2(ex, ey, eth);
}

}  // namespace lidar2d::sim
