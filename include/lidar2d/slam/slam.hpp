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
#include <numbers>
#include <string>
#include <vector>

#include "lidar2d/core/frame.hpp"
#include "lidar2d/core/se2.hpp"
#include "lidar2d/slam/pose_graph.hpp"

namespace lidar2d::slam {

inline constexpr double kDeg = std::numbers::pi / 180.0;

/// Every SLAM parameter, with the defaults used for every dataset in BENCHMARK.md.
struct SlamOptions {
  // --- input ---
  bool use_odometry = true;      ///< use the frames' wheel odometry as the prediction (when present)
  double max_range_m = 30.0;     ///< beams at or beyond this range are not matched [m], > 0
  std::size_t min_points = 20;   ///< a scan with fewer valid points is not matched (pose predicted), >= 3

  // --- motion filter: which scans become nodes ---
  double node_min_translation_m = 0.25;         ///< [m], >= 0
  double node_min_rotation_rad = 10.0 * kDeg;   ///< [rad], >= 0
  double node_max_interval_s = 5.0;             ///< a node at least this often while moving [s], > 0

  // --- front end ---
  int local_map_nodes = 12;                 ///< nodes whose points form the local map, >= 1
  /// Match scans against the local map's likelihood field (registration::matchLikelihoodField,
  /// Gauss-Newton, two resolutions) instead of point-to-line ICP (the default; the two are compared
  /// in BENCHMARK.md).
  bool front_end_likelihood_field = false;
  double icp_max_correspondence_m = 0.5;    ///< ICP pairs farther apart are rejected [m], > 0
  /// A scan keeps one point (the centroid) per cell of this size before matching: dense returns
  /// near the robot add work, not information [m], > 0.
  double scan_voxel_m = 0.05;
  double map_voxel_m = 0.05;
  /// Map points fitted per line normal (point-to-line ICP). More than a single scan needs: the
  /// local map stacks several scans, whose small misalignments would make short fits fail the
  /// flatness test, >= 2.
  int normal_neighbors = 10;
  /// A neighbourhood whose spread across its line exceeds this share of its spread along it gets
  /// no normal (see IcpOptions::max_line_flatness), in (0, 1].
  double max_line_flatness = 0.5;                ///< local maps and submaps keep one point (the centroid) per cell of this size [m], > 0
  double match_inlier_distance_m = 0.1;     ///< a point within this of the map counts as explained [m], > 0
  double min_explained_fraction = 0.5;      ///< a match explaining less is poor: correlative search next, in (0, 1]
  /// When the predicted motion exceeds either, ICP also starts from "no motion" and from constant
  /// velocity, and the result explaining the most points wins [m], [rad], >= 0.
  double alternative_start_m = 0.1;
  double alternative_start_rad = 3.0 * kDeg;
  double fallback_linear_window_m = 1.0;    ///< correlative search window around the prediction [m], > 0
  double fallback_angular_window_rad = 30.0 * kDeg;  ///< [rad], > 0
  /// The smallest eigenvalue of the translational information per matched point (a value in [0, 1]:
  /// the share of the points' line normals along the weakest direction) below which the match is
  /// degenerate; its translation along that direction is then taken from the prediction, >= 0.
  double degeneracy_threshold = 0.04;
  double odometry_jump_m = 1.5;             ///< an odometry step longer than this is not trusted [m], > 0
  double odometry_jump_rad = 60.0 * kDeg;   ///< ... or turning more than this [rad], > 0
  double time_gap_s = 2.0;                  ///< scans further apart in time are reported as a gap [s], > 0

  // --- submaps ---
  int submap_nodes = 30;  ///< nodes per submap, >= 2

  // --- loop closure ---
  double loop_search_radius_m = 5.0;       ///< submaps whose centre is nearer than this are candidates [m], > 0
  int loop_search_every_nodes = 5;         ///< branch-and-bound search for one node in this many, >= 1
  int loop_searches_per_node = 2;          ///< at most this many searches (nearest submaps first), >= 1
  double loop_linear_window_m = 2.0;       ///< branch-and-bound window half-width [m], > 0
  double loop_angular_window_rad = 15.0 * kDeg;  ///< [rad], > 0
  double loop_min_score = 0.55;            ///< correlative score a closure needs, in (0, 1]
  double loop_min_explained_fraction = 0.7;  ///< points within match_inlier_distance_m after refinement, in (0, 1]
  /// A searched closure is accepted only when a second search from a node at most this many nodes
  /// later agrees with it (through the front end's relative poses) within the tolerances, >= 1.
  int loop_confirm_window_nodes = 30;
  double loop_confirm_tolerance_m = 0.2;             ///< [m], > 0
  double loop_confirm_tolerance_rad = 2.0 * kDeg;    ///< [rad], > 0
  /// A constraint to a submap linked within this many nodes is found by ICP from the linked
  /// estimate instead of a search, >= 0.
  int loop_link_memory_nodes = 15;

