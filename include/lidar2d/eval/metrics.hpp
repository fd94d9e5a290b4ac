#pragma once
/// @file
/// Accuracy metrics of estimated trajectories and relative poses against ground truth:
/// - ATE (absolute trajectory error) after a least-squares SE(2) alignment,
/// - RPE (relative pose error) over consecutive poses and per distance travelled,
/// - the relation metric of Kuemmerle et al. 2009 ("On measuring the accuracy of SLAM algorithms",
///   Autonomous Robots 27(4)), the metric of the Cartographer paper's Table II,
/// - per-pair errors of scan matching and their success rate.
///
/// Conventions: est = estimated, ref = reference (ground truth). Poses are `T_world_robot` in each
/// trajectory's own world frame. Rotation errors are absolute wrapped angles in radians (the CLI
/// prints degrees). For two relative poses A (estimated) and B (reference) of the same pair, the
/// translation error is |t(A) - t(B)| and the rotation error |wrap(theta(A) - theta(B))|; note
/// |t(A) - t(B)| == |t(B^-1 * A)|, so this equals the usual "error transform" E = B^-1 A of the
/// RPE literature (Sturm et al. 2012) and the difference of (dx, dy) of Kuemmerle et al. 2009.
///
/// Every statistic (`ErrorStats`) reports the *sample* standard deviation (divisor n - 1), as
/// Cartographer's compute_relations_metrics does for the published mean +- std figures; it is 0
/// for a single value.

#include <cstddef>
#include <limits>
#include <optional>
#include <vector>

#include "lidar2d/core/se2.hpp"
#include "lidar2d/core/trajectory.hpp"

