#pragma once
/// @file
/// The SLAM options: the plain struct the library takes (`SlamOptions`, with the defaults) and the
/// table that declares, once per option, its name in YAML configs, its unit, its allowed range and
/// what it means (`kSlamOptionTable`). Validation, the CLI's config files, `lidar2d slam
/// --dump-config`, the `options` of summary.json and the table in docs/slam.md all come from it.

#include <cstddef>
#include <limits>
#include <numbers>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <variant>

#include "lidar2d/slam/pose_graph.hpp"

namespace lidar2d::slam {

inline constexpr double kDeg = std::numbers::pi / 180.0;

/// Every SLAM parameter, with its default. What each one means, its unit and its allowed range are
/// declared once, in `kSlamOptionTable` below (printed by `lidar2d slam --dump-config`, listed in
/// docs/slam.md). Units are in the names: `_m` metres, `_s` seconds, `_rad` radians (degrees, `_deg`, in YAML
/// configs); the others are counts, fractions or flags.
struct SlamOptions {
  // --- input ---
  bool use_odometry = true;
  double max_range_m = 30.0;
  std::size_t min_points = 20;
  bool drop_moving_objects = true;

  // --- motion filter: which scans become nodes ---
  double node_min_translation_m = 0.25;
  double node_min_rotation_rad = 10.0 * kDeg;
  double node_max_interval_s = 5.0;

  // --- front end ---
  int local_map_nodes = 12;
  bool front_end_likelihood_field = false;
  double icp_max_correspondence_m = 0.5;
  double scan_voxel_m = 0.05;
  double map_voxel_m = 0.05;
  int normal_neighbors = 10;
  double max_line_flatness = 0.5;
  double match_inlier_distance_m = 0.1;
  double min_explained_fraction = 0.5;
  bool refine_odometry_placement = true;
  double refine_min_turn_sigmas = 2.0;
  double alternative_start_m = 0.1;
  double alternative_start_rad = 3.0 * kDeg;
  double fallback_linear_window_m = 1.0;
  double fallback_angular_window_rad = 30.0 * kDeg;
  double degeneracy_threshold = 0.04;
  double search_max_linear_window_m = 3.0;
  double search_max_angular_window_rad = 180.0 * kDeg;
  double time_gap_s = 2.0;

  // --- motion prior: the prediction of each scan's pose and its uncertainty ---
  double prior_odometry_sigma_m = 0.05;
  double prior_odometry_sigma_per_m = 0.1;
  double prior_odometry_sigma_m_per_s = 0.01;
  double prior_odometry_sigma_rad = 1.0 * kDeg;
  double prior_odometry_sigma_per_turn = 0.1;
  double prior_odometry_sigma_rad_per_m = 2.0 * kDeg;
  bool scale_odometry = false;
  bool prior_odometry_learn_noise = true;
  double prior_velocity_sigma_m = 0.1;
  double prior_velocity_sigma_m_per_s = 1.0;
  double prior_velocity_sigma_rad = 5.0 * kDeg;
  double prior_velocity_sigma_rad_per_s = 100.0 * kDeg;
  double prior_velocity_spread_sigmas = 2.0;
  double max_speed_m_per_s = 5.0;
  double max_turn_rate_rad_per_s = 360.0 * kDeg;
  double prior_gate_sigmas = 4.0;
  double prior_nats_per_point = 1.0;

  // --- submaps ---
  int submap_nodes = 30;

  // --- loop closure ---
  double loop_search_radius_m = 5.0;
  int loop_search_every_nodes = 5;
  int loop_searches_per_node = 2;
  // Half-width of the proximity search's window: it must reach the revisit from where the
  // running estimate puts it, which on long loops in corridors drifts 2-3 m before the loop closes
  // (docs/slam.md, Loop closure).
  double loop_linear_window_m = 3.0;
  // The window widens with the path travelled since the latest accepted closure (the estimate
  // drifts with it): loop_window_per_m of that path, between loop_linear_window_m and
  // loop_max_linear_window_m; the candidate submaps' radius widens with it. It is also the drift a
  // closure may show against the estimate and the latest closure (LoopClosure::contradictsLatestClosure).
  double loop_window_per_m = 0.03;
  double loop_max_linear_window_m = 8.0;
  double loop_angular_window_rad = 15.0 * kDeg;
  double loop_min_score = 0.55;
  double loop_min_explained_fraction = 0.7;
  int loop_confirm_window_nodes = 30;
  double loop_confirm_tolerance_m = 0.2;
  double loop_confirm_tolerance_rad = 2.0 * kDeg;
  int loop_link_memory_nodes = 15;

