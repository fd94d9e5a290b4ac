#pragma once
/// @file
/// Logs derived from a recorded log for robustness tests (`lidar2d perturb`): odometry re-made from
/// the truth with a drifting noise model, keyframe subsampling, injected gaps (time windows whose
/// scans are dropped) and timestamp faults (jitter, bursts, synthesized times).
///
/// Everything works on frames and poses; reading and writing logs is the caller's job. Two passes:
/// a `GapPlanner` sees every frame once and places the gaps (it keeps one time and one pose per
/// scan, nothing else), then a `LogPerturber` streams the frames again and returns the derived ones.
/// Without gaps the first pass is not needed. `perturbLog` does both over frames held in memory.
///
/// The steps, per input frame i (file order, 0-based) with stamp s_i:
///  1. Clock: t_i = s_i, or t_i = s_0 + i / rate with `TimeFaults::synthesize_rate_hz` > 0. Gaps and
///     the output stamps use this clock.
///  2. Gaps: a frame with t_i inside a `GapWindow` [begin, end) is dropped, unless the window only
///     freezes the odometry (`GapRequest::frozen_odometry`) or makes it slip
///     (`GapRequest::odometry_slip`): such frames are kept.
///  3. Keyframes: a frame outside the gaps is kept when no frame was kept yet, or when its reference
///     pose (below) moved at least `min_distance_m` or turned at least `min_turn_rad` away from the
///     last kept frame's (a threshold of 0 is no criterion; without keyframes every frame is kept).
///  4. Odometry (`OdometrySource::kNoisyFromTruth`): odom_first = truth_0, the truth of the log's
///     first frame (kept or not); a later kept frame k gets
///       odom_k = odom_j * noisyOdometryStep(truth_j^-1 * truth_k)
///     with j the previously kept frame (or frame 0 while none was kept): the noise model applies to
///     the step between kept frames, and the first frame after a gap gets one step for the whole
///     motion across the gap (the wheels kept turning); after a carried gap (a kidnapping), one
///     step of no motion. With an `OdometryLag`, truth_k (and truth_0 as the first integration
///     point) is the truth at t_k + lag_k instead (`truthAt`): the odometry read at another time
///     than the scan. `kKeepLog` leaves the log's odometry as it is, but for the carried gaps'
///     jumps, which it removes (the odometry continues from where it was before the gap).
///     Inside a frozen-odometry window every kept frame's odometry is the last kept frame's before
///     the window (its own, when none was kept); after it the odometry reads on as made above (the
///     wheels kept counting: the motion across the window comes in one step).
///     With slip windows, each kept frame k after the previously kept j reads
///       odom'_k = odom'_j * (odom_j^-1 * odom_k) * SE2(f slip_m, 0, f slip_rad)
///     summed over the windows, f = the part of [t_j, t_k) inside the window over its length.
///  5. Stamps of the kept frames: t_i + N(0, jitter_sigma^2); then, with bursts of N, each group of N
///     consecutive kept frames (the last group may be shorter) carries the stamp of its last frame.
/// Scans, truth and laser mounting are never changed; odometry and truth stay with their scan.
///
/// Reference pose (keyframes and `@turn` gaps): the truth with `kNoisyFromTruth`; with `kKeepLog`
/// the truth when the log's first frame has truth, else the log's odometry.
///
/// Deterministic per seed: the odometry noise draws from `Rng(seed)` (three Gaussians per kept step,
/// as `noisyOdometryStep` says), the jitter from a second stream `Rng(seed ^ kJitterSeedSalt)` (one
/// Gaussian per kept frame), so enabling jitter leaves the odometry unchanged; the odometry lag from
/// a third, `Rng(seed ^ kLagSeedSalt)` (one Gaussian for frame 0 and one per later kept frame, when
/// its sigma is above 0), so it leaves the noise's draws unchanged too.

#include <cstddef>
#include <cstdint>
#include <optional>
#include <vector>

#include "lidar2d/core/frame.hpp"
#include "lidar2d/core/se2.hpp"
#include "lidar2d/sim/noise.hpp"
#include "lidar2d/sim/path.hpp"

namespace lidar2d::sim {

/// The "realistic" odometry of issue 29: translation noise 3 % of the step's distance + 5 mm per
/// step (x and y), heading noise 1 degree per metre + 3 % of the step's turn, no constant heading
/// noise, a 2 % scale error (distances read 2 % long), no heading drift. In `OdometryNoise` terms:
/// sigma_x_m = sigma_y_m = 0.005, sigma_theta_rad = 0, trans_sigma_per_m = 0.03,
/// rot_sigma_per_rad = 0.03, rot_sigma_per_m = pi / 180, scale_bias = 0.02, heading_bias_per_m = 0.
OdometryNoise realisticOdometryNoise();

/// Keyframe subsampling thresholds (see the file comment, step 3).
struct KeyframeOptions {
  double min_distance_m = 0.0;  ///< keep once moved this far from the last kept frame [m]; 0 = not by distance
  double min_turn_rad = 0.0;    ///< keep once turned this much from the last kept frame [rad], <= pi; 0 = not by turn

