#pragma once
/// @file
/// Smooth robot paths through waypoints, sampled at the scan rate.
///
/// The waypoints are joined by straight lines; each corner is replaced by a circular arc (a fillet)
/// tangent to both lines, so the heading is continuous and the robot drives at a constant speed.
/// Corners sharper than `max_fillet_turn_rad` (e.g. a U-turn at a dead end) become a turn on the
/// spot at `turn_rate_radps` instead. The heading follows the direction of travel.

#include <Eigen/Core>
#include <cstddef>
#include <vector>

#include "lidar2d/core/se2.hpp"

namespace lidar2d::sim {

/// A pose of the robot at a time.
struct TimedPose {
  double time_s = 0.0;  ///< [s]
  SE2 T_world_robot;    ///< [m, m, rad]
};

struct PathOptions {
  double speed_mps = 0.8;             ///< driving speed along lines and arcs [m/s], > 0
  double turn_rate_radps = 1.0;       ///< rotation speed of turns on the spot [rad/s], > 0
  double turn_radius_m = 0.5;         ///< radius of corner arcs [m] (smaller where the lines are short), > 0
  double max_fillet_turn_rad = 2.0;   ///< sharper corners turn on the spot [rad]
  double rate_hz = 10.0;              ///< sampling (scan) rate [Hz], > 0
  double start_time_s = 0.0;          ///< time of the first sample [s]
};

/// Samples the path through `waypoints` [m] every 1 / rate_hz seconds, starting at the first
/// waypoint facing the second. `scans` = 0 samples the whole path once (the last sample is at or
/// before its end). `scans` > 0 gives exactly that many samples; when the path is too short for
/// them, it is driven back and forth (turning on the spot at each end) as often as needed.
/// Consecutive duplicate waypoints are ignored. Throws `lidar2d::Error` (kInvalidArgument) for
/// non-finite waypoints, fewer than two distinct waypoints, or bad options.
std::vector<TimedPose> samplePath(const std::vector<Eigen::Vector2d>& waypoints, const PathOptions& options,
                                  std::size_t scans = 0);

/// Length of the polyline through the poses' positions [m].
double pathLength(const std::vector<TimedPose>& poses);

}  // namespace lidar2d::sim