  // --- loop closure by descriptors (drift too large for the proximity search) ---
  bool descriptor_loops = true;
  int descriptor_every_nodes = 10;
  int descriptor_quiet_nodes = 30;
  int descriptor_min_age_nodes = 60;
  double descriptor_min_votes = 6.0;
  int descriptor_max_candidates = 3;
  std::size_t descriptor_max_lines = 14;
  double descriptor_linear_window_m = 0.6;
  double descriptor_angular_window_rad = 6.0 * kDeg;
  double descriptor_max_correction_m = 2.0;
  double descriptor_drift_fraction = 0.1;
  double descriptor_max_rotation_rad = 30.0 * kDeg;
  double descriptor_max_see_through = 0.05;

  // --- pose graph ---
  double sequential_sigma_m = 0.02;
  double sequential_sigma_rad = 0.25 * kDeg;
  double loop_sigma_m = 0.05;
  double loop_sigma_rad = 1.0 * kDeg;
  double loop_huber = 1.0;
  double odometry_sigma_m = 0.05;
  double odometry_sigma_rad = 2.0 * kDeg;
  double odometry_sigma_per_m = 0.1;
  double odometry_sigma_per_turn = 0.1;
  int optimize_every_nodes = 30;
  int intermediate_iterations = 10;
  bool intermediate_rigid_submaps = true;
  int intermediate_free_submaps = 8;
  bool back_end_thread = true;
  /// Solver of the final optimisation (`max_iterations`), of every one (`threads`) and the loop
  /// closures' dynamic covariance scaling (`dcs_phi`: 9, the 97th percentile of a right closure's
  /// chi2 with 3 degrees of freedom); its `function_tolerance` and `dcs_rounds` are not SLAM options.
  PoseGraphOptions graph{.dcs_phi = 9.0};

  /// Throws `lidar2d::Error` (kInvalidArgument) naming the first field, in table order, that is
  /// outside its range in `kSlamOptionTable`.
  void validate() const;
};

/// The values an option may take, in the option's unit. An unbounded side is infinite; a bounded
/// floating-point option must also be finite.
struct OptionRange {
  double min = -std::numeric_limits<double>::infinity();
  bool min_open = false;  ///< `min` itself excluded
  double max = std::numeric_limits<double>::infinity();
  bool max_open = false;  ///< `max` itself excluded

  static constexpr OptionRange any() { return {}; }
  static constexpr OptionRange above(double min) { return {min, true}; }
  static constexpr OptionRange atLeast(double min) { return {min, false}; }
  /// (0, 1]
  static constexpr OptionRange fraction() { return {0.0, true, 1.0, false}; }
  /// [0, 1]
  static constexpr OptionRange unitInterval() { return {0.0, false, 1.0, false}; }

  bool contains(double v) const;
  /// The rule as an error message states it: "must be a finite value > 0", "must be in (0, 1]",
  /// or, for integers, "must be >= 3".
  std::string requirement(bool integer) const;
  /// The rule in short: "> 0", ">= 3", "(0, 1]", or "any" when unbounded.
  std::string describe() const;
};

/// One row of the option table. Angles (unit "deg") are degrees in YAML, docs and `get`/`set`,
/// radians in `SlamOptions`.
struct SlamOption {
  /// An option's value; the alternative is the field's type.
  using Value = std::variant<bool, int, std::size_t, double>;
  using Ref = std::variant<bool& (*)(SlamOptions&), int& (*)(SlamOptions&), std::size_t& (*)(SlamOptions&),
                           double& (*)(SlamOptions&)>;

  std::string_view field;  ///< the SlamOptions member, e.g. "node_min_rotation_rad", "graph.threads"
  Ref ref;                 ///< accessor of that member
  std::string_view group;  ///< heading the option is listed under ("front end", "pose graph", ...)
  std::string_view unit;   ///< "m", "deg", "s", "m/m", or what is counted ("nodes", "fraction", "flag", ...)
  OptionRange range;       ///< allowed values, in `unit` (flags: any)
  std::string_view help;   ///< what the option does

