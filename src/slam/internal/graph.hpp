#pragma once
// SLAM's pose graph: the constraints that tie each new node to the previous one, and when and how
// the graph of all nodes is optimised (slam::optimizePoseGraph).

#include <Eigen/Core>
#include <cstddef>
#include <string_view>

#include "src/slam/internal/state.hpp"

namespace lidar2d::slam::internal {

/// The constraints from node n-1 to node `n` (n > 0): the front end's relative pose (weak along
/// `dir_local`, the local-frame direction a degenerate match could not pin; only as strong as the
/// prediction after a `restart` or for Placement::kOdometry; held as a loop closure for
/// Placement::kRefined), and the odometry between them when both have trusted odometry (after a
/// `restart` it is recorded as SlamState::restart_odometry).
void addSequentialConstraints(SlamState& s, std::size_t n, bool restart, Placement placement, bool degenerate,
                              const Eigen::Vector2d& dir_local);

/// Sigmas of one step: translation (x and y) [m], rotation [rad].
struct StepSigmas {
  double m = 0.0;
  double rad = 0.0;
};

/// Sets SlamState::node_placed_sigma_m of node `n`, the newest (after its sequential constraints):
/// the covariance of the steps since the latest accepted closure that the front end did not match,
/// carried to node n, with the step to n added when its `placement` is not a match: `prior`, the
/// motion prior's sigmas of that step (its learnt odometry noise), for Placement::kOdometry; the
/// loop closures' sigmas (its link's in the graph) for Placement::kRefined.
void propagatePlacedCovariance(SlamState& s, std::size_t n, bool restart, Placement placement, StepSigmas prior);

/// Optimises every node's T_world_robot (node 0 fixed) with at most `iterations`; the front end's
/// local frame follows the newest node.
void optimize(SlamState& s, int iterations);

/// The end-of-run checks, after the final optimisation:
/// - never worse than odometry: where the link between two consecutive nodes is only the prediction
///   (the front end had lost track), no accepted loop closure ties the two sides into one map (then
///   the scans placed them: a kidnapped robot's odometry is wrong), and the optimised estimate
///   contradicts their odometry beyond the motion prior's gate, odometry wins (a constraint as
///   strong as the prior), with an event, and the graph is optimised again;
/// - fragments: the stretches between restarts that no accepted loop closure ties together; each
///   fragment beyond the first is reported as an event. Sets stats.fragments and
///   stats.odometry_wins.
void checkAtEnd(SlamState& s);

/// What the loop closures' cycles say of the two chains of links between consecutive nodes: for
/// each accepted closure over at least kCycleMinSteps node steps with both an odometry and a front
/// end (sequential) link at every step and no lost track, the closure against each chain's
/// composed links. The chains' errors per node step, heading [rad] and x and y [m], are the
/// medians of error^2 / steps, as sigmas.
struct CycleMeasure {
  std::size_t cycles = 0;
  double odometry_rad = 0.0;
  double front_end_rad = 0.0;
  double odometry_m = 0.0;
  double front_end_m = 0.0;
};
inline constexpr std::size_t kCycleMinSteps = 5;
/// The cycles needed before their measure reweighs the graph fully. From kCycleFadeFrom up to this
/// the weighting fades in (the sigmas blended geometrically, as above kCycleOdometryRatio), so that
/// one closure more or less does not switch it on or off: edmonton with perfect odometry had 19
/// cycles as read and 20 with its beams turned by half a degree (0.352 and 0.015 m ATE; their shares
/// differed too, 0.31 and 0.16).
inline constexpr std::size_t kCycleMinCount = 20;
/// Up to this many cycles their measure weighs nothing.
inline constexpr std::size_t kCycleFadeFrom = 10;
/// The odometry must err less than the front end in heading and in position, and the geometric mean
/// of the two shares must be under this. With realistic simulated odometry (a degree per metre), the
/// raw bags' own and the simulated lasers', it was at least 0.37 on every run of the robustness
/// benchmark with 20 cycles or more; with the truth as odometry 0.02-0.6 (BENCHMARK.md, SLAM).
inline constexpr double kCycleOdometryRatio = 0.25;
/// Between kCycleOdometryRatio and this the weighting fades (the sigmas blended geometrically from
/// the measured ones to the links' own), so that a share just above the threshold weighs almost as
/// one just below it: a threshold alone turned edmonton with perfect odometry from 0.016 m to 0.454 m
/// ATE on a change of the beam angles' last digits (shares 0.240 and 0.253). 0.32 lies 1.17 times
/// below the least share of a realistic run (0.373).
inline constexpr double kCycleOdometryRatioNone = 0.32;
/// The narrowest the odometry links' sigmas get (the closures' own error bounds the measure).
inline constexpr double kCycleMinSigmaRad = 0.02 * kDeg;
inline constexpr double kCycleMinSigmaM = 0.002;
CycleMeasure measureCycles(const SlamState& s);

/// Before the final optimisation: measures the cycles (stats loop_cycles, cycle_*) and, when there
/// are kCycleMinCount of them (partly from kCycleFadeFrom) and the odometry erred clearly less
/// than the front end per step (kCycleOdometryRatio; partly up to kCycleOdometryRatioNone), has
/// the final optimisation hold the odometry links' sigmas to the odometry's measured errors (never
/// wider than their own; at least kCycleMinSigmaRad and kCycleMinSigmaM) and the front end's links'
/// rotation sigma to at least theirs (SlamState::cycles_*; the state's edges keep their weights),
/// with an event. Odometry better than the scan matching, which the defaults' odometry weights
/// (made for odometry drifting a degree per metre) cannot know, then holds the map.
void calibrateFromCycles(SlamState& s);
/// How checkAtEnd's event of a fragment no closure tied begins.
inline constexpr std::string_view kFragmentEvent = "fragment from node ";

/// Records (stat loop_downweighted, one event each) the accepted closures the latest optimisation
/// scaled below half weight (PoseGraphOptions::dcs_phi): closures the rest of the graph contradicts.
void reportDownweighted(SlamState& s);

/// Optimises when due after a new node: at once after a descriptor closure (every node),
/// optimize_every_nodes nodes after a searched closure, 10x as many after other closures (then
/// with the older submaps rigid, slam::optimizePoseGraphRigid, unless intermediate_rigid_submaps is
/// off: a problem as many times smaller as a submap has nodes).
void optimizeIfDue(SlamState& s);

}  // namespace lidar2d::slam::internal
