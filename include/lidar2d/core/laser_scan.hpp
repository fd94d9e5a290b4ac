#pragma once
/// @file
/// One sweep of a 2D laser scanner, in the laser's own frame (x forward, y left, z up).

#include <Eigen/Core>
#include <cstddef>
#include <cstdint>
#include <vector>

#include "lidar2d/core/se2.hpp"

namespace lidar2d {

/// Points of a scan as a plain vector of 2D points [m].
using Points2 = std::vector<Eigen::Vector2d>;

/// Raw fields of a scan, as read from a log. Turned into a checked `LaserScan` by `LaserScan::create`.
struct LaserScanFields {
  double time = 0.0;              ///< acquisition time [s]
  double angle_min = 0.0;         ///< angle of beam 0 in the laser frame [rad]
  double angle_increment = 0.0;   ///< angle between consecutive beams [rad], non-zero
  double range_min = 0.0;         ///< ranges <= range_min are invalid [m], >= 0
  double range_max = 0.0;         ///< ranges >= range_max are invalid ("no return") [m], > range_min
  std::vector<double> ranges;     ///< one per beam [m]; NaN/inf/out-of-limits mark invalid beams
  std::vector<double> intensities;  ///< empty, or one per beam (unitless)
};

/// A checked laser scan. Invariants (checked once by `create`): at least one beam, finite
/// `angle_min`, finite non-zero `angle_increment` whose total span is at most 2*pi plus one step,
/// finite `0 <= range_min < range_max`, intensities empty or one per beam. Individual beams may be
/// invalid (NaN, +-inf, <= range_min or >= range_max); validity is computed once at creation.
class LaserScan {
 public:
  /// Upper bound on the number of beams a scan may have; larger counts are reported as bad input
  /// (real scanners have at most a few thousand beams per sweep).
  static constexpr std::size_t kMaxBeams = 1u << 20;

  LaserScan() = default;
  /// Checks the invariants above and throws `lidar2d::Error` (kind kBadInput, field named) on
  /// violation.
  static LaserScan create(LaserScanFields fields);

  double time() const { return f_.time; }
  void setTime(double t) { f_.time = t; }
  double angleMin() const { return f_.angle_min; }
  double angleIncrement() const { return f_.angle_increment; }
  /// Angle of the last beam [rad].
  double angleMax() const { return angle(size() - 1); }
  double rangeMin() const { return f_.range_min; }
  double rangeMax() const { return f_.range_max; }
  std::size_t size() const { return f_.ranges.size(); }
  bool empty() const { return f_.ranges.empty(); }
  const std::vector<double>& ranges() const { return f_.ranges; }
  const std::vector<double>& intensities() const { return f_.intensities; }
  bool hasIntensities() const { return !f_.intensities.empty(); }
  const LaserScanFields& fields() const { return f_; }

  /// Angle of beam i in the laser frame [rad] (not wrapped).
  double angle(std::size_t i) const { return f_.angle_min + static_cast<double>(i) * f_.angle_increment; }
  /// True when beam i has a usable return: finite and strictly inside (range_min, range_max).
  bool isValid(std::size_t i) const { return valid_[i] != 0; }
  std::size_t numValid() const { return num_valid_; }
  /// Field of view covered by the beams, |n * increment| [rad].
  double fieldOfView() const;

  /// Endpoints of the valid beams in the laser frame [m], in beam order.
  Points2 toPoints() const;
  /// Endpoints of the valid beams in the robot frame: `T_robot_laser * p_laser`.
  Points2 toPoints(const SE2& T_robot_laser) const;
  /// Indices of the valid beams, matching the order of `toPoints()`.
  std::vector<std::size_t> validIndices() const;

 private:
  LaserScanFields f_;
  std::vector<std::uint8_t> valid_;
  std::size_t num_valid_ = 0;
};

}  // namespace lidar2d
