#pragma once
// SLAM's motion prior: the predicted step from the previous scan to the next one, with an honest
// uncertainty. Odometry when present and plausible over the time the step took, its sigma growing
// with distance, turn and time; else constant velocity with a wide sigma growing with time. The
// front end sizes its search by the sigma and weighs a match that contradicts the prediction
// against it (FrontEnd::track).

#include <cstddef>
#include <deque>
#include <optional>
#include <string>
#include <vector>

#include "lidar2d/core/frame.hpp"
#include "lidar2d/core/se2.hpp"
#include "lidar2d/slam/slam_options.hpp"

namespace lidar2d::slam::internal {

/// Where a prediction came from.
enum class PriorSource {
  kNone,              ///< the first scan
  kOdometry,          ///< the wheel odometry's step
  kConstantVelocity,  ///< the recent steps' median (no motion across a gap)
};
const char* toString(PriorSource s);

/// The predicted step T_prev_cur and its uncertainty: independent x, y (one sigma, isotropic) and
/// theta.
struct MotionPrediction {
  SE2 delta;
  double sigma_m = 0.0;
  double sigma_rad = 0.0;
  PriorSource source = PriorSource::kNone;
  /// Odometry's step when it was present but not plausible over the time it took (a start the
  /// front end also tries, so the scan can decide); `source` is then constant velocity.
  std::optional<SE2> implausible_odometry;
  /// Constant velocity only: the sigmas come from the spread of the robot's recent steps, not from
  /// the time since the previous scan (SlamOptions::prior_velocity_spread_sigmas).
  bool from_spread = false;
  bool time_ok = true;  ///< time moved forward, without a gap, since the previous scan
  double dt = 0.0;      ///< the time the step took as used for the sigma [s] (the usual interval when unknown)

  /// The Mahalanobis distance of a step `step` (T_prev_cur) from the prediction, in sigmas.
  double distance(const SE2& step) const;
};

/// The odometry prediction of step `odo` that took `dt` seconds: its sigmas under `opt`.
MotionPrediction odometryPrediction(const SlamOptions& opt, const SE2& odo, double dt);

class MotionPrior {
 public:
  explicit MotionPrior(const SlamOptions& opt) : opt_(opt) {}

  /// The prediction for frame `f` (identity with source kNone for the first). `event` records what
  /// the prior noticed (time going backwards, gaps, odometry missing, resuming or implausible).
  template <class EventSink>
  MotionPrediction predict(const Frame& f, EventSink&& event) {
    MotionPrediction p = predictImpl(f);
    for (std::string& e : notes_) event(std::move(e));
    notes_.clear();
    return p;
  }
  /// Frame `f` ended at `step` from the previous scan (front-end estimate; ignored for the first).
  void remember(const Frame& f, const SE2& step, bool first, bool time_ok);
  /// The usual interval between scans so far (median of the recent ones, repeated stamps as 0) [s], 0
  /// before any.
  double usualInterval() const;

 private:
  MotionPrediction predictImpl(const Frame& f);
  SE2 velocityStep() const;
  void narrowToSpread(MotionPrediction& p) const;

  static constexpr std::size_t kVelocitySteps = 5;  // steps behind the constant-velocity prediction
  static constexpr std::size_t kIntervals = 21;     // intervals behind the usual interval
  static constexpr std::size_t kSpreadSteps = 20;   // steps behind the spread of the robot's motion
  static constexpr std::size_t kMinSpreadSteps = 10;

  const SlamOptions& opt_;
  std::vector<std::string> notes_;
  bool have_prev_ = false;
  double time_prev_ = 0.0;
  std::optional<SE2> odom_prev_;
  bool odometry_seen_ = false, odometry_missing_ = false;
  std::size_t odometry_missing_count_ = 0;
  // The front end's last few steps (robot frame), oldest first; emptied across gaps. The
  // constant-velocity prediction is their component-wise median (`velocityStep`).
  std::deque<SE2> recent_steps_;
  // The last kSpreadSteps steps since the latest gap (robot frame), oldest first.
  std::deque<SE2> spread_steps_;
  std::deque<double> recent_intervals_;  // intervals between scans (>= 0) [s], oldest first
};

}  // namespace lidar2d::slam::internal
