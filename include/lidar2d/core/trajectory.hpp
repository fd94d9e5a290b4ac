#pragma once
/// @file
/// Timestamped poses as plain types: trajectories, ground-truth relations and relative poses
/// between scans, and the nearest-time lookup over a trajectory. io/trajectory.hpp reads and writes
/// them as files; eval compares them; mapping places scans with them.

#include <cstddef>
#include <optional>
#include <vector>

#include "lidar2d/core/se2.hpp"

namespace lidar2d {

/// A pose with its timestamp.
struct StampedPose {
  double time = 0.0;  ///< [s]
  SE2 pose;           ///< e.g. T_world_robot
};
using Trajectory = std::vector<StampedPose>;

/// Nearest-timestamp lookup by binary search over sorted times; indices refer to the original order.
class TimeIndex {
 public:
  explicit TimeIndex(const Trajectory& trajectory);
  explicit TimeIndex(const std::vector<double>& times);

  /// Original index of the pose whose time is nearest to `t` with |time - t| <= max_dt, or nullopt.
  /// Ties (equal distance before and after, or repeated times) go to the earlier time, then to the
  /// earlier pose in the original order.
  std::optional<std::size_t> nearest(double t, double max_dt) const;
  /// True when at least two poses share a timestamp (time lookups are then ambiguous).
  bool hasRepeatedTimes() const { return repeated_; }
  std::size_t size() const { return times_.size(); }

 private:
  std::vector<double> times_;        // sorted
  std::vector<std::size_t> order_;   // order_[k] = original index of times_[k]
  bool repeated_ = false;
};

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
