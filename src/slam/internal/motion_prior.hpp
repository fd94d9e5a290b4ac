#pragma once
// SLAM's motion prior: the predicted step from the previous scan to the next one, with an honest
// uncertainty. Odometry when present and plausible over the time the step took, its sigma growing
// with distance, turn and time; else constant velocity with a wide sigma growing with time. The
// front end sizes its search by the sigma and weighs a match that contradicts the prediction
// against it (FrontEnd::track).

#include <cstddef>
#include <deque>
#include <numbers>
#include <optional>
#include <string>
#include <vector>

#include "lidar2d/core/frame.hpp"
#include "lidar2d/core/se2.hpp"
#include "lidar2d/slam/slam.hpp"
#include "lidar2d/slam/slam_options.hpp"

namespace lidar2d::slam::internal {

/// The upper median of `v` (its element n/2 in sorted order; n > 0), in O(n).
double upperMedian(std::vector<double> v);

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
  /// Odometry only: the odometry's own step, before OdometryScale's factor (`delta` carries it).
  SE2 odometry_step;
  /// The frame's odometry pose on a chain of its steps, each with the distance scale estimated when
  /// it was taken (what the graph's odometry constraints link); nothing without odometry.
  std::optional<SE2> T_odom_scaled;
  /// The odometry read exactly the pose it read at the previous scan (a robot standing still, or
  /// odometry that froze: MotionPrior::remember tells them apart by the scans).
  bool odometry_still = false;
  bool time_ok = true;  ///< time moved forward, without a gap, since the previous scan
  double dt = 0.0;      ///< the time the step took as used for the sigma [s] (the usual interval when unknown)

  /// The Mahalanobis distance of a step `step` (T_prev_cur) from the prediction, in sigmas.
  double distance(const SE2& step) const;
};

/// The odometry prediction of step `odo` that took `dt` seconds: its sigmas under `opt`.
MotionPrediction odometryPrediction(const SlamOptions& opt, const SE2& odo, double dt);

/// The odometry's distance scale as the scans measure it. Wheel odometry reads distances a few
/// percent long or short (wheel radius, tyre pressure, load). Where the scan pins every direction
/// that error is corrected step by step, but along a corridor the match takes its translation along
/// the corridor from the prediction, so the odometry's error there becomes the map's (the simulated
/// corridor's keyframes with odometry 2% long: 0.42-0.51 m ATE against 0.05-0.12 m with its exact
/// scale, seeds 1-3). Over spans of consecutive steps the scans pinned, each at least kSpanM of
/// odometry chord, the distance the scans measured along that chord is compared with its length:
/// the factor is the ratio of their sums over about the last kMemoryM metres of spans (older ones
/// fade), once kMinEvidenceM metres were seen, bounded to [kMinFactor, kMaxFactor]. Spans, not
/// steps: the length of a short noisy step is biased long (its noise across the motion only adds),
/// by 3% for 2 cm steps with 5 mm of noise (a 40 Hz laser), and consecutive scan-to-map matches
/// share their errors, which cancel over a span. With exact odometry the factor is 1 to 0.2% (the
/// simulator). The motion prior applies it only with SlamOptions::scale_odometry (BENCHMARK.md:
/// on the corrected logs it moved the ATE the wrong way).
class OdometryScale {
 public:
  /// Odometry measured `odometry_step` where the scans matched `matched_step` (both robot frame,
  /// the same step), both ends pinned: the span goes on, and is measured once long enough.
  void observe(const SE2& odometry_step, const SE2& matched_step);
  /// A step the scans did not pin: the span being measured ends unused.
  void interrupt() { odometry_span_ = scan_span_ = SE2(); }
  /// The factor odometry translations are multiplied by: 1 until the evidence suffices.
  double factor() const { return factor_; }
  /// Metres of odometry chord behind the factor (faded).
  double evidenceM() const { return odometry_m_; }

  static constexpr double kSpanM = 0.5;
  static constexpr double kMinEvidenceM = kOdometryScaleMinEvidenceM;
  static constexpr double kMemoryM = 100.0;
  static constexpr double kMinFactor = 0.8;
  static constexpr double kMaxFactor = 1.25;

 private:
  SE2 odometry_span_, scan_span_;  // the span being measured, from its first scan
  double odometry_m_ = 0.0, scan_m_ = 0.0;
  double factor_ = 1.0;
};

