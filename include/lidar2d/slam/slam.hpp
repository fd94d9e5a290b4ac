#pragma once
/// @file
/// 2D SLAM: a scan-to-local-map front end (point-to-line ICP, the correlative matcher when the match
/// is poor, odometry as the prediction, degeneracy-aware), submaps of consecutive nodes (their
/// search grids built with the mapping module's occupancy grid), loop
/// closure candidates by proximity and, after a drift too large for that, by the global
/// localizer's line-pair descriptors (each verified by branch-and-bound search + ICP refinement +
/// strict acceptance), and an SE(2) pose graph solved with Ceres (robust loss on loop closures),
/// periodically and at the end.
///
/// Frames: the front end tracks `T_local_robot` in its own drift-prone "local" frame (it is never
/// corrected, so scan matching stays locally consistent, as in Cartographer's local trajectory
/// builder); the back end estimates `T_world_node` of the nodes. A scan that is not a node keeps
/// its pose relative to the node it was matched after: `T_world_scan = T_world_node * T_node_scan`.
/// Every pose is the robot's (the laser mounting `Frame::T_robot_laser` is applied to the points).

#include <Eigen/Core>
#include <cstddef>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "lidar2d/core/frame.hpp"
#include "lidar2d/core/se2.hpp"
#include "lidar2d/slam/pose_graph.hpp"
#include "lidar2d/slam/slam_options.hpp"

namespace lidar2d::slam {

/// The estimate of one input scan.
struct ScanEstimate {
  std::size_t frame_index = 0;  ///< Frame::index
  double time = 0.0;            ///< Frame::time
  SE2 T_world_robot;            ///< final (or current) estimate
  std::size_t node = 0;         ///< the node it is attached to
  std::size_t session = 0;      ///< the session (0: the first log mapped; see Slam(State, ...))
  bool is_node = false;         ///< the scan is that node
  bool matched = false;         ///< the front end matched it (else its pose is the prediction)
  bool degenerate = false;      ///< its match was degenerate (translation along `degenerate_dir` predicted)
  double seconds = 0.0;         ///< processing time of this scan (front end + back end work it triggered) [s]
};

/// A node of the pose graph (a scan kept by the motion filter).
struct Node {
  std::size_t scan = 0;    ///< index into the scans (ScanEstimate) list
  double time = 0.0;
  SE2 T_local_robot;       ///< front-end estimate
  SE2 T_world_robot;       ///< optimised estimate
  std::size_t submap = 0;  ///< submap it belongs to
  bool degenerate = false;
  double degenerate_dir_rad = 0.0;  ///< direction (robot frame) the scan could not pin, if degenerate
};

/// A constraint considered by the back end.
struct Constraint {
  enum class Kind { kSequential, kOdometry, kLoop };
  Kind kind = Kind::kSequential;
  std::size_t from = 0, to = 0;  ///< nodes
  SE2 T_from_to;                 ///< measurement
  bool accepted = true;          ///< loop closures may be rejected (kept for the report)
  bool searched = false;         ///< loop closure found by branch-and-bound search (not ICP from a link)
  bool descriptor = false;       ///< ... in a submap proposed by the descriptor index (large drift); implies searched
  double score = 0.0;            ///< correlative score (searched loops)
  double explained = 0.0;        ///< fraction of points explained after refinement (loops)
  std::string reason;            ///< why a loop closure was rejected
};
const char* toString(Constraint::Kind k);

/// Something the run noticed and survived (reported, never fatal).
struct Event {
  std::size_t frame_index = 0;
  double time = 0.0;
  std::string what;
};

/// The metres of odometry path, in steps the scans pinned, before SLAM states the odometry's distance
/// scale as the scans measured it (SlamStats::odometry_scale; applied with SlamOptions::scale_odometry).
inline constexpr double kOdometryScaleMinEvidenceM = 10.0;

/// Counters of a run.
struct SlamStats {
  std::size_t scans = 0, nodes = 0, submaps = 0;
  std::size_t matched = 0, correlative_fallbacks = 0, unmatched = 0, degenerate = 0;
  /// Returns left out as moving objects (SlamOptions::drop_moving_objects), and the scans they were in.
  std::size_t moving_points = 0, moving_scans = 0;
  std::size_t prior_overridden = 0;  ///< matches taken against the motion prior, on strong scan evidence
  std::size_t prior_kept = 0;        ///< matches contradicting the prior without that evidence (prior kept)
  std::size_t fragments = 0;         ///< stretches between lost tracks not tied together by a loop closure (1: all one)
  std::size_t relocalizations = 0;   ///< lost tracks tied back to the earlier map by a verified closure
  std::size_t odometry_wins = 0;     ///< node links where odometry overruled an estimate without scan evidence
  /// The scans' metres per metre of odometry at the end (1 until kOdometryScaleMinEvidenceM; the
  /// factor odometry distances are scaled by with SlamOptions::scale_odometry), and the metres of
  /// odometry path behind it (older steps fade over about 100 m). This session's own: a saved state
  /// does not keep it.
  double odometry_scale = 1.0;
  double odometry_scale_evidence_m = 0.0;
  /// The loop closures' cycles at the end (internal::calibrateFromCycles; docs/slam.md, Pose graph):
  /// how many were measured, the odometry's and the scan matches' heading error per node step they
  /// show [deg], and whether the final optimisation weighed the odometry links by them. This
  /// session's own: a saved state does not keep it.
  std::size_t loop_cycles = 0;
  double cycle_odometry_deg = 0.0;
  double cycle_front_end_deg = 0.0;
  double cycle_odometry_m = 0.0;
  double cycle_front_end_m = 0.0;
  bool odometry_weighted_by_cycles = false;
  std::size_t loop_searches = 0, loop_accepted = 0, loop_rejected = 0;
  std::size_t loop_downweighted = 0;  ///< accepted closures the final graph scaled below half weight (DCS)
  std::size_t descriptor_queries = 0;      ///< descriptor look-ups
  std::size_t descriptor_hypotheses = 0;   ///< hypotheses verified by branch and bound
  std::size_t descriptor_accepted = 0;     ///< closures found through descriptors that entered the graph
  double descriptor_seconds = 0.0;         ///< time of describing, indexing, looking up and verifying [s]
  std::size_t optimizations = 0;
  double optimization_seconds = 0.0;
  double total_seconds = 0.0;
};

struct State;

/// Incremental SLAM: feed frames in log order with `add`, then `finish`.
class Slam {
 public:
  /// A new map; `session` names the recording it starts with (State::Session::name).
  explicit Slam(const SlamOptions& options = {}, std::string session = {});
  /// Continues the map of `saved` (readStateFile) with a new session named `session`, with
  /// `saved.options` (validated: throws `lidar2d::Error` (kInvalidArgument) when out of range). The
  /// new session's first pose is unknown: it starts like a lost track with no odometry link (a new
  /// fragment, predicted where the saved run ended), and the relocalization of lost tracks (descriptor
  /// look-ups of each of its nodes in every saved submap, proximity searches while it is untied, each
  /// closure confirmed by a second one) ties it to the saved map; until then it is a separate
  /// fragment (SlamStats::fragments, an event at `finish`). Node points, lines, submap grids and
  /// descriptor indexes are rebuilt from the saved scans by the code that builds them during a run.
  explicit Slam(State saved, std::string session = {});
  ~Slam();
  Slam(const Slam&) = delete;
  Slam& operator=(const Slam&) = delete;

