// Degeneracy-aware matching on the simulated corridor: scan-to-scan matching in the featureless
// middle of the corridor slides along it; keeping the odometry along the degenerate direction
// (degeneracy::constrainMatch) keeps the drift along the corridor at the odometry's level while the
// match still corrects the motion across the corridor and the rotation.

#include <gtest/gtest.h>

#include <cmath>
#include <iostream>
#include <numbers>

#include "lidar2d/degeneracy/degeneracy.hpp"
#include "lidar2d/degeneracy/ground_truth.hpp"
#include "lidar2d/registration/matcher.hpp"
#include "lidar2d/sim/path.hpp"
#include "lidar2d/sim/simulator.hpp"
#include "lidar2d/sim/worlds.hpp"

namespace lidar2d::degeneracy {
namespace {

struct Errors {
  double along_sum = 0.0;  // accumulated signed error along the corridor [m] (the drift)
  double along_sq = 0.0;   // sum of squared per-pair errors along the corridor [m^2]
  double across_sq = 0.0;  // ... across the corridor [m^2]
  double rot_sq = 0.0;     // ... of the rotation [rad^2]
  std::size_t n = 0;
  void add(const SE2& est, const SE2& truth, const Eigen::Vector2d& along) {
    const Eigen::Vector2d e = est.translation() - truth.translation();
    const Eigen::Vector2d across(-along.y(), along.x());
    along_sum += e.dot(along);
    along_sq += e.dot(along) * e.dot(along);
    across_sq += e.dot(across) * e.dot(across);
    rot_sq += angleDiff(est.theta(), truth.theta()) * angleDiff(est.theta(), truth.theta());
    ++n;
  }
  double alongRms() const { return std::sqrt(along_sq / n); }
  double acrossRms() const { return std::sqrt(across_sq / n); }
  double rotRms() const { return std::sqrt(rot_sq / n); }
};

class CorridorDrift : public ::testing::TestWithParam<registration::Method> {};

TEST_P(CorridorDrift, ConstrainedMatchDriftsNoMoreThanOdometry) {
  const sim::Scenario sc = sim::builtinScenario("corridor");
  sim::SimulatorOptions so;
  so.seed = 4;
  so.laser.beams = 241;
  // The route's stretch along the corridor's middle (x 5..17 m, driving east); only it is simulated.
  std::vector<sim::TimedPose> path;
  for (const auto& p : sim::samplePath(sc.waypoints, sim::PathOptions{}))
    if (p.T_world_robot.x() >= 5.0 && p.T_world_robot.x() <= 17.0 && std::abs(p.T_world_robot.y()) < 0.5)
      path.push_back(p);
  const std::vector<Frame> frames = sim::simulate(sc.world, path, so);
  std::vector<bool> degenerate_label;
  for (const Frame& f : frames)
    degenerate_label.push_back(labelFromWorld(sc.world, *f.T_world_robot, so.laser).degenerate);
  registration::MatcherOptions mo;
  mo.method = GetParam();
  Errors odom, match, constrained;
  std::size_t flagged = 0;
  for (std::size_t k = 1; k < frames.size(); ++k) {
    const Frame& a = frames[k - 1];
    const Frame& b = frames[k];
    // Only the featureless stretch: both scans labelled degenerate from the world geometry.
    if (!degenerate_label[k - 1] || !degenerate_label[k]) continue;
    const SE2 truth = a.T_world_robot->inverse() * *b.T_world_robot;
    const SE2 prior = a.T_odom_robot->inverse() * *b.T_odom_robot;
    const Points2 pa = a.scan.toPoints(a.T_robot_laser), pb = b.scan.toPoints(b.T_robot_laser);
    const registration::Result r = registration::matchScans(pa, pb, prior, mo);
    const Result deg = analyze(pb);
    flagged += deg.degenerate();
    // The corridor's axis (world x) in the previous robot frame.
    const double th = a.T_world_robot->theta();
    const Eigen::Vector2d along(std::cos(-th), std::sin(-th));
    odom.add(prior, truth, along);
    match.add(r.T_target_source, truth, along);
    constrained.add(constrainMatch(r.T_target_source, prior, deg), truth, along);
  }
  ASSERT_GT(odom.n, 120u);  // 12 m of corridor at 0.08 m per scan
  EXPECT_GE(flagged, odom.n * 95 / 100);
  std::cout << "pairs " << odom.n << ", flagged " << flagged << "\n"
            << "along-corridor drift [m]: odometry " << odom.along_sum << ", match " << match.along_sum
            << ", constrained " << constrained.along_sum << "\n"
            << "per-pair RMS along [mm]: odometry " << 1e3 * odom.alongRms() << ", match " << 1e3 * match.alongRms()
            << ", constrained " << 1e3 * constrained.alongRms() << "\n"
            << "per-pair RMS across [mm]: odometry " << 1e3 * odom.acrossRms() << ", match " << 1e3 * match.acrossRms()
            << ", constrained " << 1e3 * constrained.acrossRms() << "\n"
            << "per-pair RMS rotation [mdeg]: odometry " << odom.rotRms() * 180e3 / std::numbers::pi << ", match "
            << match.rotRms() * 180e3 / std::numbers::pi << ", constrained "
            << constrained.rotRms() * 180e3 / std::numbers::pi << "\n";
  // The problem: the plain matcher slides along the corridor, several times the odometry's error.
  EXPECT_GT(match.alongRms(), 2 * odom.alongRms());
  // Along the corridor: the odometry's level (the constrained estimate takes the odometry there,
  // up to the rotation of the scan's axis estimate).
  EXPECT_LE(std::abs(constrained.along_sum), std::abs(odom.along_sum) * 1.1 + 0.02);
  EXPECT_LE(constrained.alongRms(), odom.alongRms() * 1.1 + 1e-4);
  // Across the corridor and in rotation: the match's accuracy, better than the odometry's.
  EXPECT_LE(constrained.acrossRms(), odom.acrossRms());
  EXPECT_LE(constrained.rotRms(), odom.rotRms());
}

INSTANTIATE_TEST_SUITE_P(Methods, CorridorDrift,
                         ::testing::Values(registration::Method::kP2P, registration::Method::kP2L),
                         [](const auto& info) { return std::string(registration::toString(info.param)); });

}  // namespace
}  // namespace lidar2d::degeneracy