  /// The name in YAML configs, docs and summary.json: `field` with '_' for '.', and `_deg` for the
  /// `_rad` of an angle ("node_min_rotation_deg", "graph_threads").
  std::string name() const;
  /// An angle or an angular rate ("deg", "deg/s", "deg/m"): radians in SlamOptions.
  bool isAngle() const { return unit == "deg" || unit.starts_with("deg/"); }
  bool isFlag() const { return std::holds_alternative<bool& (*)(SlamOptions&)>(ref); }
  /// The value in `unit`. An angle is the shortest decimal number of degrees that `set` turns back
  /// into exactly the same radians (30, not 29.999999999999996), when there is one.
  Value get(const SlamOptions& o) const;
  /// Stores `v` (in `unit`; an angle becomes `v * kDeg`) into `o` without checking the range.
  /// Throws `lidar2d::Error` (kInvalidArgument) when `v` does not hold the field's type.
  void set(SlamOptions& o, const Value& v) const;
  /// The requirement `o`'s value breaks ("must be a finite value > 0"), or nothing when in range.
  std::optional<std::string> rangeError(const SlamOptions& o) const;
};

// `path` is a SlamOptions member (e.g. graph.threads): its name as text and its accessor, from one
// spelling.
// clang-format off
#define LIDAR2D_SLAM_FIELD(path) #path, SlamOption::Ref(+[](SlamOptions& o) -> auto& { return o.path; })
// clang-format on

/// Every SLAM option, in SlamOptions' order: the one declaration of their names, units, ranges and
/// meanings. Row: member, group, unit, range, help.
inline constexpr SlamOption kSlamOptionTable[] = {
    {LIDAR2D_SLAM_FIELD(use_odometry), "input", "flag", OptionRange::any(),
     "use the frames' wheel odometry as the prediction when present (--no-odometry sets false)"},
    {LIDAR2D_SLAM_FIELD(max_range_m), "input", "m", OptionRange::above(0),
     "returns at or beyond this range are not matched"},
    {LIDAR2D_SLAM_FIELD(min_points), "input", "points", OptionRange::atLeast(3),
     "a scan with fewer valid points is not matched (its pose is the prediction)"},
    {LIDAR2D_SLAM_FIELD(drop_moving_objects), "input", "flag", OptionRange::any(),
     "leave out small objects (0.8 m across at most) that moved: those that kept their place in the robot's "
     "frame while the odometry moved it 0.5 m (people walking with it, its own parts) and those standing where "
     "the scan from 0.5 m back saw through (people crossing); needs odometry"},
    {LIDAR2D_SLAM_FIELD(node_min_translation_m), "motion filter", "m", OptionRange::atLeast(0),
     "a scan becomes a node when it moved this far from the last node"},
    {LIDAR2D_SLAM_FIELD(node_min_rotation_rad), "motion filter", "deg", OptionRange::atLeast(0),
     "... or turned this much"},
    {LIDAR2D_SLAM_FIELD(node_max_interval_s), "motion filter", "s", OptionRange::above(0),
     "... or this much time passed"},
    {LIDAR2D_SLAM_FIELD(local_map_nodes), "front end", "nodes", OptionRange::atLeast(1),
     "nodes whose points form the local map"},
    {LIDAR2D_SLAM_FIELD(front_end_likelihood_field), "front end", "flag", OptionRange::any(),
     "match scans against the local map's likelihood field (Gauss-Newton, two resolutions) instead of "
     "point-to-line ICP"},
    {LIDAR2D_SLAM_FIELD(icp_max_correspondence_m), "front end", "m", OptionRange::above(0),
     "ICP pairs farther apart are rejected"},
    {LIDAR2D_SLAM_FIELD(scan_voxel_m), "front end", "m", OptionRange::above(0),
     "a scan keeps one point (the centroid) per cell of this size before matching"},
    {LIDAR2D_SLAM_FIELD(map_voxel_m), "front end", "m", OptionRange::above(0),
     "local maps and submaps keep one point (the centroid) per cell of this size"},
    {LIDAR2D_SLAM_FIELD(normal_neighbors), "front end", "points", OptionRange::atLeast(2),
     "map points fitted per line normal (point-to-line ICP); more than one scan needs, since the local map"
     " stacks several scans"},
    {LIDAR2D_SLAM_FIELD(max_line_flatness), "front end", "ratio", OptionRange::fraction(),
     "a neighbourhood whose spread across its line exceeds this share of its spread along it gets no "
     "normal"},
    {LIDAR2D_SLAM_FIELD(match_inlier_distance_m), "front end", "m", OptionRange::above(0),
     "a point within this distance of the map counts as explained"},
    {LIDAR2D_SLAM_FIELD(min_explained_fraction), "front end", "fraction", OptionRange::fraction(),
     "a match explaining less of the scan is poor: the correlative search runs next"},
    {LIDAR2D_SLAM_FIELD(refine_odometry_placement), "front end", "flag", OptionRange::any(),
     "a scan the odometry places (unmatched) goes to the best match near the prediction when it lies within "
     "1 sigma and explains 30% of the points that overlap the local map"},
    {LIDAR2D_SLAM_FIELD(refine_min_turn_sigmas), "front end", "sigmas", OptionRange::atLeast(0),
     "... a degenerate match only when it turns the odometry's heading by more than this many of its own "
     "heading sigmas (less is the match's noise)"},
    {LIDAR2D_SLAM_FIELD(alternative_start_m), "front end", "m", OptionRange::atLeast(0),
     "when the predicted step exceeds this (or the angle below), ICP also starts from no motion and from "
     "constant velocity, and the result explaining the most points wins"},
    {LIDAR2D_SLAM_FIELD(alternative_start_rad), "front end", "deg", OptionRange::atLeast(0),
     "... or turns more than this"},
    {LIDAR2D_SLAM_FIELD(fallback_linear_window_m), "front end", "m", OptionRange::above(0),
     "smallest half-width of the correlative search window around the prediction (the window is three "
     "sigmas of the motion prior, at least this)"},
    {LIDAR2D_SLAM_FIELD(fallback_angular_window_rad), "front end", "deg", OptionRange::above(0),
     "its smallest angular half-width"},
    {LIDAR2D_SLAM_FIELD(degeneracy_threshold), "front end", "fraction", OptionRange::atLeast(0),
     "smallest eigenvalue of the translational information per matched point (the share of line normals "
     "along the weakest direction) below which the translation along it is taken from the prediction"},
    {LIDAR2D_SLAM_FIELD(search_max_linear_window_m), "front end", "m", OptionRange::above(0),
     "largest half-width of that window (an uncertain prior, after a gap or without odometry)"},
    {LIDAR2D_SLAM_FIELD(search_max_angular_window_rad),
     "front end",
     "deg",
     {0.0, true, 180.0, false},
     "its largest angular half-width"},
    {LIDAR2D_SLAM_FIELD(time_gap_s), "front end", "s", OptionRange::above(0),
     "scans further apart in time than this and than five times the log's usual interval are reported as "
     "a gap"},
    {LIDAR2D_SLAM_FIELD(prior_odometry_sigma_m), "motion prior", "m", OptionRange::above(0),
     "sigma of an odometry step's translation (x and y): this ..."},
    {LIDAR2D_SLAM_FIELD(prior_odometry_sigma_per_m), "motion prior", "m/m", OptionRange::atLeast(0),
     "... plus this share of the distance ..."},
    {LIDAR2D_SLAM_FIELD(prior_odometry_sigma_m_per_s), "motion prior", "m/s", OptionRange::atLeast(0),
     "... plus this much per second the step took"},
    {LIDAR2D_SLAM_FIELD(prior_odometry_sigma_rad), "motion prior", "deg", OptionRange::above(0),
     "sigma of an odometry step's rotation: this ..."},
    {LIDAR2D_SLAM_FIELD(prior_odometry_sigma_per_turn), "motion prior", "rad/rad", OptionRange::atLeast(0),
     "... plus this share of the turn ..."},
    {LIDAR2D_SLAM_FIELD(prior_odometry_sigma_rad_per_m), "motion prior", "deg/m", OptionRange::atLeast(0),
     "... plus this much per metre travelled"},
    {LIDAR2D_SLAM_FIELD(prior_odometry_learn_noise), "motion prior", "flag", OptionRange::any(),
     "narrow those sigmas (never below their constant terms) to what the odometry's long steps strayed "
     "from the scans' matches: the upper decile of the last 30, in sigmas (docs/slam.md, motion prior)"},
    {LIDAR2D_SLAM_FIELD(scale_odometry), "motion prior", "flag", OptionRange::any(),
     "scale odometry distances by the ratio the scans measured over the recent steps they pinned, from "
     "10 m of such steps (summary.json's odometry_scale, measured either way; off: it moved the corrected "
     "logs' ATE the wrong way, BENCHMARK.md)"},
    {LIDAR2D_SLAM_FIELD(prior_velocity_sigma_m), "motion prior", "m", OptionRange::above(0),
     "sigma of the constant-velocity prediction's translation (no odometry, or odometry not plausible): "
     "this ..."},
    {LIDAR2D_SLAM_FIELD(prior_velocity_sigma_m_per_s), "motion prior", "m/s", OptionRange::atLeast(0),
     "... plus this much per second since the previous scan"},
    {LIDAR2D_SLAM_FIELD(prior_velocity_sigma_rad), "motion prior", "deg", OptionRange::above(0),
     "sigma of its rotation: this ..."},
    {LIDAR2D_SLAM_FIELD(prior_velocity_sigma_rad_per_s), "motion prior", "deg/s", OptionRange::atLeast(0),
     "... plus this much per second since the previous scan"},
    {LIDAR2D_SLAM_FIELD(prior_velocity_spread_sigmas), "motion prior", "factor", OptionRange::atLeast(0),
     "in a log whose usual interval widens those sigmas beyond the correlative search's largest window "
     "(scans a second or more apart), they are at most this many times the spread of the last 20 steps "
     "about their median (the robot's own recent motion; at least half the smallest window); 0: off"},
    {LIDAR2D_SLAM_FIELD(max_speed_m_per_s), "motion prior", "m/s", OptionRange::above(0),
     "an odometry step faster than this over the time it took is not plausible: the constant-velocity "
     "prior replaces it, and the scan decides between the two"},
    {LIDAR2D_SLAM_FIELD(max_turn_rate_rad_per_s), "motion prior", "deg/s", OptionRange::above(0),
     "... nor one turning faster than this"},
    {LIDAR2D_SLAM_FIELD(prior_gate_sigmas), "motion prior", "sigmas", OptionRange::above(0),
     "a match farther from the prediction than this (Mahalanobis distance under the prior) contradicts the "
     "prior ..."},
    {LIDAR2D_SLAM_FIELD(prior_nats_per_point), "motion prior", "nats", OptionRange::above(0),
     "... and wins only when its log-posterior beats the best match within the gate: this much "
     "log-likelihood per point it explains, minus half its squared distance in sigmas"},
    {LIDAR2D_SLAM_FIELD(submap_nodes), "submaps", "nodes", OptionRange::atLeast(2), "nodes per submap"},
    {LIDAR2D_SLAM_FIELD(loop_search_radius_m), "loop closure", "m", OptionRange::above(0),
     "finished submaps with a node nearer than this to the node are candidates"},
    {LIDAR2D_SLAM_FIELD(loop_search_every_nodes), "loop closure", "nodes", OptionRange::atLeast(1),
     "branch-and-bound search for one node in this many"},
    {LIDAR2D_SLAM_FIELD(loop_searches_per_node), "loop closure", "searches", OptionRange::atLeast(1),
     "at most this many searches per node, nearest submaps first"},
    {LIDAR2D_SLAM_FIELD(loop_linear_window_m), "loop closure", "m", OptionRange::above(0),
     "branch-and-bound window half-width (the least: see loop_window_per_m)"},
    {LIDAR2D_SLAM_FIELD(loop_window_per_m), "loop closure", "m/m", OptionRange::atLeast(0),
     "the window widens to this share of the path travelled since the latest accepted closure (the "
     "estimate's drift), and the candidate submaps' radius with it; a closure contradicting both the "
     "estimate and that closure by over 1 m plus this share is refused ..."},
    {LIDAR2D_SLAM_FIELD(loop_max_linear_window_m), "loop closure", "m", OptionRange::above(0),
     "... up to this half-width"},
    {LIDAR2D_SLAM_FIELD(loop_angular_window_rad), "loop closure", "deg", OptionRange::above(0),
     "its angular half-width"},
    {LIDAR2D_SLAM_FIELD(loop_min_score), "loop closure", "fraction", OptionRange::fraction(),
     "correlative score a closure needs"},
    {LIDAR2D_SLAM_FIELD(loop_min_explained_fraction), "loop closure", "fraction", OptionRange::fraction(),
     "share of the points within match_inlier_distance_m after ICP refinement a closure needs"},
    {LIDAR2D_SLAM_FIELD(loop_confirm_window_nodes), "loop closure", "nodes", OptionRange::atLeast(1),
     "a searched closure is accepted only when a second search from a node at most this many nodes later "
     "agrees with it (through the front end's relative poses)"},
    {LIDAR2D_SLAM_FIELD(loop_confirm_tolerance_m), "loop closure", "m", OptionRange::above(0),
     "how closely the second search must agree"},
    {LIDAR2D_SLAM_FIELD(loop_confirm_tolerance_rad), "loop closure", "deg", OptionRange::above(0), "... and in angle"},
    {LIDAR2D_SLAM_FIELD(loop_link_memory_nodes), "loop closure", "nodes", OptionRange::atLeast(0),
     "a closure to a submap linked within this many nodes is found by ICP from the linked estimate instead"
     " of a search"},
    {LIDAR2D_SLAM_FIELD(descriptor_loops), "loop closure by descriptors", "flag", OptionRange::any(),
     "look nodes up by the localization module's line-pair descriptors in the submaps the proximity search"
     " does not cover (drift too large for it); hypotheses are verified like searched closures"},
    {LIDAR2D_SLAM_FIELD(descriptor_every_nodes), "loop closure by descriptors", "nodes", OptionRange::atLeast(1),
     "look up one node in this many"},
    {LIDAR2D_SLAM_FIELD(descriptor_quiet_nodes), "loop closure by descriptors", "nodes", OptionRange::atLeast(0),
     "look up only when no closure was accepted within this many nodes"},
    {LIDAR2D_SLAM_FIELD(descriptor_min_age_nodes), "loop closure by descriptors", "nodes", OptionRange::atLeast(0),
     "submaps whose last node is fewer than this many nodes old are not looked up"},
    {LIDAR2D_SLAM_FIELD(descriptor_min_votes), "loop closure by descriptors", "votes", OptionRange::atLeast(1),
     "line-pair votes a hypothesis needs"},
    {LIDAR2D_SLAM_FIELD(descriptor_max_candidates), "loop closure by descriptors", "hypotheses",
     OptionRange::atLeast(1), "hypotheses verified per look-up, most votes first"},
    {LIDAR2D_SLAM_FIELD(descriptor_max_lines), "loop closure by descriptors", "lines", OptionRange::atLeast(2),
     "longest lines of a scan described and looked up"},
    {LIDAR2D_SLAM_FIELD(descriptor_linear_window_m), "loop closure by descriptors", "m", OptionRange::above(0),
     "branch-and-bound window half-width around a hypothesis"},
    {LIDAR2D_SLAM_FIELD(descriptor_angular_window_rad), "loop closure by descriptors", "deg", OptionRange::above(0),
     "its angular half-width"},
    {LIDAR2D_SLAM_FIELD(descriptor_max_correction_m), "loop closure by descriptors", "m", OptionRange::atLeast(0),
     "the correction a descriptor closure makes to the current estimate must be at most this plus "
     "descriptor_drift_fraction times the path travelled since the submap"},
    {LIDAR2D_SLAM_FIELD(descriptor_drift_fraction), "loop closure by descriptors", "m/m", OptionRange::atLeast(0),
     "drift allowed per metre of path (see descriptor_max_correction_m)"},
    {LIDAR2D_SLAM_FIELD(descriptor_max_rotation_rad), "loop closure by descriptors", "deg", OptionRange::atLeast(0),
     "... and it may turn the current estimate by at most this (aliased places are typically turned by 90 "
     "or 180 degrees)"},
    {LIDAR2D_SLAM_FIELD(descriptor_max_see_through), "loop closure by descriptors", "fraction",
     OptionRange::unitInterval(),
     "a hypothesis is rejected when more of the scan's beams than this pass through the submap's walls "
     "(more than 0.3 m before their endpoint)"},
    {LIDAR2D_SLAM_FIELD(sequential_sigma_m), "pose graph", "m", OptionRange::above(0),
     "sigma of the front end's relative pose between nodes"},
    {LIDAR2D_SLAM_FIELD(sequential_sigma_rad), "pose graph", "deg", OptionRange::above(0), "... in angle"},
    {LIDAR2D_SLAM_FIELD(loop_sigma_m), "pose graph", "m", OptionRange::above(0), "sigma of a loop-closure constraint"},
    {LIDAR2D_SLAM_FIELD(loop_sigma_rad), "pose graph", "deg", OptionRange::above(0), "... in angle"},
    {LIDAR2D_SLAM_FIELD(loop_huber), "pose graph", "sigmas", OptionRange::above(0),
     "Huber scale on the whitened residual of loop closures found by proximity"},
    {LIDAR2D_SLAM_FIELD(odometry_sigma_m), "pose graph", "m", OptionRange::above(0),
     "sigma of an odometry constraint between nodes: this ..."},
    {LIDAR2D_SLAM_FIELD(odometry_sigma_per_m), "pose graph", "m/m", OptionRange::atLeast(0),
     "... plus this share of its distance"},
    {LIDAR2D_SLAM_FIELD(odometry_sigma_rad), "pose graph", "deg", OptionRange::above(0), "... in angle: this ..."},
    {LIDAR2D_SLAM_FIELD(odometry_sigma_per_turn), "pose graph", "rad/rad", OptionRange::atLeast(0),
     "... plus this share of its rotation (a robot whose odometry is better than its scan matching, a short-range "
     "laser with good wheel odometry: smaller values; BENCHMARK.md, SLAM, the floor)"},
    {LIDAR2D_SLAM_FIELD(optimize_every_nodes), "pose graph", "nodes", OptionRange::atLeast(1),
     "optimise this many nodes after a closure found by search (10 times as many after other closures)"},
    {LIDAR2D_SLAM_FIELD(intermediate_iterations), "pose graph", "iterations", OptionRange::atLeast(1),
     "solver iterations of the optimisations during the run"},
    {LIDAR2D_SLAM_FIELD(intermediate_rigid_submaps), "pose graph", "flag", OptionRange::any(),
     "the optimisations during the run hold each finished submap's nodes rigid to each other (one pose per "
     "submap): their cost grows with the submaps, not the nodes; the final optimisation moves every node ..."},
    {LIDAR2D_SLAM_FIELD(intermediate_free_submaps), "pose graph", "submaps", OptionRange::atLeast(0),
     "... but for the newest submaps: the one being built and this many finished ones, whose nodes move each "
     "on its own"},
    {LIDAR2D_SLAM_FIELD(graph.max_iterations), "pose graph", "iterations", OptionRange::atLeast(1),
     "solver iterations of the final optimisation (and after a descriptor closure)"},
    {LIDAR2D_SLAM_FIELD(graph.dcs_phi), "pose graph", "chi2", OptionRange::atLeast(0),
     "dynamic covariance scaling of the loop closures: a closure whose whitened squared "
     "residual chi2 at the solution exceeds this is scaled by 2 phi / (phi + chi2) and the graph solved "
     "again (0: off)"},
    {LIDAR2D_SLAM_FIELD(graph.threads), "pose graph", "threads", OptionRange::atLeast(1),
     "Ceres threads of every optimisation (another count sums in another order: runs with different "
     "counts may differ, runs with the same count do not)"},
    {LIDAR2D_SLAM_FIELD(back_end_thread), "pose graph", "flag", OptionRange::any(),
     "the nodes' graph work (constraints, loop searches, optimisations) runs on a second thread, in "
     "order, while the next scans are tracked (the results are the same as without it)"},
};

#undef LIDAR2D_SLAM_FIELD

/// kSlamOptionTable as a range.
inline std::span<const SlamOption> slamOptionTable() { return kSlamOptionTable; }

/// The option whose `name()` is `name`, or nullptr.
const SlamOption* findSlamOption(std::string_view name);

/// `v` as text: true/false, integers, and the shortest decimal that reads back to the same double.
std::string formatOptionValue(const SlamOption::Value& v);

}  // namespace lidar2d::slam
