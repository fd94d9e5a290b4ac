#pragma once
/// @file
/// Timestamped poses as plain types: trajectories, ground-truth relations and relative poses
/// between scans. io/trajectory.hpp reads and writes them as files; eval compares them.

#include <vector>

#include "lidar2d/core/se2.hpp"

namespace lidar2d {

/// A pose with its timestamp.
struct StampedPose {
  double time = 0.0;  ///< [s]
  SE2 pose;           ///< e.g. T_world_robot
};
using Trajectory = std::vector<StampedPose>;

/// One ground-truth relation (Kuemmerle et al. 2009): the pose of the robot at `t2` in the frame of
/// the robot at `t1`. dz, roll and pitch of the file are ignored (they are 0 in every 2D data set).
struct Relation {
  double t1 = 0.0;  ///< [s]
  double t2 = 0.0;  ///< [s]
  SE2 T_1_2;        ///< (dx, dy, dyaw) [m, m, rad]
};
using Relations = std::vector<Relation>;

/// One relative pose estimated between two scans, as written by `lidar2d match`.
struct RelativePose {
  double t_prev = 0.0;  ///< time of the previous (target) scan [s]
  double t_cur = 0.0;   ///< time of the current (source) scan [s]
  SE2 T_prev_cur;       ///< pose of the current scan's robot in the previous one's frame
  bool converged = true;    ///< the matcher's convergence flag (true when the file has no such column)
  int iterations = 0;       ///< iterations the matcher used (0 when the file has no such column)
};

}  // namespace lidar2d
