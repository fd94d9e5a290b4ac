#pragma once
/// @file
/// An SE(2) pose graph solved with Ceres: nodes are poses `T_world_node`, edges are measured
/// relative poses `T_from_to` (so that `T_world_to = T_world_from * T_from_to`) with a square-root
/// information matrix and an optional robust loss. Used by the SLAM back end; usable on its own.

#include <Eigen/Core>
#include <cstddef>
#include <span>
#include <string>
#include <vector>

#include "lidar2d/core/se2.hpp"

namespace lidar2d::slam {

/// One relative-pose measurement between two nodes.
struct PoseGraphEdge {
  std::size_t from = 0;  ///< node index
  std::size_t to = 0;    ///< node index
  SE2 T_from_to;         ///< measured pose of `to` in the frame of `from`
  /// Square root of the information matrix of (x, y, theta) of the residual, expressed in the frame
  /// of `from` [1/m, 1/m, 1/rad]. The residual is
  ///   r = sqrt_information * (R_from^T (t_to - t_from) - t_meas, wrap(theta_to - theta_from - theta_meas)).
  Eigen::Matrix3d sqrt_information = Eigen::Matrix3d::Identity();
  /// > 0: a Huber loss with this scale on the whitened residual's squared norm (a loop closure that
  /// may be wrong); 0: plain least squares (trusted edges).
  double huber_scale = 0.0;
  /// May be faded by dynamic covariance scaling (PoseGraphOptions::dcs_phi): a measurement that may
  /// be wrong (a loop closure), unlike the odometry chain the scaling measures it against.
  bool scalable = false;
};

/// Solver settings.
struct PoseGraphOptions {
  int max_iterations = 50;      ///< Levenberg-Marquardt iterations, >= 1
  int threads = 2;              ///< Ceres threads for the Jacobian evaluation, >= 1
  double function_tolerance = 1e-7;  ///< relative cost change that ends the solve, > 0
  /// > 0: dynamic covariance scaling (Agarwal et al., ICRA 2013) of the `scalable` edges: after
  /// the solve, each one's residual is scaled by
  ///   s = min(1, 2 phi / (phi + chi2)),  chi2 = its whitened squared residual at the solution,
  /// and the graph solved again, for up to `dcs_rounds` rounds (until the scales settle). An edge
  /// the rest of the graph contradicts fades out instead of bending the graph; one that agrees
  /// keeps s = 1. Scaled at the solution, not at the start: a right closure after a long drift is
  /// far off before the first solve and agrees after it. 0: off.
  double dcs_phi = 0.0;
  int dcs_rounds = 3;  ///< >= 1
};

/// What a solve did.
struct PoseGraphSummary {
  double initial_cost = 0.0;  ///< 0.5 * sum of robustified squared residuals before
  double final_cost = 0.0;    ///< ... and after (with the final edge scales)
  int iterations = 0;
  bool usable = false;        ///< Ceres returned a usable solution (the poses were updated)
  double seconds = 0.0;       ///< wall time of the solve
  std::string message;        ///< Ceres' brief report
  /// Per edge, the final dynamic covariance scale s in (0, 1] (1 for edges not `scalable`, and for
  /// all when `dcs_phi` is 0).
  std::vector<double> edge_scale;
};

/// Optimises `poses` in place given `edges`; node `fixed` is held constant (gauge freedom). Nodes
/// no edge touches keep their pose. Throws `lidar2d::Error` (kInvalidArgument) when an edge names
/// a node outside `poses`, `fixed` is out of range, a pose or measurement is not finite, or an
/// option is out of its domain.
PoseGraphSummary optimizePoseGraph(std::vector<SE2>& poses, const std::vector<PoseGraphEdge>& edges, std::size_t fixed,
                                   const PoseGraphOptions& options = {});

/// As optimizePoseGraph, with the nodes in rigid groups: `group_of[i]` names node i's group
/// (numbers below the node count, in any order; one entry per node). The nodes of a group keep their
/// poses relative to each other and move as one body, whose parameter is the pose of the group's
/// first node; edges within a group are constant and left out (their `edge_scale` is 1). With
/// groups of tens of nodes the problem is that many times smaller: SLAM optimises its submaps this
/// way between full optimisations. Throws as optimizePoseGraph, and when `group_of` does not hold
/// one group per node.
PoseGraphSummary optimizePoseGraphRigid(std::vector<SE2>& poses, const std::vector<PoseGraphEdge>& edges,
                                        std::span<const std::size_t> group_of, std::size_t fixed,
                                        const PoseGraphOptions& options = {});

/// The whitened residual of one edge at the given poses (the quantity the solver minimises, before
/// the robust loss); for diagnostics and tests.
Eigen::Vector3d edgeResidual(const SE2& T_world_from, const SE2& T_world_to, const PoseGraphEdge& edge);

}  // namespace lidar2d::slam
