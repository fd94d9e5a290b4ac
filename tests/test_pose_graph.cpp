// SE(2) pose graph: exact recovery from perturbed starts, robustness to a wrong loop closure, rigid
// groups of nodes, and bad input.

#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "lidar2d/core/error.hpp"
#include "lidar2d/slam/pose_graph.hpp"
#include "support/test_support.hpp"

namespace lidar2d::slam {
namespace {

constexpr double kPi = 3.14159265358979323846;

/// A square loop of `n` poses per side (true poses), with odometry edges and one loop closure.
std::vector<SE2> squareLoop(int per_side) {
  std::vector<SE2> truth;
  SE2 T;
  for (int side = 0; side < 4; ++side)
    for (int k = 0; k < per_side; ++k) {
      truth.push_back(T);
      T = T * SE2(1.0, 0.0, k + 1 == per_side ? kPi / 2 : 0.0);
    }
  return truth;
}

PoseGraphEdge edgeBetween(const std::vector<SE2>& truth, std::size_t a, std::size_t b, double sm, double sr,
                          double huber = 0.0) {
  PoseGraphEdge e;
  e.from = a;
  e.to = b;
  e.T_from_to = truth[a].inverse() * truth[b];
  e.sqrt_information = Eigen::Vector3d(1 / sm, 1 / sm, 1 / sr).asDiagonal();
  e.huber_scale = huber;
  e.scalable = huber > 0.0;  // a loop closure that may be wrong
  return e;
}

/// Odometry edges along `truth` that over-estimate each rotation by 1 degree (appended to `edges`);
/// returns the poses they chain to from truth[0].
std::vector<SE2> driftingChain(const std::vector<SE2>& truth, std::vector<PoseGraphEdge>& edges) {
  std::vector<SE2> poses{truth[0]};
  for (std::size_t i = 0; i + 1 < truth.size(); ++i) {
    PoseGraphEdge e = edgeBetween(truth, i, i + 1, 0.05, 0.02);
    e.T_from_to = e.T_from_to * SE2(0, 0, kPi / 180);
    edges.push_back(e);
    poses.push_back(poses.back() * e.T_from_to);
  }
  return poses;
}

TEST(PoseGraph, ResidualIsZeroAtTheMeasurement) {
  const std::vector<SE2> truth{SE2(1, 2, 0.3), SE2(2.5, 1, -2.9)};
  const auto e = edgeBetween(truth, 0, 1, 0.1, 0.01);
  EXPECT_LT(edgeResidual(truth[0], truth[1], e).norm(), 1e-9);
  // Angles wrap: the same pose with theta + 2 pi gives the same residual.
  EXPECT_LT(edgeResidual(truth[0], SE2(truth[1].translation(), truth[1].theta() + 2 * kPi), e).norm(), 1e-9);
  EXPECT_GT(edgeResidual(truth[0], SE2(2.6, 1, -2.9), e).norm(), 0.5);
}

TEST(PoseGraph, RecoversTheTruthFromAPerturbedStart) {
  const auto truth = squareLoop(5);
  std::vector<PoseGraphEdge> edges;
  for (std::size_t i = 0; i + 1 < truth.size(); ++i) edges.push_back(edgeBetween(truth, i, i + 1, 0.05, 0.01));
  edges.push_back(edgeBetween(truth, truth.size() - 1, 0, 0.05, 0.01));  // closes the loop
  edges.push_back(edgeBetween(truth, 2, 12, 0.05, 0.01));
  std::mt19937 rng(3);
  std::normal_distribution<double> n(0.0, 0.3);
  std::vector<SE2> poses = truth;
  for (std::size_t i = 1; i < poses.size(); ++i)
    poses[i] = poses[i] * SE2(n(rng), n(rng), 0.3 * n(rng));
  const PoseGraphSummary s = optimizePoseGraph(poses, edges, 0);
  ASSERT_TRUE(s.usable) << s.message;
  EXPECT_LT(s.final_cost, 1e-12);
  for (std::size_t i = 0; i < poses.size(); ++i) EXPECT_TRUE(test::IsNearPose(truth[i], poses[i], 1e-5, 1e-3)) << "node " << i;
}

TEST(PoseGraph, DistributesTheLoopErrorOfDriftingOdometry) {
  const auto truth = squareLoop(6);
  std::vector<PoseGraphEdge> edges;
  std::vector<SE2> poses = driftingChain(truth, edges);  // the open chain ends far off
  const double open_end_error = (poses.back().translation() - truth.back().translation()).norm();
  edges.push_back(edgeBetween(truth, truth.size() - 1, 0, 0.01, 0.002));  // an accurate loop closure
  const PoseGraphSummary s = optimizePoseGraph(poses, edges, 0);
  ASSERT_TRUE(s.usable);
  EXPECT_LT(s.final_cost, s.initial_cost);
  double worst = 0;
  for (std::size_t i = 0; i < poses.size(); ++i)
    worst = std::max(worst, (poses[i].translation() - truth[i].translation()).norm());
  EXPECT_GT(open_end_error, 0.5);
  EXPECT_LT(worst, open_end_error / 3);
}

TEST(PoseGraph, HuberLossLimitsAWrongLoopClosure) {
  const auto truth = squareLoop(5);
  std::vector<PoseGraphEdge> edges;
  for (std::size_t i = 0; i + 1 < truth.size(); ++i) edges.push_back(edgeBetween(truth, i, i + 1, 0.01, 0.002));
  PoseGraphEdge wrong = edgeBetween(truth, 3, 13, 0.05, 0.01, 1.0);
  wrong.T_from_to = wrong.T_from_to * SE2(2.0, -1.0, 0.5);  // metres off
  edges.push_back(wrong);
  auto robust = truth;
  optimizePoseGraph(robust, edges, 0);
  auto plain = truth;
  edges.back().huber_scale = 0.0;
  optimizePoseGraph(plain, edges, 0);
  double worst_robust = 0, worst_plain = 0;
  for (std::size_t i = 0; i < truth.size(); ++i) {
    worst_robust = std::max(worst_robust, (robust[i].translation() - truth[i].translation()).norm());
    worst_plain = std::max(worst_plain, (plain[i].translation() - truth[i].translation()).norm());
  }
  EXPECT_LT(worst_robust, worst_plain / 2);
}

TEST(PoseGraph, DynamicCovarianceScalingFadesAWrongClosureAmongRightOnes) {
  // Two laps of a square with drifting odometry (1 degree too much per step): right closures
  // between the laps, far off before the first solve, and one wrong closure two metres off.
  const auto lap = squareLoop(6);
  std::vector<SE2> truth = lap;
  for (const SE2& T : lap) truth.push_back(T);
  std::vector<PoseGraphEdge> edges;
  const std::vector<SE2> poses = driftingChain(truth, edges);
  const std::size_t n = lap.size();
  for (std::size_t i : {2u, 8u, 14u, 20u}) edges.push_back(edgeBetween(truth, i, n + i, 0.05, 0.01, 1.0));
  edges.push_back(edgeBetween(truth, n - 1, 0, 0.05, 0.01, 1.0));
  edges.push_back(edgeBetween(truth, 2 * n - 1, 0, 0.05, 0.01, 1.0));
  PoseGraphEdge wrong = edgeBetween(truth, 5, n + 11, 0.05, 0.01, 1.0);
  wrong.T_from_to = wrong.T_from_to * SE2(2.0, -1.0, 0.3);
  edges.push_back(wrong);
  const std::size_t wrong_index = edges.size() - 1;

  auto worstError = [&](const std::vector<SE2>& p) {
    double worst = 0;
    for (std::size_t i = 0; i < p.size(); ++i)
      worst = std::max(worst, (p[i].translation() - truth[i].translation()).norm());
    return worst;
  };
  auto huber_only = poses;
  const PoseGraphSummary h = optimizePoseGraph(huber_only, edges, 0);
  ASSERT_TRUE(h.usable);
  for (double scale : h.edge_scale) EXPECT_EQ(scale, 1.0);  // off by default

  PoseGraphOptions o;
  o.dcs_phi = 9.0;
  auto dcs = poses;
  const PoseGraphSummary d = optimizePoseGraph(dcs, edges, 0, o);
  ASSERT_TRUE(d.usable);
  ASSERT_EQ(d.edge_scale.size(), edges.size());
  EXPECT_LT(d.edge_scale[wrong_index], 0.1);
  for (std::size_t k = wrong_index - 6; k < wrong_index; ++k) EXPECT_GT(d.edge_scale[k], 0.9) << "right closure " << k;
  for (std::size_t k = 0; k + 7 < edges.size(); ++k) EXPECT_EQ(d.edge_scale[k], 1.0);  // not robust: never scaled
  // Huber alone keeps the wrong closure's pull linear: the laps bend by decimetres; faded, it is a centimetre.
  EXPECT_GT(worstError(huber_only), 0.1);
  EXPECT_LT(worstError(dcs), worstError(huber_only) / 5);
}

TEST(PoseGraph, UntouchedNodesKeepTheirPose) {
  std::vector<SE2> poses{SE2(), SE2(1, 0, 0), SE2(5, 5, 1)};
  const std::vector<PoseGraphEdge> edges{edgeBetween({SE2(), SE2(2, 0, 0)}, 0, 1, 0.1, 0.1)};
  optimizePoseGraph(poses, edges, 0);
  EXPECT_TRUE(test::IsNearPose(SE2(2, 0, 0), poses[1], 1e-5, 1e-3));
  EXPECT_TRUE(test::IsNearPose(SE2(5, 5, 1), poses[2], 1e-12, 1e-9));
}

TEST(PoseGraph, RigidGroupsMoveAsOneBody) {
  // Two sides of the square as two rigid groups whose inner chains are exact; the second group
  // starts rotated and shifted. Only the edges between the groups can move it, and they do so
  // without bending it.
  const auto truth = squareLoop(5);
  std::vector<PoseGraphEdge> edges;
  for (std::size_t i = 0; i + 1 < 10; ++i) edges.push_back(edgeBetween(truth, i, i + 1, 0.05, 0.01));
  edges.push_back(edgeBetween(truth, 2, 8, 0.05, 0.01));
  std::vector<SE2> poses(truth.begin(), truth.begin() + 10);
  const SE2 shove(0.4, -0.3, 0.2);
  for (std::size_t i = 5; i < 10; ++i) poses[i] = truth[5] * shove * (truth[5].inverse() * truth[i]);
  const std::vector<std::size_t> group{0, 0, 0, 0, 0, 1, 1, 1, 1, 1};
  const std::vector<SE2> before = poses;
  const PoseGraphSummary s = optimizePoseGraphRigid(poses, edges, group, 0);
  ASSERT_TRUE(s.usable) << s.message;
  EXPECT_LT(s.final_cost, 1e-12);
  for (std::size_t i = 0; i < 10; ++i) EXPECT_TRUE(test::IsNearPose(truth[i], poses[i], 1e-5, 1e-4)) << "node " << i;
  // Within a group the relative poses are those it started with, to rounding.
  for (std::size_t i = 6; i < 10; ++i)
    EXPECT_TRUE(test::IsNearPose(before[5].inverse() * before[i], poses[5].inverse() * poses[i], 1e-9, 1e-9));
  ASSERT_EQ(s.edge_scale.size(), edges.size());
}

TEST(PoseGraph, RigidGroupsKeepTheirShapeAgainstTheEdges) {
  // A drifting chain in one group cannot be straightened by the loop closure: the group is rigid,
  // so the closure only moves the other group; with a group per node the same edges spread the error.
  const auto truth = squareLoop(6);
  std::vector<PoseGraphEdge> edges;
  const std::vector<SE2> start = driftingChain(truth, edges);
  edges.push_back(edgeBetween(truth, truth.size() - 1, 0, 0.01, 0.002));
  std::vector<std::size_t> halves(truth.size()), singles(truth.size());
  for (std::size_t i = 0; i < truth.size(); ++i) {
    halves[i] = i < truth.size() / 2 ? 0 : 1;
    singles[i] = truth.size() - 1 - i;  // any numbering
  }
  std::vector<SE2> rigid = start, single = start, plain = start;
  ASSERT_TRUE(optimizePoseGraphRigid(rigid, edges, halves, 0).usable);
  ASSERT_TRUE(optimizePoseGraphRigid(single, edges, singles, 0).usable);
  ASSERT_TRUE(optimizePoseGraph(plain, edges, 0).usable);
  for (std::size_t i = 1; i < truth.size() / 2; ++i)  // the fixed node's group does not move
    EXPECT_TRUE(test::IsNearPose(start[i], rigid[i], 1e-9, 1e-9)) << "node " << i;
  const std::size_t h = truth.size() / 2;
  for (std::size_t i = h + 1; i < truth.size(); ++i)
    EXPECT_TRUE(test::IsNearPose(start[h].inverse() * start[i], rigid[h].inverse() * rigid[i], 1e-9, 1e-9));
  EXPECT_FALSE(test::IsNearPose(start[h], rigid[h], 1e-3, 1e-3));  // the second half moved
  for (std::size_t i = 0; i < truth.size(); ++i)
    EXPECT_TRUE(test::IsNearPose(plain[i], single[i], 1e-6, 1e-6)) << "node " << i;
}

TEST(PoseGraph, BadInputThrows) {
  std::vector<SE2> poses{SE2(), SE2(1, 0, 0)};
  PoseGraphEdge e;
  e.from = 0;
  e.to = 5;
  EXPECT_THROW(optimizePoseGraph(poses, {e}, 0), Error);
  e.to = 0;
  EXPECT_THROW(optimizePoseGraph(poses, {e}, 0), Error);  // self edge
  e.to = 1;
  e.T_from_to = SE2(std::nan(""), 0, 0);
  EXPECT_THROW(optimizePoseGraph(poses, {e}, 0), Error);
  e.T_from_to = SE2();
  EXPECT_THROW(optimizePoseGraph(poses, {e}, 2), Error);  // fixed out of range
  PoseGraphOptions o;
  o.max_iterations = 0;
  EXPECT_THROW(optimizePoseGraph(poses, {e}, 0, o), Error);
  o = PoseGraphOptions();
  o.dcs_phi = -1.0;
  EXPECT_THROW(optimizePoseGraph(poses, {e}, 0, o), Error);
  o.dcs_phi = 1.0;
  o.dcs_rounds = 0;
  EXPECT_THROW(optimizePoseGraph(poses, {e}, 0, o), Error);
  std::vector<SE2> empty;
  EXPECT_TRUE(optimizePoseGraph(empty, {}, 0).usable);
  const std::vector<std::size_t> one_group{0};
  EXPECT_THROW(optimizePoseGraphRigid(poses, {e}, one_group, 0), Error);  // a group for each node
  const std::vector<std::size_t> far_group{0, 7};
  EXPECT_THROW(optimizePoseGraphRigid(poses, {e}, far_group, 0), Error);  // numbered below the node count
}

}  // namespace
}  // namespace lidar2d::slam
