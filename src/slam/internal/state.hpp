#pragma once
// What a SLAM run has built so far (scans, nodes, submaps, constraints, events, counters) and the
// matcher settings derived from SlamOptions: shared by the parts of the pipeline (front end, loop
// closure, descriptor loops, pose graph), which Slam::Impl (slam.cpp) wires together.

#include <Eigen/Core>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstddef>
#include <memory>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "lidar2d/core/frame.hpp"
#include "lidar2d/localization/lines.hpp"
#include "lidar2d/localization/localizer.hpp"
#include "lidar2d/registration/correlative.hpp"
#include "lidar2d/registration/icp.hpp"
#include "lidar2d/registration/likelihood_field.hpp"
#include "lidar2d/slam/slam.hpp"
#include "lidar2d/slam/state_file.hpp"

namespace lidar2d::slam::internal {

/// How the front end placed a scan against the node before it.
enum class Placement {
  kMatched,   ///< a match against the local map
  kOdometry,  ///< unmatched, placed by odometry alone at its prediction
  kRefined,   ///< unmatched, placed by odometry at a weak match near its prediction
};

using Clock = std::chrono::steady_clock;

inline double secondsSince(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

/// One scan's record (what the state file keeps: the node it hangs off and its pose relative to
/// that node), and its session.
struct ScanRecord : State::Scan {
  std::size_t session = 0;  // index into SlamState::sessions
};

/// A submap: consecutive nodes, their points in the frame of the first (anchor) node.
struct Submap {
  std::size_t anchor = 0;
  std::vector<std::size_t> nodes;
  bool finished = false;
  Points2 points_anchor;
  Eigen::Vector2d nodes_min_anchor = Eigen::Vector2d::Zero();  // the box its nodes were in (anchor frame)
  Eigen::Vector2d nodes_max_anchor = Eigen::Vector2d::Zero();
  std::unique_ptr<registration::IcpTarget> icp;
  std::unique_ptr<registration::CorrelativeGrid> grid;  // built at the first branch-and-bound search
  std::unique_ptr<registration::CorrelativeGrid> coarse_grid;  // ... of the relocalization by search
  std::optional<std::size_t> last_link_node;
  SE2 last_link_T_anchor_node;
  std::optional<Constraint> pending;           // searched closure awaiting confirmation
  std::optional<Constraint> wide_pending;      // ... found by the widened window: only another confirms it
  std::optional<Constraint> untied_pending;    // ... found by the relocalization search (searchUntied)
  std::unique_ptr<localization::Database> db;  // line-pair descriptors of its nodes (anchor frame)
};

/// The settings of every matcher SLAM runs, derived once from SlamOptions (makeMatcherSettings).
struct MatcherSettings {
  registration::IcpOptions icp;                        ///< front end: scan to local map
  registration::IcpOptions loop_icp;                   ///< refinement of loop closures
  registration::LikelihoodFieldOptions local_lf;       ///< front end with front_end_likelihood_field
  registration::CorrelativeOptions fallback;           ///< front end's search when ICP explains too little
  registration::CorrelativeOptions loop_search;        ///< branch and bound for loop closures
  registration::CorrelativeOptions descriptor_search;  ///< ... around a descriptor hypothesis
  localization::LocalizerOptions descriptor_query;     ///< line extraction and lookup of descriptor loops
  localization::DatabaseOptions descriptor_db;         ///< each finished submap's descriptor index
};
MatcherSettings makeMatcherSettings(const SlamOptions& opt);

/// The run's data. Node-indexed vectors all have one entry per node.
struct SlamState {
  /// Throws `lidar2d::Error` when `o` is invalid (SlamOptions::validate).
  explicit SlamState(const SlamOptions& o) : opt(validated(o)), match(makeMatcherSettings(opt)) {}

  const SlamOptions opt;
  const MatcherSettings match;

  std::vector<State::Session> sessions;  // the logs mapped so far, in order (the last one is being added)
  std::vector<ScanRecord> scans;
  std::vector<Node> nodes;
  std::vector<Points2> node_points;                         // robot frame, voxel-filtered
  std::vector<std::pair<LaserScan, SE2>> node_scans;        // each node's scan and T_robot_laser (submap grids)
  std::vector<std::optional<SE2>> node_odometry;            // trusted odometry poses (odometry constraints)
  std::vector<std::vector<localization::Line>> node_lines;  // robot frame, longest first (descriptor loops)
  std::vector<double> node_path_m;                          // front-end path length from the first node [m]
  std::vector<std::size_t> node_frame_index;                // Frame::index of each node's scan
  std::vector<std::size_t> restarts;                        // nodes where the front end restarted (lost track)
  std::vector<Submap> submaps;
  std::vector<Constraint> constraints;
  std::vector<PoseGraphEdge> edges;  // of the accepted constraints
  std::vector<Event> events;
  // Events of the back end (loop closure, optimisation), which may run on its own thread while the
  // front end records its own events: merged into `events` when the two meet (Slam::Impl::sync).
  std::vector<Event> back_end_events;
  SlamStats stats;

  // Back end.
  SE2 T_world_local;
  std::optional<std::size_t> last_loop_node;  // latest node with an accepted closure
  /// Half-width of the proximity search's window at node `n`: loop_window_per_m of the path
  /// travelled since the latest accepted closure (all of it before the first), in quadrature with
  /// kPlacedWindowSigmas of node_placed_sigma_m, within [loop_linear_window_m,
  /// loop_max_linear_window_m]. The estimate drifts along an unclosed path.
  double proximityWindowM(std::size_t n) const {
    const double open = node_path_m[n] - (last_loop_node && *last_loop_node <= n ? node_path_m[*last_loop_node] : 0.0);
    const double placed = n < node_placed_sigma_m.size() ? kPlacedWindowSigmas * node_placed_sigma_m[n] : 0.0;
    return std::clamp(std::hypot(opt.loop_window_per_m * open, placed), opt.loop_linear_window_m,
                      std::max(opt.loop_linear_window_m, opt.loop_max_linear_window_m));
  }
  /// The position sigma [m] the steps the front end did not match (placed by the odometry, or
  /// refined by a weak match) give each node since the latest accepted closure
  /// (propagatePlacedCovariance): each such step's sigmas, carried forward by the path after it (a
  /// heading error turns the rest of the path). Steps the scans matched drift as loop_window_per_m
  /// says; these may drift much more (keyframes metres apart: degrees on one step).
  std::vector<double> node_placed_sigma_m;
  Eigen::Matrix3d placed_cov = Eigen::Matrix3d::Zero();  // of the newest node (world frame)
  std::optional<std::size_t> placed_cov_since;           // last_loop_node when placed_cov was reset
  /// The window holds this many of those sigmas (with the matched steps' drift, in quadrature);
  /// three let the simulated office's look-alike rooms in (BENCHMARK.md, SLAM, sparser keyframes).
  static constexpr double kPlacedWindowSigmas = 2.0;
  // The first node of the current fragment (the front end lost track there) while no accepted
  // closure ties the fragment to the nodes before it: the descriptor search relocalizes its nodes
  // against every earlier submap, without the drift limits (its link is only the prediction).
  std::optional<std::size_t> untied_since;
  /// Nodes up to this one search for loop closures at every node (graphNode sets it after a node
  /// placed by the odometry without a match): the chain's drift there is less certain, and where a
  /// lost track's relocalization would have corrected it, these searches find the closures instead
  /// (BENCHMARK.md, SLAM).
  std::size_t search_every_node_until = 0;
  static constexpr std::size_t kSearchEveryNodeAfterPlaced = 30;
  // The odometry constraint across the latest lost track (indices into edges and constraints, and
  // its `to` node), while the fragment is untied: the relocalization checks it.
  using RestartOdometry = State::RestartOdometry;
  std::optional<RestartOdometry> restart_odometry;
  /// Whether an odometry constraint links the untied fragment to the map before it (false for a
  /// resumed session or a lost track without odometry: the fragment's place is only a guess).
  bool untiedHasOdometryLink() const {
    return untied_since && restart_odometry && restart_odometry->node == *untied_since;
  }
  /// Sigmas the final optimisation gives the odometry links (rotation and x, y: at most) and the
  /// front end's links (rotation: at least), measured from the loop closures' cycles
  /// (calibrateFromCycles); 0: the links' own. This session's own: not saved.
  double cycles_odometry_sigma_rad = 0.0;
  double cycles_sequential_sigma_rad = 0.0;
  double cycles_odometry_sigma_m = 0.0;
  std::vector<double> edge_scale;  // of `edges` at the latest optimisation (PoseGraphSummary::edge_scale)
  /// Whether the latest optimisation faded edge k (a closure the rest of the graph contradicts:
  /// dynamic covariance scaling left it under half its weight); false for edges added since.
  bool edgeFaded(std::size_t k) const { return k < edge_scale.size() && edge_scale[k] < 0.5; }
  std::size_t nodes_since_optimization = 0;
  std::size_t loops_since_optimization = 0;
  bool searched_loop_pending = false;     // a searched closure was accepted since the last optimisation
  bool descriptor_loop_accepted = false;  // ... a descriptor closure, since the last node

  void event(const Frame& f, std::string what) { events.push_back({f.index, f.time, std::move(what)}); }

  static const SlamOptions& validated(const SlamOptions& o) {
    o.validate();
    return o;
  }

  /// Records `c`; an accepted one also becomes a pose-graph edge with this weight and Huber scale
  /// (loop closures may be faded by the pose graph's dynamic covariance scaling).
  void addEdge(Constraint c, const Eigen::Matrix3d& sqrt_info, double huber) {
    if (c.accepted) edges.push_back({c.from, c.to, c.T_from_to, sqrt_info, huber, c.kind == Constraint::Kind::kLoop});
    constraints.push_back(std::move(c));
  }
};

/// The square-root information of independent x, y (sigma `sm`) and theta (sigma `sr`).
inline Eigen::Matrix3d diagSqrtInfo(double sm, double sr) {
  return Eigen::Vector3d(1.0 / sm, 1.0 / sm, 1.0 / sr).asDiagonal();
}

/// The square-root information of a translation with sigma `s_along` along the unit direction
/// `dir` (0 information for infinity) and `s_across` across it, and theta with sigma `sr`;
/// `dir` in the frame of the edge's residual (its `from` node).
inline Eigen::Matrix3d directionalSqrtInfo(const Eigen::Vector2d& dir, double s_along, double s_across, double sr) {
  Eigen::Matrix3d sqrt_info = Eigen::Matrix3d::Zero();
  sqrt_info.block<1, 2>(0, 0) = dir.transpose() / s_along;
  sqrt_info.block<1, 2>(1, 0) = Eigen::Vector2d(-dir.y(), dir.x()).transpose() / s_across;
  sqrt_info(2, 2) = 1.0 / sr;
  return sqrt_info;
}

}  // namespace lidar2d::slam::internal