namespace lidar2d::eval {

/// How estimated poses are paired with reference poses.
enum class AssociationMode {
  kAuto,   ///< kIndex when both have as many poses and the same times in the same order, else kTime
  kIndex,  ///< the i-th estimated pose with the i-th reference pose (same length required)
  kTime,   ///< each reference pose with the estimated pose of the nearest time within max_dt_s
};

/// Options of every metric in this header.
struct Options {
  double max_dt_s = 0.1;  ///< a pose stands for a time when its timestamp is within this [s]; the
                          ///< 0.1 s of Kuemmerle et al. 2009. |dt| <= max_dt_s matches.
  AssociationMode association = AssociationMode::kAuto;  ///< see AssociationMode
  double same_time_tol_s = 1e-6;  ///< kAuto: times closer than this count as equal [s] (files
                                  ///< print microseconds or finer)
  bool align = true;              ///< ATE after the least-squares SE(2) alignment (false: as given)
  double rpe_distance_m = 1.0;    ///< per-distance RPE: segment length along the reference path [m]
  double pair_max_trans_m = 0.10;  ///< a pair succeeds when its translation error is below this [m]
  double pair_max_rot_deg = 2.0;   ///< ... and its rotation error below this [deg]
};

/// Summary of a list of non-negative errors. All NaN when count == 0.
struct ErrorStats {
  static constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
  std::size_t count = 0;
  double rmse = kNaN;    ///< sqrt(mean of squares)
  double mean = kNaN;
  double stddev = kNaN;  ///< sample standard deviation (divisor n - 1); 0 when count == 1
  double median = kNaN;  ///< middle value, or the mean of the two middle values
  double min = kNaN;
  double max = kNaN;
};

/// Statistics of `values` (any order). Non-finite values are not expected (the metrics never
/// produce them).
ErrorStats summarize(std::vector<double> values);

/// The q-quantile (q in [0, 1]) of `values` with linear interpolation between order statistics:
/// q = 0.5 is the median (the mean of the two middle values for an even count), q = 1 the maximum.
/// NaN when `values` is empty. Used for the timing summaries of the CLI and the benchmarks.
double percentile(std::vector<double> values, double q);

/// One associated pose pair.
struct Match {
  std::size_t est = 0;  ///< index into the estimated trajectory
  std::size_t ref = 0;  ///< index into the reference trajectory
};

/// Result of associating an estimated trajectory with a reference trajectory.
struct Association {
  AssociationMode mode = AssociationMode::kIndex;  ///< the mode used (never kAuto)
  std::vector<Match> matches;                      ///< in reference order
  std::size_t unmatched_reference = 0;  ///< reference poses without an estimated pose
  std::size_t unmatched_estimate = 0;   ///< estimated poses used by no match
  double max_abs_dt_s = 0.0;            ///< largest |t_est - t_ref| among the matches [s]
  bool ambiguous_times = false;  ///< kTime with repeated estimated timestamps: nearest is the first
};

/// Associates poses (see AssociationMode). Throws `lidar2d::Error` (kInvalidArgument) for kIndex
/// with trajectories of different lengths. Never throws for an empty result: check `matches`.
Association associate(const Trajectory& est, const Trajectory& ref, const Options& options = {});

/// Absolute trajectory error.
struct AteResult {
  SE2 T_ref_est;                ///< alignment applied to the estimate (identity when !align)
  ErrorStats trans_m;           ///< |p_ref - T_ref_est * p_est| [m]
  ErrorStats rot_rad;           ///< |wrap(theta_ref - theta(T_ref_est * T_est))| [rad]
  ErrorStats unaligned_trans_m;  ///< |p_ref - p_est| with no alignment [m]
};

/// Relative pose error.
struct RpeResult {
  /// Consecutive matches k, k+1 (in reference order): errors of T_est_k^-1 T_est_k+1 against
  /// T_ref_k^-1 T_ref_k+1 [m], [rad]. count = matches - 1.
  ErrorStats trans_m;
  ErrorStats rot_rad;
  /// Per distance travelled (as KITTI, Geiger et al. 2012, with one segment length d): for every
  /// match k as a start, the end j is the first later match whose reference path length
  /// s_kj = sum of |p_ref_{i+1} - p_ref_i| over matches k..j reaches d = rpe_distance_m; the
  /// segment's errors (as above, of T_k^-1 T_j) divided by s_kj. Starts with no such j are dropped.
  double distance_m = 1.0;
  ErrorStats trans_per_m;    ///< [m/m]
  ErrorStats rot_rad_per_m;  ///< [rad/m]
};

/// ATE, RPE and the association they used.
struct TrajectoryResult {
  Association association;
  AteResult ate;
  RpeResult rpe;
};

/// ATE over the matches. Throws `lidar2d::Error` (kBadInput) when there is no match.
AteResult computeAte(const Trajectory& est, const Trajectory& ref, const Association& association,
                     const Options& options = {});
/// RPE over the matches (empty statistics with fewer than two matches).
RpeResult computeRpe(const Trajectory& est, const Trajectory& ref, const Association& association,
                     const Options& options = {});
/// associate + computeAte + computeRpe. Throws `lidar2d::Error` (kBadInput) when no pose matches.
TrajectoryResult evaluateTrajectory(const Trajectory& est, const Trajectory& ref,
                                    const Options& options = {});

/// Error of one relation.
struct RelationError {
  std::size_t relation = 0;  ///< index in the relations list
  double trans_m = 0.0;      ///< |(dx, dy)_est - (dx, dy)_ref| [m]
  double rot_rad = 0.0;      ///< |wrap(dyaw_est - dyaw_ref)| [rad]
};

/// The relation metric (Kuemmerle et al. 2009).
struct RelationsResult {
  std::vector<RelationError> errors;  ///< evaluated relations, in list order
  ErrorStats trans_m;                 ///< report mean +- std
  ErrorStats rot_rad;
  std::size_t count = 0;    ///< relations evaluated
  std::size_t skipped = 0;  ///< relations lacking an estimated pose within max_dt_s of t1 or t2
  bool ambiguous_times = false;  ///< the estimate repeats timestamps (nearest = first of them)
};

/// For each relation (t1, t2, T_1_2): the estimated poses at the nearest estimated times within
/// max_dt_s of t1 and of t2 (a relation lacking either is skipped and counted), T_rel_est =
/// T_t1^-1 * T_t2, compared with T_1_2. Never throws; count may be 0.
RelationsResult evaluateRelations(const Trajectory& est, const Relations& relations,
                                  const Options& options = {});

/// Error of one estimated relative pose (scan matching pair).
struct PairError {
  std::size_t pair = 0;  ///< index in the pairs list
  double trans_m = 0.0;  ///< |t(T_prev_cur est) - t(T_prev_cur ref)| [m]
  double rot_rad = 0.0;  ///< |wrap(theta est - theta ref)| [rad]
  bool success = false;  ///< trans_m < pair_max_trans_m and rot < pair_max_rot_deg
};

/// Per-pair errors of relative poses against a reference trajectory.
struct PairsResult {
  AssociationMode mode = AssociationMode::kTime;  ///< kIndex: pair k is reference poses k, k+1
  std::vector<PairError> errors;  ///< evaluated pairs, in list order
  ErrorStats trans_m;
  ErrorStats rot_rad;
  std::size_t count = 0;       ///< pairs evaluated
  std::size_t skipped = 0;     ///< pairs lacking a reference pose within max_dt_s of a time
  std::size_t successes = 0;   ///< evaluated pairs under both thresholds
  std::size_t converged = 0;   ///< evaluated pairs the matcher flagged converged
  double success_rate = ErrorStats::kNaN;  ///< successes / count
};

/// Compares each estimated T_prev_cur with T_ref(t_prev)^-1 * T_ref(t_cur). Reference poses are
/// found by index when (kAuto) the pairs are exactly the consecutive reference poses (pairs.size()
/// == ref.size() - 1 and pair k has the times of reference poses k and k + 1), which handles logs
/// whose times repeat; otherwise by nearest time within max_dt_s. Never throws; count may be 0.
PairsResult evaluatePairs(const std::vector<RelativePose>& pairs, const Trajectory& ref,
                          const Options& options = {});

/// Printable name of a mode ("auto", "index", "time").
const char* toString(AssociationMode mode);

}  // namespace lidar2d::eval
