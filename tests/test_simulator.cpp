// The simulator: exact ranges against the brute-force ray caster, determinism, odometry and range
// noise statistics, paths, and the properties each built-in world promises.

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <random>

#include "lidar2d/core/error.hpp"
#include "lidar2d/sim/noise.hpp"
#include "lidar2d/sim/path.hpp"
#include "lidar2d/sim/simulator.hpp"
#include "lidar2d/sim/worlds.hpp"
#include "support/test_support.hpp"

namespace lidar2d::sim {
namespace {

using V = Eigen::Vector2d;
constexpr double kPi = std::numbers::pi;
using lidar2d::test::IsNearPose;

using lidar2d::test::Stats;

std::vector<TimedPose> route(const std::string& world, std::size_t scans = 0) {
  return samplePath(builtinScenario(world).waypoints, PathOptions{}, scans);
}

// ---- random numbers ----

TEST(Rng, UsesTheRawEngineOnly) {
  // mt19937_64's sequence is fixed by the C++ standard; uniform() is its top 53 bits.
  Rng rng(5489);
  std::mt19937_64 ref(5489);
  for (int i = 0; i < 10; ++i) EXPECT_EQ(rng.uniform(), static_cast<double>(ref() >> 11) * 0x1.0p-53);
  // The standard's check value: the 10000th output of a default-seeded mt19937_64.
  std::mt19937_64 e(5489);
  e.discard(9999);
  EXPECT_EQ(e(), 9981545732273789042ULL);
}

TEST(Rng, GaussianMomentsAndDeterminism) {
  Rng a(1), b(1), c(2);
  Stats s;
  bool differs = false;
  for (int i = 0; i < 200000; ++i) {
    const double x = a.gaussian();
    EXPECT_EQ(x, b.gaussian());
    if (x != c.gaussian()) differs = true;
    s.add(x);
  }
  EXPECT_TRUE(differs);
  EXPECT_NEAR(s.mean(), 0.0, 0.01);  // 5 standard errors (1/sqrt(200000) = 0.0022)
  EXPECT_NEAR(s.stddev(), 1.0, 0.01);
}

// ---- odometry noise ----

TEST(OdometryNoise, NoneReproducesTheMotion) {
  Rng rng(3);
  const SE2 step(0.08, 0.01, 0.05);
  EXPECT_TRUE(noisyOdometryStep(step, OdometryNoise::none(), rng).isApprox(step, 1e-15, 1e-15));
  EXPECT_TRUE(OdometryNoise::none().isZero());
  EXPECT_FALSE(OdometryNoise{}.isZero());
  OdometryNoise bad;
  bad.sigma_x_m = -1;
  EXPECT_THROW(bad.validate(), Error);
}

TEST(OdometryNoise, ConstantNoiseHasTheRequestedStatistics) {
  // perturb's model: T_odom = T_true * SE2(n_x, n_y, n_theta), n ~ N(0, diag(sx^2, sy^2, sth^2)).
  Rng rng(9);
  const auto model = OdometryNoise::constant(0.01, 0.005, 0.002);
  const SE2 step(0.1, 0.0, 0.02);
  Stats x, y, th;
  for (int i = 0; i < 50000; ++i) {
    const SE2 e = step.inverse() * noisyOdometryStep(step, model, rng);
    x.add(e.x());
    y.add(e.y());
    th.add(e.theta());
  }
  EXPECT_NEAR(x.mean(), 0.0, 0.0003);  // about 6 standard errors
  EXPECT_NEAR(y.mean(), 0.0, 0.00015);
  EXPECT_NEAR(th.mean(), 0.0, 0.00006);
  EXPECT_NEAR(x.stddev(), 0.01, 0.0002);
  EXPECT_NEAR(y.stddev(), 0.005, 0.0001);
  EXPECT_NEAR(th.stddev(), 0.002, 0.00004);
}

TEST(OdometryNoise, ProportionalNoiseAndBias) {
  OdometryNoise m = OdometryNoise::none();
  m.trans_sigma_per_m = 0.05;
  m.rot_sigma_per_rad = 0.1;
  m.scale_bias = 0.02;
  m.heading_bias_per_m = 0.01;
  const SE2 step(0.2, 0.0, 0.1);  // d = 0.2 m: sigma_x = 0.01 m, sigma_theta = 0.01 rad
  Rng rng(5);
  Stats x, th;
  for (int i = 0; i < 50000; ++i) {
    const SE2 o = noisyOdometryStep(step, m, rng);
    x.add(o.x());
    th.add(o.theta());
  }
  // Means carry the bias: 0.2 * 1.02 and 0.1 + 0.01 * 0.2 (the heading noise adds no mean; its
  // effect on x is second order).
  EXPECT_NEAR(x.mean(), 0.204, 0.0003);
  EXPECT_NEAR(th.mean(), 0.102, 0.0003);
  EXPECT_NEAR(x.stddev(), 0.01, 0.0003);
  EXPECT_NEAR(th.stddev(), 0.01, 0.0003);
}

// ---- paths ----

TEST(Path, ConstantSpeedSmoothHeadingAndEnds) {
  const std::vector<V> w{V(0, 0), V(5, 0), V(5, 4), V(0, 4), V(0, 0.5)};
  PathOptions o;
  const auto poses = samplePath(w, o);
  ASSERT_GT(poses.size(), 100u);
  EXPECT_TRUE(IsNearPose(SE2(0, 0, 0), poses.front().T_world_robot, 1e-12, 1e-9));
  EXPECT_NEAR((poses.back().T_world_robot.translation() - w.back()).norm(), 0.0, o.speed_mps / o.rate_hz + 1e-9);
  const double dt = 1.0 / o.rate_hz;
  for (std::size_t i = 1; i < poses.size(); ++i) {
    EXPECT_NEAR(poses[i].time_s - poses[i - 1].time_s, dt, 1e-9);
    const double step = (poses[i].T_world_robot.translation() - poses[i - 1].T_world_robot.translation()).norm();
    EXPECT_LE(step, o.speed_mps * dt + 1e-9);
    EXPECT_GT(step, 0.5 * o.speed_mps * dt);  // no turns on the spot here (all corners 90 deg)
    EXPECT_LE(std::abs(angleDiff(poses[i].T_world_robot.theta(), poses[i - 1].T_world_robot.theta())),
              o.speed_mps / 0.3 * dt);  // curvature bounded by the smallest fillet radius
  }
}

TEST(Path, ExactScanCountDrivesBackAndForth) {
  const std::vector<V> w{V(0, 0), V(2, 0)};
  const auto poses = samplePath(w, PathOptions{}, 200);  // 20 s at 0.8 m/s: four lengths of 2 m plus turns
  ASSERT_EQ(poses.size(), 200u);
  double max_x = 0, min_x_after_end = 10;
  for (const auto& p : poses) {
    max_x = std::max(max_x, p.T_world_robot.x());
    if (p.time_s > 5) min_x_after_end = std::min(min_x_after_end, p.T_world_robot.x());
    EXPECT_NEAR(p.T_world_robot.y(), 0.0, 1e-12);
  }
  EXPECT_NEAR(max_x, 2.0, 1e-9);
  EXPECT_LT(min_x_after_end, 0.5);  // came back
  EXPECT_THROW(samplePath({V(0, 0), V(0, 0)}, PathOptions{}), Error);
  PathOptions bad;
  bad.speed_mps = 0;
  EXPECT_THROW(samplePath(w, bad), Error);
}

// ---- laser model ----

TEST(LaserModel, GeometryAndValidation) {
  LaserModel l;
  EXPECT_NEAR(l.angleMin(), -135 * kPi / 180, 1e-12);
  EXPECT_NEAR(l.angleMin() + 540 * l.angleIncrement(), 135 * kPi / 180, 1e-12);
  l.fov_rad = 2 * kPi;
  l.beams = 360;
  EXPECT_NEAR(l.angleIncrement(), kPi / 180, 1e-15);
  EXPECT_NEAR(l.angleMin(), -kPi, 1e-15);
  l.beams = 0;
  EXPECT_THROW(l.validate(), Error);
  l = LaserModel{};
  l.range_max_m = 0.01;
  EXPECT_THROW(l.validate(), Error);
  l = LaserModel{};
  l.dropout = 1.5;
  EXPECT_THROW(l.validate(), Error);
}

// ---- the simulator ----

class SimWorld : public ::testing::TestWithParam<std::string> {};

TEST_P(SimWorld, NoiseFreeRangesEqualBruteForce) {
  const Scenario s = builtinScenario(GetParam());
  SimulatorOptions o = SimulatorOptions{}.noiseFree();
  o.laser.T_robot_laser = SE2(0.12, -0.03, 0.05);
  Rng rng(17);
  const V lo = s.world.boundsMin(), hi = s.world.boundsMax();
  std::vector<TimedPose> poses;
  for (int i = 0; i < 60; ++i)
    poses.push_back({0.1 * i, SE2(lo.x() + (hi.x() - lo.x()) * rng.uniform(), lo.y() + (hi.y() - lo.y()) * rng.uniform(),
                                  2 * kPi * rng.uniform())});
  const auto frames = simulate(s.world, poses, o);
  ASSERT_EQ(frames.size(), poses.size());
  for (const Frame& f : frames) {
    const SE2 T_world_laser = *f.T_world_robot * f.T_robot_laser;
    for (std::size_t i = 0; i < f.scan.size(); ++i) {
      const double a = T_world_laser.theta() + f.scan.angle(i);
      const double ref = s.world.castRayBruteForce(T_world_laser.translation(), V(std::cos(a), std::sin(a)), o.laser.range_max_m);
      const double expected = std::isfinite(ref) && ref < o.laser.range_max_m ? ref : o.laser.range_max_m;
      ASSERT_NEAR(f.scan.ranges()[i], expected, 1e-9) << "frame " << f.index << " beam " << i;
    }
  }
}

TEST_P(SimWorld, DeterministicPerSeed) {
  const Scenario s = builtinScenario(GetParam());
  const auto truth = samplePath(s.waypoints, PathOptions{}, 30);
  SimulatorOptions o;
  o.seed = 123;
  const auto a = simulate(s.world, truth, o);
  const auto b = simulate(s.world, truth, o);
  o.seed = 124;
  const auto c = simulate(s.world, truth, o);
  bool differs = false;
  for (std::size_t k = 0; k < a.size(); ++k) {
    EXPECT_EQ(a[k].scan.ranges(), b[k].scan.ranges());
    EXPECT_EQ(a[k].T_odom_robot->vector(), b[k].T_odom_robot->vector());
    if (a[k].scan.ranges() != c[k].scan.ranges() || a[k].T_odom_robot->vector() != c[k].T_odom_robot->vector())
      differs = true;
  }
  EXPECT_TRUE(differs);
}

TEST_P(SimWorld, RouteKeepsClearanceFromObstacles) {
  const Scenario s = builtinScenario(GetParam());
  const auto poses = samplePath(s.waypoints, PathOptions{});
  double min_clearance = 1e9;
  for (const auto& p : poses) min_clearance = std::min(min_clearance, s.world.distance(p.T_world_robot.translation()));
  EXPECT_GE(min_clearance, 0.3) << GetParam();
}

INSTANTIATE_TEST_SUITE_P(AllWorlds, SimWorld, ::testing::Values("office", "corridor", "symmetric", "open"));

TEST(Simulator, NoiseFreeOdometryEqualsTruthMotion) {
  const Scenario s = builtinScenario("office");
  const auto frames = simulate(s.world, samplePath(s.waypoints, PathOptions{}, 200), SimulatorOptions{}.noiseFree());
  EXPECT_TRUE(IsNearPose(*frames[0].T_world_robot, *frames[0].T_odom_robot, 1e-12, 1e-10));
  for (std::size_t k = 1; k < frames.size(); ++k) {
    const SE2 truth = frames[k - 1].T_world_robot->inverse() * *frames[k].T_world_robot;
    const SE2 odom = frames[k - 1].T_odom_robot->inverse() * *frames[k].T_odom_robot;
    EXPECT_TRUE(IsNearPose(truth, odom, 1e-9, 1e-7)) << k;
    EXPECT_TRUE(IsNearPose(*frames[k].T_world_robot, *frames[k].T_odom_robot, 1e-9, 1e-7)) << k;
  }
}

TEST(Simulator, DefaultOdometryDrifts) {
  const Scenario s = builtinScenario("corridor");
  const auto frames = simulate(s.world, samplePath(s.waypoints, PathOptions{}), SimulatorOptions{});
  const SE2& truth = *frames.back().T_world_robot;
  const SE2& odom = *frames.back().T_odom_robot;
  const double dist = pathLength(samplePath(s.waypoints, PathOptions{}));
  const double err = (truth.translation() - odom.translation()).norm();
  // Drifts noticeably but stays plausible for wheel odometry: 0.1 % .. 10 % of the distance.
  EXPECT_GT(err, 0.001 * dist);
  EXPECT_LT(err, 0.10 * dist);
}

TEST(Simulator, RangeNoiseAndDropoutStatistics) {
  const Scenario s = builtinScenario("office");
  SimulatorOptions o;
  o.laser.range_noise_m = 0.02;
  o.laser.dropout = 0.1;
  std::vector<TimedPose> poses(300, TimedPose{0.0, SE2(3.0, 7.5, 0.3)});
  for (std::size_t i = 0; i < poses.size(); ++i) poses[i].time_s = 0.1 * static_cast<double>(i);
  Simulator sim(s.world, poses, o);
  const std::vector<double> exact = sim.exactRanges(poses[0].T_world_robot);
  Stats err;
  double hits = 0, dropped = 0;
  while (auto f = sim.next()) {
    for (std::size_t i = 0; i < exact.size(); ++i) {
      if (exact[i] >= o.laser.range_max_m) {
        EXPECT_EQ(f->scan.ranges()[i], o.laser.range_max_m);
        continue;
      }
      ++hits;
      if (f->scan.ranges()[i] == 0.0) {  // a lost echo: an error reading, invalid
        ++dropped;
        EXPECT_FALSE(f->scan.isValid(i));
      } else {
        EXPECT_NE(f->scan.ranges()[i], o.laser.range_max_m);
        err.add(f->scan.ranges()[i] - exact[i]);
      }
    }
  }
  ASSERT_GT(hits, 10000);
  EXPECT_NEAR(dropped / hits, 0.1, 0.01);
  EXPECT_NEAR(err.mean(), 0.0, 0.001);
  EXPECT_NEAR(err.stddev(), 0.02, 0.001);
}

TEST(Simulator, FramesCarryMountingTruthAndTimes) {
  const Scenario s = builtinScenario("symmetric");
  SimulatorOptions o;
  o.laser.beams = 360;
  o.laser.fov_rad = 2 * kPi;
  const auto frames = simulate(s.world, samplePath(s.waypoints, PathOptions{}, 20), o);
  ASSERT_EQ(frames.size(), 20u);
  for (std::size_t k = 0; k < frames.size(); ++k) {
    EXPECT_EQ(frames[k].index, k);
    EXPECT_NEAR(frames[k].time, 0.1 * static_cast<double>(k), 1e-12);
    EXPECT_EQ(frames[k].scan.time(), frames[k].time);
    EXPECT_EQ(frames[k].scan.size(), 360u);
    EXPECT_TRUE(frames[k].T_robot_laser.isApprox(SE2(0.1, 0, 0)));
    EXPECT_TRUE(frames[k].T_world_robot.has_value());
    EXPECT_TRUE(frames[k].T_odom_robot.has_value());
  }
}

TEST(Simulator, PeopleWalkTheRouteAndOnlyShortenBeams) {
  const Scenario s = builtinScenario("office");
  const auto path = samplePath(s.waypoints, PathOptions{}, 400);
  SimulatorOptions o;
  o.crowd.people = 8;
  Simulator with(s.world, path, o);
  const auto alone = simulate(s.world, path, SimulatorOptions{});
  std::size_t shorter = 0;
  for (std::size_t k = 0; auto f = with.next(); ++k) {
    // The odometry and the truth do not know the people; no beam reads longer than without them,
    // and the noise is the same where a beam hit the same wall.
    EXPECT_TRUE(IsNearPose(*alone[k].T_odom_robot, *f->T_odom_robot, 0.0, 0.0)) << k;
    const auto people = with.peopleAt(f->time);
    ASSERT_EQ(people.size(), 8u);
    for (std::size_t i = 0; i < f->scan.size(); ++i) {
      const double a = alone[k].scan.ranges()[i], b = f->scan.ranges()[i];
      if (a == b) continue;
      ++shorter;
      // A shortened beam ends on the rim of a person's disc (0.25 m; 5 cm for the range noise;
      // two people may overlap).
      const double ang = f->scan.angle(i);
      const Eigen::Vector2d end =
          *f->T_world_robot * (f->T_robot_laser * Eigen::Vector2d(b * std::cos(ang), b * std::sin(ang)));
      double off_rim = 1e9;
      for (const auto& c : people) off_rim = std::min(off_rim, std::abs((end - c).norm() - 0.25));
      if (b > 0.0) {
        EXPECT_LE(off_rim, 0.05) << k << " " << i;
      }
    }
    // Each person is on the route, within 0.5 m of where the robot is at some time.
    for (const auto& c : people) {
      double d = 1e9;
      for (const TimedPose& p : path) d = std::min(d, (p.T_world_robot.translation() - c).norm());
      EXPECT_LE(d, 0.5 + 0.05) << k;
    }
  }
  EXPECT_GT(shorter, 1000u);
  // Deterministic per seed; no people, no change to the frames.
  const auto again = simulate(s.world, path, o);
  Simulator twice(s.world, path, o);
  for (std::size_t k = 0; auto f = twice.next(); ++k) EXPECT_EQ(f->scan.ranges(), again[k].scan.ranges());
  o.crowd.people = 0;
  const auto none = simulate(s.world, path, o);
  for (std::size_t k = 0; k < none.size(); ++k) EXPECT_EQ(none[k].scan.ranges(), alone[k].scan.ranges());
  o.crowd.radius_m = -1;
  EXPECT_THROW(Simulator(s.world, path, o), Error);
}

// ---- what each built-in world promises ----

TEST(Worlds, OfficeRouteVisitsEveryRoom) {
  const auto poses = route("office");
  struct Box {
    double x0, y0, x1, y1;
  };
  const Box rooms[] = {{0, 0, 5, 6.5},    {5, 0, 10, 6.5},    {10, 0, 15, 6.5},  {15, 0, 20, 6.5},
                       {0, 8.5, 7, 15},   {7, 8.5, 13, 15},   {13, 8.5, 20, 15}};
  for (const Box& b : rooms) {
    int inside = 0;
    for (const auto& p : poses) {
      const V t = p.T_world_robot.translation();
      if (t.x() > b.x0 + 0.9 && t.x() < b.x1 - 0.9 && t.y() > b.y0 + 0.9 && t.y() < b.y1 - 0.9) ++inside;
    }
    EXPECT_GT(inside, 50) << "room " << b.x0 << "," << b.y0;
  }
}

TEST(Worlds, CorridorIsSixtyMetresAndFeatureless) {
  const Scenario s = builtinScenario("corridor");
  const auto poses = route("corridor");
  double min_x = 1e9, max_x = -1e9;
  for (const auto& p : poses) {
    min_x = std::min(min_x, p.T_world_robot.x());
    max_x = std::max(max_x, p.T_world_robot.x());
  }
  EXPECT_LT(min_x, -4.0);  // drives through the west room ...
  EXPECT_GT(max_x, 64.0);  // ... the whole corridor and into the east room
  // Scans in the middle of the corridor (x 25..35, more than 25 m from either end) see only the two
  // long walls (y = +-1, 0 <= x <= 60): nothing in the end rooms is within range through the opening.
  std::vector<TimedPose> middle;
  for (const auto& p : poses)
    if (p.T_world_robot.x() > 25 && p.T_world_robot.x() < 35) middle.push_back(p);
  ASSERT_GT(middle.size(), 100u);
  const auto frames = simulate(s.world, middle, SimulatorOptions{}.noiseFree());
  for (const Frame& f : frames) {
    const SE2 T_world_laser = *f.T_world_robot * f.T_robot_laser;
    ASSERT_GT(f.scan.numValid(), 100u);
    for (const V& p_laser : f.scan.toPoints()) {
      const V p = T_world_laser * p_laser;
      ASSERT_NEAR(std::abs(p.y()), 1.0, 1e-9) << p.transpose();
      ASSERT_GE(p.x(), 0.0);
      ASSERT_LE(p.x(), 60.0);
    }
  }
}

TEST(Worlds, SymmetricRoomsGiveIdenticalScans) {
  const Scenario s = builtinScenario("symmetric");
  Simulator sim(s.world, {}, SimulatorOptions{}.noiseFree());
  Rng rng(21);
  for (int i = 0; i < 50; ++i) {
    SE2 pose(0.5 + 5 * rng.uniform(), 0.5 + 5 * rng.uniform(), 2 * kPi * rng.uniform());  // room I
    const auto r0 = sim.exactRanges(pose);
    for (int k = 1; k < 4; ++k) {
      pose = SE2(0, 0, kPi / 2) * pose;  // the corresponding pose in the next room
      const auto rk = sim.exactRanges(pose);
      for (std::size_t b = 0; b < r0.size(); ++b) ASSERT_NEAR(rk[b], r0[b], 1e-6) << "room " << k << " beam " << b;
    }
  }
  // The route visits all four rooms.
  int quadrants[4] = {0, 0, 0, 0};
  for (const auto& p : route("symmetric")) {
    const V t = p.T_world_robot.translation();
    ++quadrants[(t.x() >= 0 ? 0 : 1) + (t.y() >= 0 ? 0 : 2)];
  }
  for (int q : quadrants) EXPECT_GT(q, 40);
}

TEST(Worlds, OpenWorldHasFewReturns) {
  const Scenario s = builtinScenario("open");
  const auto frames = simulate(s.world, route("open"), SimulatorOptions{});
  double valid = 0, total = 0;
  for (const Frame& f : frames) {
    valid += static_cast<double>(f.scan.numValid());
    total += static_cast<double>(f.scan.size());
  }
  EXPECT_LT(valid / total, 0.25);
  EXPECT_GT(valid, 0.0);
}

}  // namespace
}  // namespace lidar2d::sim