  // --- loop closure by descriptors (drift too large for the radius above) ---
  /// Describe every node's scan by the localization module's line-pair descriptors (one index per
  /// finished submap) and look the current node up in the submaps the proximity search does not
  /// cover; hypotheses are verified like searched closures (branch and bound in a small window,
  /// ICP, score, explained fraction, confirmation by a second closure) plus a drift-plausibility
  /// and an ambiguity test.
  bool descriptor_loops = true;
  int descriptor_every_nodes = 10;   ///< query one node in this many, >= 1
  /// Query only when no closure was accepted within this many nodes (the proximity search is
  /// working otherwise), >= 0.
  int descriptor_quiet_nodes = 30;
  /// Submaps whose last node is fewer than this many nodes before the query are not looked up
  /// (recent ground is the front end's), >= 0.
  int descriptor_min_age_nodes = 60;
  double descriptor_min_votes = 6.0;       ///< a hypothesis needs this many line-pair votes, >= 1
  int descriptor_max_candidates = 3;       ///< hypotheses verified per query (most votes first), >= 1
  std::size_t descriptor_max_lines = 14;   ///< longest lines of a scan described and queried, >= 2
  double descriptor_linear_window_m = 0.6;           ///< branch-and-bound window around a hypothesis [m], > 0
  double descriptor_angular_window_rad = 6.0 * kDeg; ///< [rad], > 0
  /// The correction a descriptor closure makes to the current estimate must be at most
  /// descriptor_max_correction_m + descriptor_drift_fraction * (path travelled since the submap)
  /// [m], >= 0; a larger one is implausible for the front end's drift (an aliased place).
  double descriptor_max_correction_m = 2.0;
  double descriptor_drift_fraction = 0.1;    ///< [m/m], >= 0
  /// ... and must turn the current estimate by at most this [rad], >= 0: the front end's heading
  /// drifts slowly, while aliased places in buildings are typically turned by 90 or 180 degrees.
  double descriptor_max_rotation_rad = 30.0 * kDeg;
  /// A descriptor hypothesis is rejected when more than this share of the scan's beams pass
  /// through the submap's points (more than 0.3 m before their endpoint): the scan sees through
  /// the walls it should see there, the signature of a look-alike place, in [0, 1].
  double descriptor_max_see_through = 0.05;

  // --- pose graph ---
  double sequential_sigma_m = 0.02;          ///< front-end relative pose between nodes [m], > 0
  double sequential_sigma_rad = 0.25 * kDeg; ///< [rad], > 0
  double loop_sigma_m = 0.05;                ///< loop-closure constraint [m], > 0
  double loop_sigma_rad = 1.0 * kDeg;        ///< [rad], > 0
  double loop_huber = 1.0;                   ///< Huber scale on the whitened loop residual, > 0
  double odometry_sigma_m = 0.05;            ///< odometry edge, plus 10% of the distance [m], > 0
  double odometry_sigma_rad = 2.0 * kDeg;    ///< odometry edge, plus 10% of the rotation [rad], > 0
  /// Optimise this many nodes after a closure found by search (10x as many after other closures), >= 1.
  int optimize_every_nodes = 30;
  int intermediate_iterations = 10;          ///< iterations of the optimisations during the run, >= 1
  PoseGraphOptions graph;  ///< solver of the final optimisation (max_iterations) and of every one (threads)

  /// Throws `lidar2d::Error` (kInvalidArgument) naming the first field out of its domain.
  void validate() const;
};

/// The estimate of one input scan.
struct ScanEstimate {
  std::size_t frame_index = 0;  ///< Frame::index
  double time = 0.0;            ///< Frame::time
  SE2 T_world_robot;            ///< final (or current) estimate
  std::size_t node = 0;         ///< the node it is attached to
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

/// Counters of a run.
struct SlamStats {
  std::size_t scans = 0, nodes = 0, submaps = 0;
  std::size_t matched = 0, correlative_fallbacks = 0, unmatched = 0, degenerate = 0;
  std::size_t loop_searches = 0, loop_accepted = 0, loop_rejected = 0;
  std::size_t descriptor_queries = 0;      ///< descriptor look-ups
  std::size_t descriptor_hypotheses = 0;   ///< hypotheses verified by branch and bound
  std::size_t descriptor_accepted = 0;     ///< closures found through descriptors that entered the graph
  double descriptor_seconds = 0.0;         ///< time of describing, indexing, looking up and verifying [s]
  std::size_t optimizations = 0;
  double optimization_seconds = 0.0;
  double total_seconds = 0.0;
};

/// Incremental SLAM: feed frames in log order with `add`, then `finish`.
class Slam {
 public:
  explicit Slam(const SlamOptions& options = {});
  ~Slam();
  Slam(const Slam&) = delete;
  Slam& operator=(const Slam&) = delete;

  /// Processes the next frame. Never throws for bad data in a frame (too few points, missing or
  /// jumping odometry, time going backwards): it records an Event and goes on.
  void add(const Frame& frame);
  /// Final pose-graph optimisation; the estimates are final afterwards. Idempotent.
  void finish();

  /// Every scan added so far, in input order, with its current estimate.
  std::vector<ScanEstimate> trajectory() const;
  const std::vector<Node>& nodes() const;
  /// Sequential, odometry and loop constraints (accepted and rejected).
  const std::vector<Constraint>& constraints() const;
  const std::vector<Event>& events() const;
  const SlamStats& stats() const;
  const SlamOptions& options() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace lidar2d::slam
