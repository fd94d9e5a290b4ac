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
  LaserScan scan;                 ///< ranges in the laser frame
  std::optional<SE2> T_odom_robot;   ///< wheel odometry at `time`, in the odometry frame, if any
  std::optional<SE2> T_world_robot;  ///< ground-truth pose at `time`, if the log carries one
  SE2 T_robot_laser;              ///< laser mounting pose on the robot (identity if unknown)
};

}  // namespace lidar2d