  /// Processes the next frame. Never throws for bad data in a frame (too few points, missing or
  /// jumping odometry, time going backwards): it records an Event and goes on.
  void add(const Frame& frame);
  /// Ends the run: a loop closure the last nodes found and no later search confirmed is searched
  /// for again from the nodes around it, then the final pose-graph optimisation; the estimates are
  /// final afterwards. Idempotent.
  void finish();

  /// Every scan added so far, in input order, with its current estimate.
  std::vector<ScanEstimate> trajectory() const;

  /// The current estimate of the scan added last (every `add` records one scan), in O(1) where
  /// `trajectory()` copies every scan: for a caller that wants each scan's pose as it goes (the
  /// Python binding's `Slam.add`). It does not wait for the back-end thread: the pose is the
  /// front end's, in the world frame as of the back end's last finished work. Throws
  /// `lidar2d::Error` (kInvalidArgument) before the first `add`.
  ScanEstimate latest() const;
  const std::vector<Node>& nodes() const;
  /// Sequential, odometry and loop constraints (accepted and rejected).
  const std::vector<Constraint>& constraints() const;
  const std::vector<Event>& events() const;
  /// Waits for the back-end thread to work through every node added, then the counters.
  const SlamStats& stats() const;
  /// The counters without waiting for the back-end thread (a progress display): the front end's
  /// as of the last `add`, the back end's (loops, optimisations, nodes in the graph: at least the
  /// nodes added) as of its last finished node.
  SlamStats statsSoFar() const;
  const SlamOptions& options() const;
  /// What a later run needs to continue this map (Slam(State, ...)) or to localize in it; after
  /// `finish` it is the complete, final state (before, closures awaiting confirmation are left out).
  State state() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace lidar2d::slam
