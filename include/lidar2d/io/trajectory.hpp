#pragma once
/// @file
/// Trajectory files: one pose per line.
/// - `kPlain` (lidar2d's own): `timestamp x y theta` [s, m, m, rad]; `#` starts a comment line.
/// - `kTum`: `timestamp tx ty tz qx qy qz qw` (TUM RGB-D benchmark format), z = 0, rotation about z.

#include <string>
#include <vector>

#include "lidar2d/core/se2.hpp"

namespace lidar2d::io {

/// A pose with its timestamp.
struct StampedPose {
  double time = 0.0;  ///< [s]
  SE2 pose;           ///< e.g. T_world_robot
};
using Trajectory = std::vector<StampedPose>;

enum class TrajectoryFormat { kPlain, kTum };

/// Reads a trajectory file; the format is detected per file from the number of fields (4 plain,
/// 8 TUM). Throws `lidar2d::Error` naming file, line and field on malformed or non-finite values.
Trajectory readTrajectory(const std::string& path);

/// Writes a trajectory atomically, with full precision (timestamps to microseconds or better).
void writeTrajectory(const std::string& path, const Trajectory& trajectory,
                     TrajectoryFormat format = TrajectoryFormat::kPlain);

}  // namespace lidar2d::io