/// How far the odometry's steps actually stray from what the scans measured, against the model's
/// sigmas (SlamOptions::prior_odometry_*): the model is set wide enough for poor wheel odometry,
/// and on good odometry with scans metres apart its distance and turn terms make a prior so wide
/// that the correlative search over it finds look-alikes (a room turned by 45 degrees, a corridor
/// one door on) explaining as much of a sparse scan as the right pose. The factor each sigma is
/// narrowed by is the upper decile of the recent steps' residuals in model sigmas (so that decile
/// lies at one sigma and the gate at four), never above the model and never below its constant
/// terms (MotionPrior::narrowToOdometryNoise).
class OdometryNoise {
 public:
  /// A step both ends of which the scans pinned, or an override of the prediction: its residual
  /// (prediction^-1 * matched) against the model's sigmas `model_m`, `model_rad`, whose constant
  /// terms are `floor_m`, `floor_rad`.
  void observe(const SE2& residual, double model_m, double model_rad, double floor_m, double floor_rad);
  /// The factors (translation, rotation) in (0, 1]: 1 until kMinSteps residuals are known.
  double factorM() const { return factor_m_; }
  double factorRad() const { return factor_rad_; }

  static constexpr std::size_t kSteps = 30;
  static constexpr std::size_t kMinSteps = 10;
  static constexpr double kQuantile = 0.9;
  static constexpr double kMinFactor = 0.2;

 private:
  std::deque<double> z_m_, z_rad_;
  double factor_m_ = 1.0, factor_rad_ = 1.0;
};

class MotionPrior {
 public:
  explicit MotionPrior(const SlamOptions& opt) : opt_(opt) {}
  /// The prior keeps a reference to its options: a temporary would dangle.
  explicit MotionPrior(const SlamOptions&&) = delete;

  /// The prediction for frame `f` (identity with source kNone for the first). `event` records what
  /// the prior noticed (time going backwards, gaps, odometry missing, resuming or implausible).
  template <class EventSink>
  MotionPrediction predict(const Frame& f, EventSink&& event) {
    MotionPrediction p = predictImpl(f);
    widenAfterOverride(p);
    for (std::string& e : notes_) event(std::move(e));
    notes_.clear();
    return p;
  }
  /// The front end took a match `taken` (prediction^-1 * match) against prediction `p`, on scan
  /// evidence. When its heading contradicts `p` beyond the gate, the next prediction's sigmas are at
  /// least half of it: odometry whose heading was wrong at this stamp is in doubt for the next step
  /// too. A scan logged late in a turn matches where it was taken, tens of degrees from the odometry
  /// interpolated at its stamp, and the fresh scan after it is predicted from that pose with an
  /// odometry step just as wrong (the simulated office with late-scan bursts: the fresh scan's right
  /// match, 28 degrees off, refused at 18 sigmas). Not after an override in translation alone (the
  /// Intel bag's odometry jumps of 0.2-0.9 m): a prior widened after those let look-alikes win.
  void overridden(const MotionPrediction& p, const SE2& taken);
  /// Frame `f`, predicted by `p`, ended at `step` from the previous scan (front-end estimate;
  /// ignored for the first). `pinned`: the scan measured the step (matched, not degenerate); only
  /// such steps make the constant-velocity history, since an unmatched or degenerate step is (along
  /// its weak direction) the prediction itself.
  ///
  /// Frozen odometry: a driver that stalls, or wheels that do not turn while the robot is pushed,
  /// keep reading one pose while the robot moves (and a bag whose odometry ends early is read as
  /// its last pose). Each scan then fights a confident prediction of no motion, and every node
  /// carries an odometry link that holds it still (the simulated office with its odometry frozen
  /// for 10 s: 0.003 -> 0.071 m ATE). The odometry is taken as frozen once the scans have moved the
  /// robot, since it last read another pose, beyond the prior's gate for standing still over that
  /// time (odometryPrediction of no motion; a robot that stands still stays within it, the scans'
  /// jitter being centimetres). From then on the prior is constant velocity, without odometry links,
  /// until the odometry reads another pose.
  void remember(const Frame& f, const MotionPrediction& p, const SE2& step, bool first, bool pinned = true);
  /// The scans matched step `matched_step` of a prediction `p` from odometry, pinning both its ends
  /// (OdometryScale::observe).
  void observeOdometryStep(const MotionPrediction& p, const SE2& matched_step);
  /// The scans placed the frame of prediction `p` at `matched_step` from the previous frame, both
  /// ends pinned or overriding `p` (OdometryNoise::observe).
  void observeOdometryNoise(const MotionPrediction& p, const SE2& matched_step);
  /// A step they did not pin (OdometryScale::interrupt).
  void interruptOdometryScale() { scale_.interrupt(); }
  const OdometryScale& odometryScale() const { return scale_; }
  /// The factor odometry steps are scaled by: OdometryScale's with SlamOptions::scale_odometry, else 1.
  double appliedScale() const { return opt_.scale_odometry ? scale_.factor() : 1.0; }
  /// The usual interval between scans so far (median of the recent ones, repeated stamps as 0) [s], 0
  /// before any.
  double usualInterval() const;
  /// Without odometry, the step the robot's recent pinned steps say it takes when it turns by
  /// `turn` [rad]: the component-wise median translation of those (since the latest gap) whose turn
  /// is within kSimilarTurnRad of it, with `turn`; nothing when fewer than kMinSimilarSteps are.
  /// Along a corridor the scan measures the turn but not the distance: a robot driving straight
  /// drives its straight steps' length, not the average of its last few steps, turns included (a
  /// keyframe log keeps a scan every metre or 30 degrees, so its turning steps are the short ones).
  std::optional<SE2> stepTurning(double turn) const;

