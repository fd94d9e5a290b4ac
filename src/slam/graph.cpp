#include "src/slam/internal/graph.hpp"

#include <algorithm>
#include <cmath>
#include <utility>
#include <vector>

namespace lidar2d::slam::internal {

void addSequentialConstraints(SlamState& s, std::size_t n, bool restart, bool degenerate,
                              const Eigen::Vector2d& dir_local) {
  const Node& prev = s.nodes[n - 1];
  Constraint c;
  c.kind = Constraint::Kind::kSequential;
  c.from = n - 1;
  c.to = n;
  c.T_from_to = prev.T_local_robot.inverse() * s.nodes[n].T_local_robot;
  Eigen::Matrix3d sqrt_info = diagSqrtInfo(s.opt.sequential_sigma_m, s.opt.sequential_sigma_rad);
  if (restart) {
    // Tracking was lost: the link is only the prediction.
    sqrt_info = diagSqrtInfo(s.opt.odometry_sigma_m * 20.0, s.opt.odometry_sigma_rad * 20.0);
  } else if (degenerate) {
    // Along the degenerate direction the relative pose is as good as the prediction.
    const Eigen::Vector2d v = prev.T_local_robot.rotation().transpose() * dir_local;
    const Eigen::Vector2d p(-v.y(), v.x());
    sqrt_info.setZero();
    sqrt_info.block<1, 2>(0, 0) = v.transpose() / (s.opt.odometry_sigma_m * 2.0);
    sqrt_info.block<1, 2>(1, 0) = p.transpose() / s.opt.sequential_sigma_m;
    sqrt_info(2, 2) = 1.0 / s.opt.sequential_sigma_rad;
  }
  s.addEdge(std::move(c), sqrt_info, 0.0);
  if (s.node_odometry[n - 1] && s.node_odometry[n]) {
    Constraint o;
    o.kind = Constraint::Kind::kOdometry;
    o.from = n - 1;
    o.to = n;
    o.T_from_to = s.node_odometry[n - 1]->inverse() * *s.node_odometry[n];
    const double sm = s.opt.odometry_sigma_m + 0.1 * o.T_from_to.translation().norm();
    const double sr = s.opt.odometry_sigma_rad + 0.1 * std::abs(o.T_from_to.theta());
    s.addEdge(std::move(o), diagSqrtInfo(sm, sr), 0.0);
  }
}

void optimize(SlamState& s, int iterations) {
  if (s.nodes.size() < 2) return;
  std::vector<SE2> poses;
  poses.reserve(s.nodes.size());
  for (const Node& n : s.nodes) poses.push_back(n.T_world_robot);
  PoseGraphOptions go = s.opt.graph;
  go.max_iterations = iterations;
  const PoseGraphSummary summary = optimizePoseGraph(poses, s.edges, 0, go);
  ++s.stats.optimizations;
  s.stats.optimization_seconds += summary.seconds;
  if (summary.usable)
    for (std::size_t i = 0; i < s.nodes.size(); ++i) s.nodes[i].T_world_robot = poses[i];
  s.T_world_local = s.nodes.back().T_world_robot * s.nodes.back().T_local_robot.inverse();
  s.nodes_since_optimization = 0;
  s.loops_since_optimization = 0;
  s.searched_loop_pending = false;
}

void optimizeIfDue(SlamState& s) {
  // A closure found by search may move the global estimate a lot (later searches are centred on
  // it): optimise soon. Closures that follow a link refine what is known: optimise now and then.
  const bool prompt =
      s.searched_loop_pending && static_cast<int>(s.nodes_since_optimization) >= s.opt.optimize_every_nodes;
  const bool periodic =
      s.loops_since_optimization > 0 && static_cast<int>(s.nodes_since_optimization) >= 10 * s.opt.optimize_every_nodes;
  if (s.descriptor_loop_accepted) {
    // A descriptor closure corrects a large drift: the estimate must follow it at once, or the
    // proximity search keeps looking in the wrong place.
    optimize(s, std::max(s.opt.intermediate_iterations, s.opt.graph.max_iterations));
    s.descriptor_loop_accepted = false;
  } else if (periodic || prompt) {
    optimize(s, s.opt.intermediate_iterations);
  }
}

}  // namespace lidar2d::slam::internal
