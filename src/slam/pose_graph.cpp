#include "lidar2d/slam/pose_graph.hpp"

#include <ceres/ceres.h>
#include <fmt/format.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <numbers>
#include <span>

#include "lidar2d/core/error.hpp"

namespace lidar2d::slam {
namespace {

/// Wraps an angle to [-pi, pi) in a form automatic differentiation can carry (the derivative of
/// the wrap is 1 almost everywhere).
template <typename T>
T wrap(const T& a) {
  using std::floor;
  const T two_pi = T(2.0 * std::numbers::pi);
  return a - two_pi * floor((a + T(std::numbers::pi)) / two_pi);
}

/// The residual of one edge (Ceres' slam_2d example formulation): the measured translation compared
/// in the `from` frame, and the wrapped angle difference, whitened by the square-root information.
struct EdgeCost {
  EdgeCost(const SE2& meas, const Eigen::Matrix3d& sqrt_info) : meas_(meas), sqrt_info_(sqrt_info) {}

  template <typename T>
  bool operator()(const T* a, const T* b, T* residual) const {
    using std::cos;
    using std::sin;
    const T c = cos(a[2]), s = sin(a[2]);
    const T dx = b[0] - a[0], dy = b[1] - a[1];
    Eigen::Matrix<T, 3, 1> r;
    r(0) = c * dx + s * dy - T(meas_.x());
    r(1) = -s * dx + c * dy - T(meas_.y());
    r(2) = wrap(b[2] - a[2] - T(meas_.theta()));
    const Eigen::Matrix<T, 3, 1> w = sqrt_info_.cast<T>() * r;
    residual[0] = w(0);
    residual[1] = w(1);
    residual[2] = w(2);
    return true;
  }

  SE2 meas_;
  Eigen::Matrix3d sqrt_info_;
};

/// The edge's Huber loss, or nullptr (plain least squares); the caller owns it.
ceres::LossFunction* huberOf(const PoseGraphEdge& e) {
  return e.huber_scale > 0.0 ? new ceres::HuberLoss(e.huber_scale) : nullptr;
}

}  // namespace

Eigen::Vector3d edgeResidual(const SE2& T_world_from, const SE2& T_world_to, const PoseGraphEdge& edge) {
  const std::array<double, 3> a{T_world_from.x(), T_world_from.y(), T_world_from.theta()};
  const std::array<double, 3> b{T_world_to.x(), T_world_to.y(), T_world_to.theta()};
  Eigen::Vector3d r;
  EdgeCost(edge.T_from_to, edge.sqrt_information)(a.data(), b.data(), r.data());
  return r;
}

namespace {

/// EdgeCost between two nodes that move with their groups: each node's pose is its group's
/// parameter composed with the node's fixed offset in the group.
struct RigidEdgeCost {
  RigidEdgeCost(const SE2& meas, const Eigen::Matrix3d& sqrt_info, const SE2& offset_from, const SE2& offset_to)
      : edge_(meas, sqrt_info), from_(offset_from), to_(offset_to) {}

  template <typename T>
  static void compose(const T* g, const SE2& offset, T* out) {
    using std::cos;
    using std::sin;
    const T c = cos(g[2]), s = sin(g[2]);
    out[0] = g[0] + c * T(offset.x()) - s * T(offset.y());
    out[1] = g[1] + s * T(offset.x()) + c * T(offset.y());
    out[2] = g[2] + T(offset.theta());
  }

  template <typename T>
  bool operator()(const T* ga, const T* gb, T* residual) const {
    T a[3], b[3];
    compose(ga, from_, a);
    compose(gb, to_, b);
    return edge_(a, b, residual);
  }