 private:
  MotionPrediction predictImpl(const Frame& f);
  /// The interval a gap is measured against (five times it, and `time_gap_s`): `usual`
  /// (usualInterval), or the mean of the recent intervals where repeated stamps make that 0.
  double intervalForGaps(double usual) const;
  SE2 velocityStep() const;
  void narrowToSpread(MotionPrediction& p) const;
  void widenAfterOverride(MotionPrediction& p);
  void narrowToOdometryNoise(MotionPrediction& p) const;

  static constexpr std::size_t kVelocitySteps = 5;  // steps behind the constant-velocity prediction
  static constexpr std::size_t kIntervals = 21;     // intervals behind the usual interval
  static constexpr std::size_t kSpreadSteps = 20;   // steps behind the spread of the robot's motion
  static constexpr std::size_t kMinSpreadSteps = 10;
  static constexpr double kSimilarTurnRad = 10.0 * std::numbers::pi / 180.0;
  static constexpr std::size_t kMinSimilarSteps = 3;

  const SlamOptions& opt_;
  std::vector<std::string> notes_;
  bool have_prev_ = false;
  double time_prev_ = 0.0;
  std::optional<SE2> odom_prev_;
  std::optional<SE2> odom_scaled_prev_;  // odom_prev_ on the scaled chain (MotionPrediction::T_odom_scaled)
  std::optional<SE2> odom_scaled_;       // the predicted frame's pose on it
  OdometryScale scale_;
  OdometryNoise noise_;
  std::optional<SE2> heading_override_;  // the previous scan's override, when it contradicted the heading (overridden)
  // An implausible odometry step (predictImpl): the odometry reading and time before it, the step,
  // which limits it broke, and the step its scan took (remember). The next step's odometry is taken
  // from the reading before it, less the step taken, when the odometry took the implausible step back.
  struct OdometryAnchor {
    SE2 odom;
    double time = 0.0;
    SE2 implausible;
    bool too_far = false, too_turned = false;
    SE2 taken;
    bool pinned = true;  ///< the scan pinned the step it took (else its pose is the prior's guess)
  };
  std::optional<OdometryAnchor> pending_anchor_;  // the frame being predicted had an implausible step
  std::optional<OdometryAnchor> anchor_;          // the previous frame had one
  bool odometry_seen_ = false, odometry_missing_ = false;
  std::size_t odometry_missing_count_ = 0;
  // Frozen odometry (remember): the scans' steps since the odometry last read another pose, the
  // time of that reading's first scan and the scans since that read it again; whether it is taken
  // as frozen.
  SE2 still_span_;
  double still_since_ = 0.0;
  std::size_t still_count_ = 0;
  bool odometry_frozen_ = false;
  // The front end's last few steps the scans pinned (robot frame), oldest first; a gap leaves only
  // a standstill. The constant-velocity prediction is their component-wise median (`velocityStep`).
  std::deque<SE2> recent_steps_;
  // The last kSpreadSteps steps the scans pinned since the latest gap (robot frame), oldest first.
  std::deque<SE2> spread_steps_;
  std::deque<double> recent_intervals_;  // intervals between scans (>= 0) [s], oldest first
  std::size_t repeated_ = 0;             // scans in a row up to the previous one that repeated its predecessor's stamp
};

}  // namespace lidar2d::slam::internal
