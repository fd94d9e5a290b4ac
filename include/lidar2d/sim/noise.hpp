#pragma once
/// @file
/// Seeded random numbers and the odometry noise model shared by the simulator and `perturb`.
///
/// Results depend only on the seed, never on the standard library: uniform and Gaussian variates are
/// computed here from the raw output of std::mt19937_64 (whose sequence the C++ standard fixes),
/// not with std::uniform_real_distribution / std::normal_distribution (implementation-defined).

#include <cstdint>
#include <random>

#include "lidar2d/core/se2.hpp"

namespace lidar2d::sim {

/// Deterministic random source.
class Rng {
 public:
  explicit Rng(std::uint64_t seed) : engine_(seed) {}
  /// Uniform in [0, 1), 53 random bits.
  double uniform() { return static_cast<double>(engine_() >> 11) * 0x1.0p-53; }
  /// Standard normal N(0, 1) by the Box-Muller transform; values come in pairs, the second is kept
  /// for the next call.
  double gaussian();
  /// N(0, sigma^2). Always consumes the same random numbers, also when sigma is 0, so that turning
  /// one noise source off does not change the others.
  double gaussian(double sigma) { return sigma * gaussian(); }
  std::mt19937_64& engine() { return engine_; }

 private:
  std::mt19937_64 engine_;
  bool has_spare_ = false;
  double spare_ = 0.0;
};

/// Odometry noise: each step's relative motion `T_prev_cur` (robot frame, from the truth) is read as
///   `T_prev_cur_odom = SE2(dx * (1 + scale_bias), dy * (1 + scale_bias), dtheta + heading_bias_per_m * d)
///                      * SE2(n_x, n_y, n_theta)`
/// with d = |(dx, dy)| and independent zero-mean Gaussians n of standard deviations
///   sigma_x = sigma_x_m + trans_sigma_per_m * d
///   sigma_y = sigma_y_m + trans_sigma_per_m * d
///   sigma_theta = sigma_theta_rad + rot_sigma_per_rad * |dtheta| + rot_sigma_per_m * d.
/// Integrating the noisy steps makes the odometry drift: the random part grows like a random walk,
/// the bias part linearly with the distance travelled. The constant terms are per step, so their
/// effect depends on the scan rate (they are the floor that keeps a stationary robot's odometry
/// uncertain). Defaults: a wheeled indoor robot driving ~0.8 m/s with scans at 10 Hz, which drifts
/// by roughly 1-2 % of the distance and a few degrees per 100 m.
struct OdometryNoise {
  double sigma_x_m = 0.002;            ///< constant std of the forward error per step [m]
  double sigma_y_m = 0.001;            ///< constant std of the lateral error per step [m]
  double sigma_theta_rad = 0.001;      ///< constant std of the heading error per step [rad]
  double trans_sigma_per_m = 0.02;     ///< extra std of the x and y error per metre moved [m/m]
  double rot_sigma_per_rad = 0.02;     ///< extra heading std per radian turned [rad/rad]
  double rot_sigma_per_m = 0.005;      ///< extra heading std per metre moved [rad/m]
  double scale_bias = 0.005;           ///< systematic relative error of the distance (0.005: reads 0.5 % long) []
  double heading_bias_per_m = 0.002;   ///< systematic heading drift per metre moved [rad/m]

  /// No noise at all: odometry equals the true relative motion.
  static OdometryNoise none() { return {0, 0, 0, 0, 0, 0, 0, 0}; }
  /// Constant per-step noise N(0, diag(sx^2, sy^2, sth^2)) and nothing else (what `perturb` uses).
  static OdometryNoise constant(double sx_m, double sy_m, double sth_rad) { return {sx_m, sy_m, sth_rad, 0, 0, 0, 0, 0}; }
  /// True when every term is zero.
  bool isZero() const;
  /// Throws `lidar2d::Error` (kInvalidArgument) when a term is negative or not finite.
  void validate() const;
};

/// One odometry step: the noisy reading of the true relative motion `T_prev_cur` (see
/// `OdometryNoise`). Always draws three Gaussians from `rng`.
SE2 noisyOdometryStep(const SE2& T_prev_cur, const OdometryNoise& noise, Rng& rng);

}  // namespace lidar2d::sim
