#pragma once
// Returns of objects that move: people walking ahead of the robot or behind it at its pace, a
// trolley it pushes, parts of the robot in the laser's view, people crossing its path. Those that
// keep their place in the robot's frame are, to scan matching, the world standing still around a
// robot that does not move: they pull every match towards no motion. The static world moves
// through the robot's frame as the odometry says; these do not.

#include <cstddef>
#include <deque>
#include <numbers>
#include <optional>
#include <vector>

#include "lidar2d/core/frame.hpp"
#include "lidar2d/core/se2.hpp"
#include "lidar2d/slam/slam_options.hpp"

namespace lidar2d::slam::internal {

/// Finds, scan by scan, the small objects that moved, against the latest earlier scan the odometry
/// puts kBaselineM to kMaxBaselineM behind (turned by kMaxTurnRad at most), and leaves them out.
///
/// A scan's valid returns under `max_range_m` are cut into objects where consecutive returns lie
/// farther apart than kGapM plus kGapBeams beam spacings at their range (the spacings of every beam
/// between them: beams that read nothing usable in a wall do not cut it into objects), and at every
/// beam that read its range max (free space). An object of kMinReturns
/// or more, at most kMaxObjectM across (a person, a chair, a post: not a wall), not cut off by the
/// field of view's ends or by a nearer return beside it (how far it goes on is unknown there), is
/// judged with the odometry's heading taken to err by up to kHeadingRad + kHeadingRadPerM per metre
/// + kHeadingPerTurn of the turn over the baseline: where it would have stood is known to within
/// kStaticM plus that angle's arc at its range (`static_m`), and must lie `static_m` + kSameM or
/// more from where it is (else the two cannot be told apart). It moved when fewer than half of its
/// returns lie within `static_m` of the earlier scan's returns where a standing object would have
/// been, and either
/// - three quarters of its returns lie within kSameM of the earlier scan's returns in the robot's
///   frame as they are, and the earlier scan could have seen it standing (inView: a standing
///   object coming into range matches something else there as often as not): it moved with the
///   robot; or
/// - it is kMinWalkerM across or more and more than half of its returns stand where the earlier
///   scan saw through (seenThrough): it walked into space that scan saw empty (a person crossing).
/// Only with odometry: without it there is no motion to compare with; nor across a gap in the log
/// (more than SlamOptions::time_gap_s between frames, or time going backwards): the odometry may
/// not know where the robot was carried meanwhile. A robot standing still or
/// turning in place never reaches the baseline and nothing is left out; keyframes farther apart
/// than kMaxBaselineM are left whole (the odometry's error over such a step hides where a standing
/// object would be).
class MovingObjectFilter {
 public:
  static constexpr double kBaselineM = 0.5;
  static constexpr double kMaxBaselineM = 0.75;
  static constexpr double kMaxTurnRad = 20.0 * std::numbers::pi / 180.0;
  static constexpr std::size_t kMinReturns = 3;
  static constexpr double kGapM = 0.2;
  static constexpr double kGapBeams = 3.0;
  static constexpr double kMaxObjectM = 0.8;
  static constexpr double kMinWalkerM = 0.1;
  static constexpr double kSameM = 0.1;
  static constexpr double kStaticM = 0.2;

  explicit MovingObjectFilter(const SlamOptions& opt) : opt_(opt) {}

  /// `f` with the returns of the objects that moved marked invalid (NaN) in `out`, and their count;
  /// 0 (and `out` untouched) when none did. Frames in log order.
  std::size_t filter(const Frame& f, Frame& out);

 private:
  struct Past {
    SE2 T_odom_robot;
    Points2 points;  // robot frame, every valid return under max_range_m
    LaserScan scan;
    SE2 T_robot_laser;
  };
  static constexpr std::size_t kMaxKept = 256;  // earlier scans kept at most (about 30 KB each)
  static constexpr double kThroughMarginM = 0.3;
  static constexpr double kThroughAcrossM = 0.15;
  /// What the odometry's heading may be off by over the baseline: kHeadingRad plus kHeadingRadPerM
  /// per metre and kHeadingPerTurn of the turn (twice the realistic odometry of `lidar2d perturb`).
  static constexpr double kHeadingRad = std::numbers::pi / 180.0;
  static constexpr double kHeadingRadPerM = std::numbers::pi / 180.0;
  static constexpr double kHeadingPerTurn = 0.05;
  /// Where `p_base` (the robot frame of `base`) lies for `base`'s laser: its range and the beams
  /// within `heading_rad` (or kThroughAcrossM across) of its bearing; nullopt when they reach beyond
  /// the field of view, or the range is beyond what `base` reads (less kThroughMarginM).
  struct View {
    double range_m = 0.0;
    std::size_t first_beam = 0, last_beam = 0;
  };
  std::optional<View> inView(const Past& base, const Eigen::Vector2d& p_base, double heading_rad) const;
  /// Whether every beam of inView went at least kThroughMarginM past `p_base`, or read no return.
  bool seenThrough(const Past& base, const Eigen::Vector2d& p_base, double heading_rad) const;
  const SlamOptions& opt_;
  std::deque<Past> past_;            // oldest first; the oldest is the latest at least kBaselineM behind
  std::optional<double> last_time_;  // the previous frame's time
};

}  // namespace lidar2d::slam::internal