  /// True when either threshold is set (both 0: every frame is kept).
  bool enabled() const { return min_distance_m > 0 || min_turn_rad > 0; }
  /// Throws `lidar2d::Error` (kInvalidArgument) when a threshold is negative or not finite, or the
  /// turn exceeds pi.
  void validate() const;
};

/// Where a requested gap goes.
enum class GapPlacement {
  kAtOffset,     ///< starts `offset_s` after the first frame's time
  kMiddle,       ///< centred on the log: starts (length - duration) / 2 after the first frame's time
  kLargestTurn,  ///< the window of `duration_s` in which the reference heading turns most (`planGaps`)
};

/// A gap to place on a log.
struct GapRequest {
  double duration_s = 0.0;  ///< length of the window [s], finite and > 0
  GapPlacement placement = GapPlacement::kAtOffset;
  double offset_s = 0.0;  ///< kAtOffset: start after the first frame's time [s], finite and >= 0
  /// A kidnapping: the robot is carried across the window with its wheels still, so the odometry
  /// of the first kept frame after it reads no motion (plus the model's noise for a zero step;
  /// with `kKeepLog`, the log's odometry from there on is shifted to continue where it stopped)
  /// while the truth jumps. Otherwise the odometry carries the whole motion across the gap.
  bool carried = false;
  /// The window's scans are kept, but the odometry freezes across it: it reads the pose it read at
  /// the last scan before the window (a stalled driver, or wheels that do not turn while the robot
  /// is pushed), then what the wheels counted. Not with `carried`.
  bool frozen_odometry = false;
  /// The window's scans are kept, but the odometry counts motion the robot did not make: `slip_m`
  /// forward (negative: backward) and `slip_rad` of turn (counter-clockwise positive), spread evenly
  /// over the window's time and added to the steps it spans (wheels spinning on a threshold, a robot
  /// pushed against a wall, a caster turning on the spot). After it the odometry reads on, offset by
  /// the slip. Not with `carried` or `frozen_odometry`.
  bool odometry_slip = false;
  double slip_m = 0.0;
  double slip_rad = 0.0;

  /// Throws `lidar2d::Error` (kInvalidArgument) for a duration <= 0, a negative or non-finite value,
  /// or a window of two kinds (carried, frozen, slip).
  void validate() const;
};

/// A gap placed on a log: frames whose time (on the clock of step 1) lies in [begin_s, end_s) are
/// dropped (or, for a frozen-odometry window, kept with their odometry frozen).
struct GapWindow {
  double begin_s = 0.0;  ///< first dropped time [s]
  double end_s = 0.0;    ///< frames at this time or later are kept again [s]
  /// Heading change inside the window: the sum of |wrap(theta_{j+1} - theta_j)| over consecutive
  /// frames j, j+1 (file order) whose times both lie in [begin_s, end_s) [rad]. NaN when the reference
  /// poses were not available.
  double turn_rad = 0.0;
  GapRequest request;  ///< what was asked for

  bool contains(double t_s) const { return t_s >= begin_s && t_s < end_s; }
};

/// Timestamp faults (see the file comment, steps 1 and 5).
struct TimeFaults {
  double synthesize_rate_hz = 0.0;  ///< > 0: replace stamp i by s_0 + i / rate [Hz]; 0 = keep the stamps
  double jitter_sigma_s = 0.0;      ///< std of the Gaussian added to each kept frame's stamp [s], >= 0
  std::size_t burst_size = 1;       ///< frames per burst sharing the last one's stamp, >= 1 (1 = no bursts)

  /// Throws `lidar2d::Error` (kInvalidArgument) for a negative or non-finite rate or sigma, or burst_size 0.
  void validate() const;
};

/// The odometry read at another time than its scan (see the file comment, step 4): a laser and an
/// odometry on clocks out of step, or a driver that stamps scans by a varying delay. Kept frame k's
/// odometry is integrated to the truth at t_k + lag_k, lag_k = mean_s + N(0, sigma_s^2). In a turn
/// its heading is then off by the turn rate times lag_k; the error does not accumulate, as each
/// frame's odometry is read at its own time (docs/perturb.md, Odometry lag: what the raw bags show).
struct OdometryLag {
  double mean_s = 0.0;   ///< constant part [s], finite; positive: the odometry is read after the scan
  double sigma_s = 0.0;  ///< std of the part drawn per frame [s], finite and >= 0