  EdgeCost edge_;
  SE2 from_, to_;
};

/// The solve behind optimizePoseGraph (group_of empty: every node its own parameter) and
/// optimizePoseGraphRigid.
PoseGraphSummary solve(std::vector<SE2>& poses, const std::vector<PoseGraphEdge>& edges,
                       std::span<const std::size_t> group_of, std::size_t fixed, const PoseGraphOptions& options) {
  if (options.max_iterations < 1) throw invalidArgument("must be >= 1", {"PoseGraphOptions", 0, "max_iterations"});
  if (options.threads < 1) throw invalidArgument("must be >= 1", {"PoseGraphOptions", 0, "threads"});
  if (!(options.function_tolerance > 0.0))
    throw invalidArgument("must be > 0", {"PoseGraphOptions", 0, "function_tolerance"});
  if (!(std::isfinite(options.dcs_phi) && options.dcs_phi >= 0.0))
    throw invalidArgument("must be finite and >= 0", {"PoseGraphOptions", 0, "dcs_phi"});
  if (options.dcs_rounds < 1) throw invalidArgument("must be >= 1", {"PoseGraphOptions", 0, "dcs_rounds"});
  const bool grouped = !group_of.empty();  // optimizePoseGraphRigid checked: one group per node
  if (poses.empty())
    return {.usable = true, .message = "empty graph", .edge_scale = std::vector<double>(edges.size(), 1.0)};
  if (fixed >= poses.size())
    throw invalidArgument(fmt::format("fixed node {} of {} nodes", fixed, poses.size()), {"pose graph", 0, "fixed"});
  for (std::size_t i = 0; i < poses.size(); ++i)
    if (!poses[i].isFinite()) throw invalidArgument(fmt::format("node {} is not finite", i), {"pose graph", 0, "poses"});

  // One parameter per group, at its first node's pose; each node's offset from it is held.
  std::vector<std::size_t> param_of(poses.size());
  std::vector<std::size_t> anchor;  // per parameter, its first node
  if (grouped) {
    std::vector<std::size_t> param_of_group;
    for (std::size_t i = 0; i < poses.size(); ++i) {
      const std::size_t g = group_of[i];
      if (g >= poses.size())
        throw invalidArgument(
            fmt::format("node {} is in group {}: groups are numbered below the node count {}", i, g, poses.size()),
            {"pose graph", 0, "groups"});
      if (g >= param_of_group.size()) param_of_group.resize(g + 1, poses.size());
      if (param_of_group[g] == poses.size()) {
        param_of_group[g] = anchor.size();
        anchor.push_back(i);
      }
      param_of[i] = param_of_group[g];
    }
  } else {
    anchor.resize(poses.size());
    for (std::size_t i = 0; i < poses.size(); ++i) param_of[i] = anchor[i] = i;
  }
  std::vector<SE2> offset;
  if (grouped) {
    offset.reserve(poses.size());
    for (std::size_t i = 0; i < poses.size(); ++i) offset.push_back(poses[anchor[param_of[i]]].inverse() * poses[i]);
  }
  std::vector<std::array<double, 3>> params(anchor.size());
  for (std::size_t p = 0; p < anchor.size(); ++p) {
    const SE2& T = poses[anchor[p]];
    params[p] = {T.x(), T.y(), T.theta()};
  }
  auto residualAt = [&](std::size_t k) {
    const PoseGraphEdge& e = edges[k];
    Eigen::Vector3d r;
    const double* a = params[param_of[e.from]].data();
    const double* b = params[param_of[e.to]].data();
    if (grouped)
      RigidEdgeCost(e.T_from_to, e.sqrt_information, offset[e.from], offset[e.to])(a, b, r.data());
    else
      EdgeCost(e.T_from_to, e.sqrt_information)(a, b, r.data());
    return r;
  };

  ceres::Problem::Options po;
  po.loss_function_ownership = ceres::TAKE_OWNERSHIP;
  ceres::Problem problem(po);
  // The scalable edges' losses, wrapped so that the scaling rounds can replace them.
  std::vector<ceres::LossFunctionWrapper*> scalable(edges.size(), nullptr);
  for (std::size_t k = 0; k < edges.size(); ++k) {
    const PoseGraphEdge& e = edges[k];
    if (e.from >= poses.size() || e.to >= poses.size() || e.from == e.to)
      throw invalidArgument(fmt::format("edge {} joins nodes {} and {} of {}", k, e.from, e.to, poses.size()),
                            {"pose graph", 0, "edges"});
    if (!e.T_from_to.isFinite() || !e.sqrt_information.allFinite() || !std::isfinite(e.huber_scale) ||
        e.huber_scale < 0.0)
      throw invalidArgument(fmt::format("edge {} is not finite", k), {"pose graph", 0, "edges"});
    const std::size_t a = param_of[e.from], b = param_of[e.to];
    if (a == b) continue;  // within one rigid group: constant
    ceres::CostFunction* cost =
        grouped ? static_cast<ceres::CostFunction*>(new ceres::AutoDiffCostFunction<RigidEdgeCost, 3, 3, 3>(
                      new RigidEdgeCost(e.T_from_to, e.sqrt_information, offset[e.from], offset[e.to])))
                : new ceres::AutoDiffCostFunction<EdgeCost, 3, 3, 3>(new EdgeCost(e.T_from_to, e.sqrt_information));
    ceres::LossFunction* loss = huberOf(e);
    if (e.scalable) loss = scalable[k] = new ceres::LossFunctionWrapper(loss, ceres::TAKE_OWNERSHIP);
    problem.AddResidualBlock(cost, loss, params[a].data(), params[b].data());
  }
  double* fixed_param = params[param_of[fixed]].data();
  if (problem.HasParameterBlock(fixed_param)) problem.SetParameterBlockConstant(fixed_param);

  ceres::Solver::Options so;
  so.linear_solver_type = ceres::SPARSE_NORMAL_CHOLESKY;
  so.max_num_iterations = options.max_iterations;
  so.num_threads = options.threads;
  so.function_tolerance = options.function_tolerance;
  so.logging_type = ceres::SILENT;
  so.minimizer_progress_to_stdout = false;
  ceres::Solver::Summary summary;
  const auto t0 = std::chrono::steady_clock::now();
  ceres::Solve(so, &problem, &summary);
  const double initial_cost = summary.initial_cost;
  int iterations = static_cast<int>(summary.iterations.size());

  std::vector<double> scale(edges.size(), 1.0);
  const bool any_scalable = std::any_of(scalable.begin(), scalable.end(), [](auto* w) { return w != nullptr; });
  for (int round = 0; options.dcs_phi > 0.0 && any_scalable && summary.IsSolutionUsable() && round < options.dcs_rounds;
       ++round) {
    double change = 0.0;
    for (std::size_t k = 0; k < edges.size(); ++k) {
      if (scalable[k] == nullptr) continue;
      const Eigen::Vector3d r = residualAt(k);
      const double s = std::min(1.0, 2.0 * options.dcs_phi / (options.dcs_phi + r.squaredNorm()));
      change = std::max(change, std::abs(s - scale[k]));
      scale[k] = s;
    }
    if (change < 0.01) break;
    // The residual scaled by s costs s^2 times as much: rho(s^2 chi2) ~ s^2 rho(chi2) within Huber's
    // quadratic zone, and the same weight beyond it.
    for (std::size_t k = 0; k < edges.size(); ++k)
      if (scalable[k] != nullptr)
        scalable[k]->Reset(new ceres::ScaledLoss(huberOf(edges[k]), scale[k] * scale[k], ceres::TAKE_OWNERSHIP),
                           ceres::TAKE_OWNERSHIP);
    ceres::Solve(so, &problem, &summary);
    iterations += static_cast<int>(summary.iterations.size());
  }
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();

  PoseGraphSummary out;
  out.initial_cost = initial_cost;
  out.final_cost = summary.final_cost;
  out.iterations = iterations;
  out.edge_scale = std::move(scale);
  out.usable = summary.IsSolutionUsable();
  out.seconds = seconds;
  out.message = summary.BriefReport();
  if (out.usable)
    for (std::size_t i = 0; i < poses.size(); ++i) {
      const auto& p = params[param_of[i]];
      if (!(std::isfinite(p[0]) && std::isfinite(p[1]) && std::isfinite(p[2]))) continue;
      if (grouped) {
        if (!problem.HasParameterBlock(p.data())) continue;  // no edge out of its group: unchanged
        poses[i] = SE2(p[0], p[1], p[2]) * offset[i];        // SE2 wraps the angle
      } else {
        poses[i] = SE2(p[0], p[1], wrapAngle(p[2]));
      }
    }
  return out;
}

}  // namespace

PoseGraphSummary optimizePoseGraph(std::vector<SE2>& poses, const std::vector<PoseGraphEdge>& edges, std::size_t fixed,
                                   const PoseGraphOptions& options) {
  return solve(poses, edges, {}, fixed, options);
}

PoseGraphSummary optimizePoseGraphRigid(std::vector<SE2>& poses, const std::vector<PoseGraphEdge>& edges,
                                        std::span<const std::size_t> group_of, std::size_t fixed,
                                        const PoseGraphOptions& options) {
  if (group_of.size() != poses.size())
    throw invalidArgument(fmt::format("{} groups given for {} nodes", group_of.size(), poses.size()),
                          {"pose graph", 0, "groups"});
  return solve(poses, edges, group_of, fixed, options);
}

}  // namespace lidar2d::slam
