#pragma once
/// @file
/// The format-independent unit every algorithm consumes: one scan with the poses known at its time.

#include <cstddef>
#include <optional>

#include "lidar2d/core/laser_scan.hpp"
#include "lidar2d/core/se2.hpp"

namespace lidar2d {

/// One laser scan and what is known about the robot at its timestamp.
struct Frame {
  std::size_t index = 0;          ///< 0-based position of the scan in its log (file order)
  double time = 0.0;              ///< scan timestamp [s], as stored in the log (may repeat or go back)
  /// Ranges in the upright laser frame (z up): as recorded, or mirrored / projected onto the
  /// robot's plane when the laser is mounted upside down or tilted (`LaserMount::project`), so
  /// `scan.toPoints(T_robot_laser)` is the scan in the robot frame whatever the mounting.
  LaserScan scan;
  std::optional<SE2> T_odom_robot;   ///< wheel odometry at `time`, in the odometry frame, if any
  std::optional<SE2> T_world_robot;  ///< ground-truth pose at `time`, if the log carries one
  SE2 T_robot_laser;              ///< pose of the upright laser frame on the robot (identity if unknown)
  bool laser_upside_down = false;  ///< the laser is mounted upside down (`scan` is already mirrored)
  double laser_tilt_rad = 0.0;     ///< tilt of the scan plane that `scan` was projected from [rad]; 0 = level
};

}  // namespace lidar2d