  /// True when the odometry is read at another time than the scan.
  bool enabled() const { return mean_s != 0.0 || sigma_s > 0.0; }
  /// Throws `lidar2d::Error` (kInvalidArgument) for a non-finite value or a negative sigma.
  void validate() const;
};

/// The truth at clock time `t_s`, interpolated in `timeline` (every frame's clock time and truth,
/// file order) from frame `index`: its own truth at its own time; for a later time, between the
/// first frame after `index` stamped later than `t_s` and the frame before that one; for an earlier
/// time, between the first frame back from `index` stamped at or before `t_s` and the frame after
/// it (so stamps that repeat or go backwards are walked past); the first or last frame's truth
/// beyond the log's ends. Linear in translation, the shorter way round in heading.
/// Throws `lidar2d::Error` (kInvalidArgument) when `index` is not in `timeline`.
SE2 truthAt(const std::vector<TimedPose>& timeline, std::size_t index, double t_s);

/// Where odometry comes from.
enum class OdometrySource {
  kNoisyFromTruth,  ///< integrated from the truth with `LogPerturbationOptions::odometry` noise (needs truth)
  kKeepLog,         ///< the log's own odometry, unchanged (the log needs no truth)
};

/// Salt of the jitter's random stream: `Rng(seed ^ kJitterSeedSalt)`.
inline constexpr std::uint64_t kJitterSeedSalt = 0x9E3779B97F4A7C15ULL;
/// Salt of the odometry lag's random stream: `Rng(seed ^ kLagSeedSalt)`.
inline constexpr std::uint64_t kLagSeedSalt = 0xD1B54A32D192ED03ULL;

/// Everything `LogPerturber` does. The defaults reproduce `lidar2d perturb` without options: every
/// frame kept, stamps unchanged, odometry from the truth with constant per-step noise
/// N(0, diag(0.01^2, 0.005^2, 0.002^2)) [m, m, rad].
struct LogPerturbationOptions {
  OdometrySource odometry_source = OdometrySource::kNoisyFromTruth;
  OdometryNoise odometry = OdometryNoise::constant(0.01, 0.005, 0.002);  ///< for kNoisyFromTruth
  KeyframeOptions keyframes;
  std::vector<GapWindow> gaps;  ///< placed gaps (from `planGaps` / `GapPlanner`); may overlap
  TimeFaults time;
  OdometryLag odometry_lag;  ///< for kNoisyFromTruth; needs `truth_timeline`
  /// With `odometry_lag`: the clock time and truth of every frame of the log, file order, dropped
  /// ones included (`GapPlanner::samples` of a kNoisyFromTruth pass; `perturbLog` fills it).
  std::vector<TimedPose> truth_timeline;
  std::uint64_t seed = 1;

  /// Validates every part; throws `lidar2d::Error` (kInvalidArgument) naming the field.
  void validate() const;
};

/// The frame's time on the clock of step 1: `stamp_s`, or `first_stamp_s + index / rate` when
/// `time.synthesize_rate_hz` > 0 (`index` = 0-based position of the frame in the log).
double clockTime(const TimeFaults& time, double first_stamp_s, std::size_t index, double stamp_s);

/// The heading change inside [begin_s, end_s) as `GapWindow::turn_rad` defines it, by a direct sum
/// over `samples` (time on the clock of step 1, reference pose; file order). O(n).
double turnInWindow(const std::vector<TimedPose>& samples, double begin_s, double end_s);

/// Places `requests` on a log given by the time and reference pose of every frame (file order;
/// poses are used only by kLargestTurn). Windows come back in the order of `requests`.
///
/// The log spans [t_first, t_last], the times of its first and last frame. kAtOffset and kMiddle
/// windows are placed first, then the kLargestTurn ones in the order given, each the window
/// [b, b + duration) with the largest `turn_rad` among those that start at or after t_first, end at
/// or before t_last and do not overlap a window placed before it; candidates start at a frame's time
/// or end where a placed window begins or at t_last (the maximum over all start times is always among
/// them); ties go to the earliest. Runs in O(n log n) per kLargestTurn request.
///
/// Throws `lidar2d::Error` (kBadInput) when a window would end after t_last (the gap is longer than
/// the log, or starts too late: no frame would follow it), when no window fits beside the others,
/// or when `samples` is empty; (kInvalidArgument) for an invalid request.
std::vector<GapWindow> planGaps(const std::vector<GapRequest>& requests, const std::vector<TimedPose>& samples);

/// The first pass: collects the clock time and reference pose of every frame and places the gaps.
class GapPlanner {
 public:
  /// Throws `lidar2d::Error` (kInvalidArgument) for invalid requests or time options.
  GapPlanner(std::vector<GapRequest> requests, OdometrySource source, TimeFaults time);

