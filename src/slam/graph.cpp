#include "src/slam/internal/graph.hpp"

#include <fmt/format.h>

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <cstddef>
#include <utility>
#include <vector>

#include "src/slam/internal/motion_prior.hpp"

namespace lidar2d::slam::internal {

void addSequentialConstraints(SlamState& s, std::size_t n, bool restart, Placement placement, bool degenerate,
                              const Eigen::Vector2d& dir_local) {
  const Node& prev = s.nodes[n - 1];
  Constraint c;
  c.kind = Constraint::Kind::kSequential;
  c.from = n - 1;
  c.to = n;
  c.T_from_to = prev.T_local_robot.inverse() * s.nodes[n].T_local_robot;
  // A match's relative pose; placed by odometry at a weak match near the prediction
  // (FrontEnd::refinesPlacement), that match is held as a loop closure is, looser than a match that
  // explains the scan. Along a degenerate direction the relative pose is as good as the prediction.
  const bool refined = placement == Placement::kRefined;
  const double sigma_m = refined ? s.opt.loop_sigma_m : s.opt.sequential_sigma_m;
  const double sigma_rad = refined ? s.opt.loop_sigma_rad : s.opt.sequential_sigma_rad;
  Eigen::Matrix3d sqrt_info = degenerate ? directionalSqrtInfo(prev.T_local_robot.rotation().transpose() * dir_local,
                                                               s.opt.odometry_sigma_m * 2.0, sigma_m, sigma_rad)
                                         : diagSqrtInfo(sigma_m, sigma_rad);
  if (restart || placement == Placement::kOdometry) {
    // Tracking was lost, or the scan was placed by odometry alone: the link is only the prediction
    // (the odometry constraint below holds the information).
    sqrt_info = diagSqrtInfo(s.opt.odometry_sigma_m * 20.0, s.opt.odometry_sigma_rad * 20.0);
  }
  s.addEdge(std::move(c), sqrt_info, 0.0);
  if (s.node_odometry[n - 1] && s.node_odometry[n]) {
    Constraint o;
    o.kind = Constraint::Kind::kOdometry;
    o.from = n - 1;
    o.to = n;
    o.T_from_to = s.node_odometry[n - 1]->inverse() * *s.node_odometry[n];
    const double sm = s.opt.odometry_sigma_m + s.opt.odometry_sigma_per_m * o.T_from_to.translation().norm();
    const double sr = s.opt.odometry_sigma_rad + s.opt.odometry_sigma_per_turn * std::abs(o.T_from_to.theta());
    // Across a lost track it is the only link to the map before it, until a relocalization either
    // agrees with it or shows the robot was carried (LoopClosure::acceptLoop drops it then).
    if (restart) s.restart_odometry = {s.edges.size(), s.constraints.size(), n};
    s.addEdge(std::move(o), diagSqrtInfo(sm, sr), 0.0);
  }
}

void propagatePlacedCovariance(SlamState& s, std::size_t n, bool restart, Placement placement, StepSigmas prior) {
  if (restart || n == 0 || s.last_loop_node != s.placed_cov_since) {
    s.placed_cov.setZero();
    s.placed_cov_since = s.last_loop_node;
  }
  if (n > 0 && !restart) {
    const SE2& a = s.nodes[n - 1].T_world_robot;
    const SE2& b = s.nodes[n].T_world_robot;
    // x_n = x_{n-1} (+) step: a heading error at n-1 moves node n by the lever between them.
    Eigen::Matrix3d J = Eigen::Matrix3d::Identity();
    J(0, 2) = -(b.translation().y() - a.translation().y());
    J(1, 2) = b.translation().x() - a.translation().x();
    s.placed_cov = J * s.placed_cov * J.transpose();
    if (placement != Placement::kMatched) {
      // The odometry's error as the motion prior knows it (its learnt noise), not the graph's
      // odometry links' (made for odometry drifting a degree per metre and more): with those, the
      // simulated office's keyframes from a 58-degree depth camera searched look-alike rooms 5-7 m
      // away and took them (BENCHMARK.md, SLAM, sparser keyframes).
      const bool refined = placement == Placement::kRefined;
      const double sm = refined ? s.opt.loop_sigma_m : prior.m;
      const double sr = refined ? s.opt.loop_sigma_rad : prior.rad;
      Eigen::Matrix3d G = Eigen::Matrix3d::Identity();
      G.topLeftCorner<2, 2>() = a.rotation();
      s.placed_cov += G * Eigen::Vector3d(sm * sm, sm * sm, sr * sr).asDiagonal() * G.transpose();
    }
  }
  if (s.node_placed_sigma_m.size() < n) s.node_placed_sigma_m.resize(n, 0.0);  // nodes of a resumed state
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> eig(s.placed_cov.topLeftCorner<2, 2>());
  s.node_placed_sigma_m.push_back(std::sqrt(std::max(0.0, eig.eigenvalues()(1))));
}

namespace {

void optimizeWith(SlamState& s, int iterations, bool rigid_submaps) {
  if (s.nodes.size() < 2) return;
  std::vector<SE2> poses;
  poses.reserve(s.nodes.size());
  for (const Node& n : s.nodes) poses.push_back(n.T_world_robot);
  // The cycles' sigmas (calibrateFromCycles) on a copy: the state keeps the links as built. Each
  // sigma is only narrowed (odometry) or widened (front end), never moved the other way.
  std::vector<PoseGraphEdge> calibrated;
  if (s.cycles_odometry_sigma_rad > 0.0) {
    calibrated = s.edges;
    const auto hold = [](auto rows, double sigma, double target, bool narrow) {
      if (narrow ? sigma > target : sigma < target) rows *= sigma / target;
    };
    std::size_t k = 0;
    for (const Constraint& c : s.constraints) {
      if (!c.accepted) continue;
      Eigen::Matrix3d& info = calibrated[k++].sqrt_information;
      if (c.kind == Constraint::Kind::kOdometry) {
        hold(info.row(2), 1.0 / info(2, 2), s.cycles_odometry_sigma_rad, true);
        hold(info.topRows<2>(), 1.0 / info(0, 0), s.cycles_odometry_sigma_m, true);
      } else if (c.kind == Constraint::Kind::kSequential) {
        hold(info.row(2), 1.0 / info(2, 2), s.cycles_sequential_sigma_rad, false);
      }
    }
  }
  const std::vector<PoseGraphEdge>& edges = calibrated.empty() ? s.edges : calibrated;
  PoseGraphOptions go = s.opt.graph;
  go.max_iterations = iterations;
  PoseGraphSummary summary;
  if (rigid_submaps) {
    // Submaps move as bodies, but for the newest ones (the one being built and the last
    // intermediate_free_submaps finished): the closures of the place the robot is in pull on them,
    // and the next searches are centred there. Their nodes move each on its own.
    std::vector<std::size_t> group_of, group_of_submap(s.submaps.size(), s.nodes.size());
    group_of.reserve(s.nodes.size());
    std::size_t groups = 0;
    const auto free_submaps = static_cast<std::size_t>(s.opt.intermediate_free_submaps);
    for (const Node& n : s.nodes) {
      if (!s.submaps[n.submap].finished || n.submap + free_submaps >= s.submaps.size()) {
        group_of.push_back(groups++);
        continue;
      }
      std::size_t& g = group_of_submap[n.submap];
      if (g == s.nodes.size()) g = groups++;
      group_of.push_back(g);
    }
    // Rigid submaps cannot bend to fit right closures as the full graph does: their residuals are
    // larger, and dynamic covariance scaling would fade right closures (BENCHMARK.md, SLAM). The
    // final optimisation scales them.
    go.dcs_phi = 0.0;
    summary = optimizePoseGraphRigid(poses, edges, group_of, 0, go);
  } else {
    summary = optimizePoseGraph(poses, edges, 0, go);
  }
  ++s.stats.optimizations;
  s.stats.optimization_seconds += summary.seconds;
  if (summary.usable) {
    for (std::size_t i = 0; i < s.nodes.size(); ++i) s.nodes[i].T_world_robot = poses[i];
    s.edge_scale = summary.edge_scale;
  }
  s.T_world_local = s.nodes.back().T_world_robot * s.nodes.back().T_local_robot.inverse();
  s.nodes_since_optimization = 0;
  s.loops_since_optimization = 0;
  s.searched_loop_pending = false;
}

}  // namespace

void optimize(SlamState& s, int iterations) { optimizeWith(s, iterations, false); }

CycleMeasure measureCycles(const SlamState& s) {
  const std::size_t N = s.nodes.size();
  // The accepted sequential and odometry edge into each node (the first of each kind).
  constexpr std::size_t kNone = static_cast<std::size_t>(-1);
  std::vector<std::size_t> seq(N, kNone), odo(N, kNone), loops;
  std::vector<char> restart(N, 0);
  for (std::size_t r : s.restarts)
    if (r < N) restart[r] = 1;
  std::size_t k = 0;
  for (const Constraint& c : s.constraints) {
    if (!c.accepted) continue;
    const bool link = c.to == c.from + 1 && c.to < N;
    if (link && c.kind == Constraint::Kind::kSequential && seq[c.to] == kNone) seq[c.to] = k;
    if (link && c.kind == Constraint::Kind::kOdometry && odo[c.to] == kNone) odo[c.to] = k;
    if (c.kind == Constraint::Kind::kLoop) loops.push_back(k);
    ++k;
  }
  // Per cycle, each chain's error against the closure (heading; x and y), squared, per node step.
  std::vector<double> q_odo, q_seq, t_odo, t_seq;
  for (const std::size_t l : loops) {
    const PoseGraphEdge& e = s.edges[l];
    const std::size_t a = std::min(e.from, e.to), b = std::max(e.from, e.to);
    if (b >= N || b - a < kCycleMinSteps) continue;
    SE2 T_odo, T_seq;
    bool whole = true;
    for (std::size_t n = a + 1; n <= b && whole; ++n) {
      whole = !restart[n] && seq[n] != kNone && odo[n] != kNone;
      if (whole) {
        T_odo = T_odo * s.edges[odo[n]].T_from_to;
        T_seq = T_seq * s.edges[seq[n]].T_from_to;
      }
    }
    if (!whole) continue;
    const SE2 T_loop = e.from == a ? e.T_from_to : e.T_from_to.inverse();
    const double steps = static_cast<double>(b - a);
    const double eo = angleDiff(T_loop.theta(), T_odo.theta()), es = angleDiff(T_loop.theta(), T_seq.theta());
    q_odo.push_back(eo * eo / steps);
    q_seq.push_back(es * es / steps);
    t_odo.push_back((T_odo.translation() - T_loop.translation()).squaredNorm() / steps);
    t_seq.push_back((T_seq.translation() - T_loop.translation()).squaredNorm() / steps);
  }
  CycleMeasure m;
  m.cycles = q_odo.size();
  if (q_odo.empty()) return m;
  // A chain's heading error over n steps of independent errors of sigma s is N(0, n s^2) (plus the
  // closure's own), so each cycle's e^2 / n is s^2 times a chi-square(1), whose median is 0.455; its
  // x and y error a chi-square(2), median 1.386. The median keeps the wrong closures a run may hold
  // from counting.
  m.odometry_rad = std::sqrt(upperMedian(std::move(q_odo)) / 0.455);
  m.front_end_rad = std::sqrt(upperMedian(std::move(q_seq)) / 0.455);
  m.odometry_m = std::sqrt(upperMedian(std::move(t_odo)) / 1.386);
  m.front_end_m = std::sqrt(upperMedian(std::move(t_seq)) / 1.386);
  return m;
}

void calibrateFromCycles(SlamState& s) {
  const CycleMeasure m = measureCycles(s);
  s.stats.loop_cycles = m.cycles;
  s.stats.cycle_odometry_deg = m.odometry_rad / kDeg;
  s.stats.cycle_front_end_deg = m.front_end_rad / kDeg;
  s.stats.cycle_odometry_m = m.odometry_m;
  s.stats.cycle_front_end_m = m.front_end_m;
  s.cycles_odometry_sigma_rad = s.cycles_sequential_sigma_rad = s.cycles_odometry_sigma_m = 0.0;
  s.stats.odometry_weighted_by_cycles = false;
  const double rotation = m.odometry_rad / m.front_end_rad, position = m.odometry_m / m.front_end_m;
  // The weight of the measure: 1 below kCycleOdometryRatio, fading to 0 at kCycleOdometryRatioNone;
  // times 1 from kCycleMinCount cycles, fading to 0 at kCycleFadeFrom.
  const double t_share = std::clamp(
      (kCycleOdometryRatioNone - std::sqrt(rotation * position)) / (kCycleOdometryRatioNone - kCycleOdometryRatio), 0.0,
      1.0);
  const double t_count = std::clamp((static_cast<double>(m.cycles) - static_cast<double>(kCycleFadeFrom)) /
                                        static_cast<double>(kCycleMinCount - kCycleFadeFrom),
                                    0.0, 1.0);
  const double t = t_share * t_count;
  if (!(rotation < 1.0) || !(position < 1.0) || !(t > 0.0)) return;
  const auto blend = [t](double measured, double own) { return std::pow(measured, t) * std::pow(own, 1.0 - t); };
  s.cycles_odometry_sigma_rad = blend(std::max(m.odometry_rad, kCycleMinSigmaRad), s.opt.odometry_sigma_rad);
  s.cycles_sequential_sigma_rad = blend(m.front_end_rad, s.opt.sequential_sigma_rad);
  s.cycles_odometry_sigma_m = blend(std::max(m.odometry_m, kCycleMinSigmaM), s.opt.odometry_sigma_m);
  s.stats.odometry_weighted_by_cycles = true;
  const Node& last = s.nodes.back();
  s.events.push_back(
      {s.scans[last.scan].frame_index, last.time,
       fmt::format(
           "odometry weighted by the loop closures' cycles: over {} cycles it erred {:.3f} degrees and {:.4f} m "
           "per node step, the scan matches {:.3f} degrees and {:.4f} m; the final graph holds the odometry "
           "links to {:.3f} degrees and {:.4f} m and the matches' rotation to at least {:.3f} degrees",
           m.cycles, m.odometry_rad / kDeg, m.odometry_m, m.front_end_rad / kDeg, m.front_end_m,
           s.cycles_odometry_sigma_rad / kDeg, s.cycles_odometry_sigma_m, s.cycles_sequential_sigma_rad / kDeg)});
}

void reportDownweighted(SlamState& s) {
  s.stats.loop_downweighted = 0;
  for (std::size_t k = 0; k < s.edge_scale.size() && k < s.edges.size(); ++k) {
    if (!s.edgeFaded(k)) continue;
    const PoseGraphEdge& e = s.edges[k];
    ++s.stats.loop_downweighted;
    s.events.push_back({s.scans[s.nodes[e.to].scan].frame_index, s.nodes[e.to].time,
                        fmt::format("loop closure from node {} to {} down-weighted to {:.2f} by the pose graph: the "
                                    "rest of the graph contradicts it",
                                    e.from, e.to, s.edge_scale[k])});
  }
}

void checkAtEnd(SlamState& s) {
  const std::size_t N = s.nodes.size();
  if (N < 2) {
    s.stats.fragments = N;
    return;
  }
  std::vector<char> restart(N, 0);
  for (std::size_t r : s.restarts) restart[r] = 1;

  // Fragments: the stretches between restarts, united through accepted loop closures.
  std::vector<std::size_t> fragment_of(N, 0), first_node{0};
  for (std::size_t n = 1; n < N; ++n) {
    fragment_of[n] = fragment_of[n - 1] + (restart[n] ? 1 : 0);
    if (restart[n]) first_node.push_back(n);
  }
  std::vector<std::size_t> parent(first_node.size());
  for (std::size_t i = 0; i < parent.size(); ++i) parent[i] = i;
  auto find = [&](std::size_t i) {
    while (parent[i] != i) i = parent[i] = parent[parent[i]];
    return i;
  };
  for (const Constraint& c : s.constraints)
    if (c.kind == Constraint::Kind::kLoop && c.accepted) parent[find(fragment_of[c.from])] = find(fragment_of[c.to]);

  // Never worse than odometry: across a lost track that no verified closure explains.
  bool added = false;
  for (std::size_t n = 1; n < N; ++n) {
    if (!restart[n] || !s.node_odometry[n - 1] || !s.node_odometry[n]) continue;
    // Closures tie both sides to one map: the scans placed them (a kidnapped robot's odometry is wrong).
    if (find(fragment_of[n - 1]) == find(fragment_of[n])) continue;
    const SE2 odo = s.node_odometry[n - 1]->inverse() * *s.node_odometry[n];
    const SE2 est = s.nodes[n - 1].T_world_robot.inverse() * s.nodes[n].T_world_robot;
    const MotionPrediction p = odometryPrediction(s.opt, odo, s.nodes[n].time - s.nodes[n - 1].time);
    const double sigmas = p.distance(est);
    if (!(sigmas > s.opt.prior_gate_sigmas)) continue;
    Constraint c;
    c.kind = Constraint::Kind::kOdometry;
    c.from = n - 1;
    c.to = n;
    c.T_from_to = odo;
    s.addEdge(std::move(c), diagSqrtInfo(p.sigma_m, p.sigma_rad), 0.0);
    s.events.push_back({s.scans[s.nodes[n].scan].frame_index, s.nodes[n].time,
                        fmt::format("odometry wins from node {} to {}: the estimate contradicted it by {:.1f} sigmas "
                                    "where tracking was lost (no scan evidence)",
                                    n - 1, n, sigmas)});
    ++s.stats.odometry_wins;
    added = true;
  }
  if (added) optimize(s, s.opt.graph.max_iterations);

  std::size_t fragments = 0;
  for (std::size_t i = 0; i < parent.size(); ++i) {
    if (find(i) != i) continue;
    ++fragments;
    if (find(i) == find(0)) continue;
    const std::size_t a = first_node[i];
    s.events.push_back({s.scans[s.nodes[a].scan].frame_index, s.nodes[a].time,
                        fmt::format("{}{} (after lost tracking or a new session) is tied to the first one only by "
                                    "the prediction: no loop closure verified its place",
                                    kFragmentEvent, a)});
  }
  s.stats.fragments = fragments;
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
    optimizeWith(s, s.opt.intermediate_iterations, s.opt.intermediate_rigid_submaps);
  }
}

}  // namespace lidar2d::slam::internal
