#pragma once
// SLAM's front end: each scan matched against a local map of the last few nodes, in the drift-prone
// "local" frame, from a prediction (odometry when present and sane, else constant velocity).

#include <Eigen/Core>
#include <array>
#include <cstddef>
#include <deque>
#include <memory>
#include <optional>
#include <vector>

#include "src/slam/internal/state.hpp"

namespace lidar2d::slam::internal {

class FrontEnd {
 public:
  /// Reads the options and settings of `s`, and its nodes when the local map is rebuilt; records
  /// events and counters there.
  explicit FrontEnd(SlamState& s)
      : s_(s), opt(s.opt), icp(s.match.icp), local_lf(s.match.local_lf), fallback(s.match.fallback) {}
  FrontEnd(const FrontEnd&) = delete;
  FrontEnd& operator=(const FrontEnd&) = delete;

  /// The motion predicted since the previous scan.
  struct Prediction {
    SE2 delta;                  ///< T_prev_cur (identity for the first scan)
    bool odom_trusted = false;  ///< from odometry (else constant velocity)
    bool time_ok = true;        ///< no gap and time not going backwards since the previous scan
  };
  /// The scan's match.
  struct Tracked {
    SE2 T_local_robot;  ///< the match, or the prediction when unmatched
    bool matched = false;
    bool degenerate = false;
    Eigen::Vector2d dir = Eigen::Vector2d::Zero();  ///< local frame, the direction the scan could not pin
    bool restart = false;                           ///< tracking lost: the local map restarts at this scan
  };

  /// True once a scan was remembered.
  bool started() const { return have_prev; }
  /// Where the first scan anchors the local frame: its odometry pose (so the map lines up with
  /// it), or the origin.
  SE2 firstPose(const Frame& f) const;
  /// The prediction for `f`; records events on time and odometry.
  Prediction predict(const Frame& f);
  /// Matches `pts` (robot frame, voxel-filtered) of `f`, a scan after the first; counts matched,
  /// unmatched, degenerate scans and correlative fallbacks, and records failures as events.
  Tracked track(const Frame& f, const Points2& pts, const Prediction& p);
  /// Node `n` was added (`restart`: the local map starts again from it): rebuilds the local map
  /// from the last local_map_nodes nodes.
  void addNode(std::size_t n, bool restart);
  /// Remembers scan `f` at `T_local` for the next prediction; `first`: the first scan (no step),
  /// `time_ok` as predicted.
  void remember(const Frame& f, const SE2& T_local, bool first, bool time_ok);

 private:
  static constexpr std::size_t kVelocitySteps = 5;     // steps behind the constant-velocity prediction
  static constexpr double kConfirmExplained = 0.9;     // a match explaining this much confirms its start
  static constexpr double kEarlierWithOdometry = 0.8;  // see frontEndMatch's `earlier`
  // Which earlier scans' poses are starting points (scans back, ascending).
  static constexpr std::array<std::size_t, 4> kEarlierBack{2, 4, 8, 16};

  void rebuildLocalMap();
  SE2 velocityStep() const;
  std::optional<SE2> frontEndMatch(const Points2& pts, const SE2& T_pred, const std::vector<SE2>& alternatives,
                                   const std::vector<SE2>& earlier, double earlier_below, bool& degenerate,
                                   Eigen::Vector2d& dir, bool& used_fallback);

  SlamState& s_;
  const SlamOptions& opt;
  const registration::IcpOptions& icp;
  const registration::LikelihoodFieldOptions& local_lf;
  const registration::CorrelativeOptions& fallback;

  bool have_prev = false;
  SE2 T_local_prev;
  std::optional<SE2> odom_prev;
  bool odometry_seen = false, odometry_missing = false;
  std::size_t odometry_missing_count = 0;
  double time_prev = 0.0;
  // The front end's last few steps (robot frame), oldest first; emptied across gaps. The
  // constant-velocity prediction is their component-wise median (`velocityStep`).
  std::deque<SE2> recent_steps;
  std::deque<SE2> recent_poses;  // the front end's poses of the last kEarlierBack.back() scans, oldest first
  int consecutive_failures = 0;
  std::deque<std::size_t> local_nodes;
  std::unique_ptr<registration::IcpTarget> local_target;
  std::unique_ptr<registration::LikelihoodField> local_field;  // front_end_likelihood_field
  Points2 local_points;
  std::unique_ptr<registration::CorrelativeGrid> local_grid;
};

}  // namespace lidar2d::slam::internal