  /// Takes the next frame (file order). Throws `lidar2d::Error` (kBadInput) when a kLargestTurn
  /// request needs a reference pose the frame lacks (or, with kNoisyFromTruth, the truth).
  void add(const Frame& frame);
  /// Places the gaps (see `planGaps`); `turn_rad` is NaN when the poses were incomplete.
  std::vector<GapWindow> plan() const;
  /// Time and reference pose of every frame added (identity where the pose is unknown).
  const std::vector<TimedPose>& samples() const { return samples_; }

 private:
  std::vector<GapRequest> requests_;
  OdometrySource source_;
  TimeFaults time_;
  bool need_poses_ = false;
  bool poses_complete_ = true;
  bool use_truth_ = true;
  double first_stamp_s_ = 0.0;
  std::vector<TimedPose> samples_;
};

/// What a `LogPerturber` did.
struct PerturbationStats {
  std::size_t scans_read = 0;            ///< frames pushed
  std::size_t scans_kept = 0;            ///< frames returned
  std::size_t dropped_by_keyframes = 0;  ///< outside the gaps, but too close to the last kept frame
  std::size_t dropped_by_gaps = 0;       ///< inside at least one gap that drops its frames
  std::size_t frozen_odometry = 0;       ///< kept frames whose odometry a frozen-odometry window froze
  std::size_t slipped_odometry = 0;      ///< kept frames whose odometry step a slip window added motion to
  /// Frames whose time lies in each of `LogPerturbationOptions::gaps` (a frame in two gaps counts in
  /// both; in a frozen-odometry or slip window, frames are kept unless keyframing drops them).
  std::vector<std::size_t> dropped_per_gap;
  std::optional<SE2> last_T_odom_robot;   ///< odometry of the last kept frame
  std::optional<SE2> last_T_world_robot;  ///< truth of the last kept frame
};

/// The second pass: streams a log's frames and returns the derived ones (see the file comment).
/// Memory is bounded by one burst of frames.
class LogPerturber {
 public:
  /// Throws `lidar2d::Error` (kInvalidArgument) for invalid options.
  explicit LogPerturber(LogPerturbationOptions options);
  LogPerturber(const LogPerturber&) = delete;
  LogPerturber& operator=(const LogPerturber&) = delete;

  /// Takes the next frame of the log (file order) and returns the frames now complete, in order:
  /// none while it is dropped or its burst is still open. Throws `lidar2d::Error` (kBadInput) for a
  /// frame without truth under kNoisyFromTruth, or without the reference pose that keyframes need.
  std::vector<Frame> push(Frame frame);
  /// Returns the frames of the last, incomplete burst. Call once, after the last `push`.
  std::vector<Frame> finish();

  const PerturbationStats& stats() const { return stats_; }
  const LogPerturbationOptions& options() const { return options_; }

 private:
  std::vector<Frame> flush();
  /// Where frame `index` (clock time `t`) has its odometry read: its truth, or with an odometry lag
  /// the truth at the lagged time (draws the lag).
  SE2 odometryReadingPoint(const Frame& frame, std::size_t index, double t);

  const LogPerturbationOptions options_;
  Rng odom_rng_;
  Rng jitter_rng_;
  Rng lag_rng_;
  PerturbationStats stats_;
  double first_stamp_s_ = 0.0;
  bool use_truth_ = true;  // reference poses: truth, or (kKeepLog without truth) odometry
  std::optional<SE2> last_kept_reference_;
  SE2 prev_truth_;  // truth where the odometry was last integrated
  SE2 odom_;
  bool carried_ = false;               // a carried gap dropped frames since the last kept one
  std::optional<SE2> frozen_reading_;  // inside a frozen-odometry window: what the odometry reads there
  std::optional<SE2> log_odom_shift_;  // kKeepLog after a carried gap: output odometry = shift * the log's
  // With slip windows: the previous kept frame's odometry before and after the slip, and its time.
  std::optional<SE2> slip_read_prev_, slip_out_prev_;
  double slip_t_prev_ = 0.0;
  /// Adds the slip of the windows overlapping [slip_t_prev_, t) to the odometry step since the
  /// previous kept frame (options_.gaps' slip windows; none: `odom` unchanged).
  std::optional<SE2> slipped(const std::optional<SE2>& odom, double t);
  std::vector<Frame> burst_;
};

/// Both passes over frames held in memory: places `gaps` on `frames` (added to `options.gaps`) and
/// returns the derived frames; `stats`, when given, receives what was done. Throws as `planGaps`
/// and `LogPerturber` do.
std::vector<Frame> perturbLog(const std::vector<Frame>& frames, LogPerturbationOptions options,
                              const std::vector<GapRequest>& gaps = {}, PerturbationStats* stats = nullptr);

}  // namespace lidar2d::sim
