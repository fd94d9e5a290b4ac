#pragma once
/// @file
/// Scoring one-scan global localization over a log: the success / precision tally against the
/// log's truth and the consistency of consecutive answers with odometry (the figures of
/// `lidar2d localize --json` and the localization benchmark).

#include <cstddef>
#include <numbers>
#include <optional>

#include "lidar2d/core/se2.hpp"

namespace lidar2d::eval {

/// An estimate is right when its error pose is within both bounds (inclusive).
struct PoseTolerance {
  double max_translation_m = 0.3;                           ///< [m]
  double max_rotation_rad = 5.0 * std::numbers::pi / 180.0;  ///< [rad]

  /// Whether the error pose `T_error` (e.g. `T_truth.inverse() * T_estimate`) is within both bounds.
  bool accepts(const SE2& T_error) const;
};

/// Tally of localized scans, fed in log order with `add`.
struct LocalizationTally {
  PoseTolerance tolerance;
  std::size_t scans = 0;       ///< scans added
  std::size_t answered = 0;    ///< scans with a pose
  std::size_t declined = 0;    ///< scans without one
  std::size_t with_truth = 0;  ///< scans added with a truth pose
  std::size_t correct = 0;     ///< answered scans within `tolerance` of their truth
  /// Pairs of consecutive scans, both answered and both with odometry, and how many of them have a
  /// relative pose within `tolerance` of the odometry's.
  std::size_t odometry_pairs = 0;
  std::size_t odometry_consistent = 0;

  /// One scan: its estimate `T_world_robot` (std::nullopt when declined), its truth and its
  /// odometry pose when known.
  void add(const std::optional<SE2>& T_world_robot, const std::optional<SE2>& T_world_robot_truth,
           const std::optional<SE2>& T_odom_robot);

  double successRate() const;  ///< correct / with_truth (NaN without truth)
  double precision() const;    ///< correct / answered (NaN when nothing was answered)
  double odometryConsistency() const;  ///< odometry_consistent / odometry_pairs (NaN without pairs)

 private:
  std::optional<SE2> prev_pose_;
  std::optional<SE2> prev_odom_;
};

}  // namespace lidar2d::eval
