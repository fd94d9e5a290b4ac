// The matcher dispatcher: every method x solver through one entry point recovers known motions on
// noise-free simulated scans, scan to scan and scan to map, and bad options come back as a
// Result, not an exception.

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>

#include "lidar2d/mapping/export.hpp"
#include "lidar2d/mapping/occupancy_map.hpp"
#include "lidar2d/registration/matcher.hpp"
#include "lidar2d/sim/path.hpp"
#include "lidar2d/sim/simulator.hpp"
#include "lidar2d/sim/worlds.hpp"
#include "support/test_support.hpp"

namespace lidar2d::registration {
namespace {

struct Variant {
  Method method;
  Solver solver;
  friend void PrintTo(const Variant& v, std::ostream* os) { *os << toString(v.method) << "_" << toString(v.solver); }
};

// Exact ranges of the office world as robot-frame points (what `lidar2d match` gives the matcher).
Points2 officePoints(const SE2& T_world_robot) {
  static const sim::Scenario scenario = sim::builtinScenario("office");
  sim::SimulatorOptions o = sim::SimulatorOptions{}.noiseFree();
  o.laser.beams = 361;
  static const sim::Simulator simulator(scenario.world, {{0.0, SE2()}}, o);
  return simulator.exactScan(T_world_robot).toPoints(simulator.options().laser.T_robot_laser);
}

class MatcherVariants : public ::testing::TestWithParam<Variant> {};

TEST_P(MatcherVariants, RecoversKnownMotionThroughTheDispatcher) {
  MatcherOptions o;
  o.method = GetParam().method;
  o.solver = GetParam().solver;
  // Poses inside rooms of the office (x, y, heading) and small motions between scans.
  const std::vector<SE2> poses{{2.5, 3.0, 0.3}, {12.0, 7.5, 0.0}, {8.5, 11.5, -1.2}, {17.0, 3.5, 2.5}};
  const SE2 motion(0.15, -0.05, 0.06);
  const SE2 guess_error(0.05, 0.04, 0.03);
  // Point-to-point pairs beam endpoints that are not the same surface points, so it is biased by
  // about the beam spacing (as in test_icp); the other methods are exact to the millimetre here.
  const bool p2p = o.method == Method::kP2P;
  const double tol_m = p2p ? 0.05 : 0.02, tol_deg = p2p ? 1.0 : 0.5;
  int ok = 0;
  for (const SE2& T_world_prev : poses) {
    const SE2 T_world_cur = T_world_prev * motion;
    const PreparedTarget target(officePoints(T_world_prev), o);
    const Result r = matchScans(target, officePoints(T_world_cur), motion * guess_error, o);
    ok += test::IsNearPose(motion, r.T_target_source, tol_m, tol_deg) ? 1 : 0;
    EXPECT_TRUE(r.T_target_source.isFinite());
    EXPECT_TRUE(r.information.allFinite());
  }
  EXPECT_EQ(ok, static_cast<int>(poses.size())) << toString(o.method) << "/" << toString(o.solver);
}

TEST_P(MatcherVariants, BadInputIsAResultNotAnException) {
  MatcherOptions o;
  o.method = GetParam().method;
  o.solver = GetParam().solver;
  const Points2 target = officePoints(SE2(2.5, 3.0, 0.3));
  const Result empty = matchScans(target, Points2{}, SE2(), o);
  EXPECT_FALSE(empty.converged);
  EXPECT_TRUE(empty.T_target_source.isFinite());
  const Result nan_guess = matchScans(target, target, SE2(std::nan(""), 0, 0), o);
  EXPECT_FALSE(nan_guess.converged);
  EXPECT_TRUE(nan_guess.T_target_source.isFinite());
}

INSTANTIATE_TEST_SUITE_P(All, MatcherVariants,
                         ::testing::Values(Variant{Method::kP2P, Solver::kGaussNewton}, Variant{Method::kP2P, Solver::kCeres},
                                           Variant{Method::kP2L, Solver::kGaussNewton}, Variant{Method::kP2L, Solver::kCeres},
                                           Variant{Method::kLikelihoodField, Solver::kGaussNewton},
                                           Variant{Method::kLikelihoodField, Solver::kCeres},
                                           Variant{Method::kCorrelative, Solver::kGaussNewton},
                                           Variant{Method::kCorrelative, Solver::kCeres}),
                         [](const auto& info) {
                           return std::string(toString(info.param.method)) + "_" + toString(info.param.solver);
                         });

// Scan-to-map: a map built by the mapping module from noise-free scans along the office's route,
// then scans at other poses of that route matched against it from a guess 13 cm and 3 deg off, by
// the methods that match maps (likelihood field, correlative).
struct OfficeRoute {
  sim::Scenario scenario = sim::builtinScenario("office");
  std::vector<sim::TimedPose> route = sim::samplePath(scenario.waypoints, sim::PathOptions{});
  std::unique_ptr<sim::Simulator> simulator;  // noise-free 360 beams over 360 deg, laser at the robot's centre
  OccupancyImage map;

  LaserScan scanAt(const SE2& T_world_robot) const { return simulator->exactScan(T_world_robot); }
};

const OfficeRoute& officeRoute() {
  static const OfficeRoute office = [] {
    OfficeRoute r;
    sim::SimulatorOptions o = sim::SimulatorOptions{}.noiseFree();
    o.laser.beams = 360;
    o.laser.fov_rad = 2.0 * std::numbers::pi;
    o.laser.T_robot_laser = SE2();
    r.simulator = std::make_unique<sim::Simulator>(r.scenario.world, std::vector<sim::TimedPose>{{0.0, SE2()}}, o);
    mapping::MapOptions mo;
    mo.resolution_m = 0.05;
    auto map = mapping::makeMap(mapping::MapModel::kLogOdds, mo);
    for (std::size_t k = 0; k < r.route.size(); k += 5)
      map->insert(r.scanAt(r.route[k].T_world_robot), r.route[k].T_world_robot);
    r.map = mapping::toOccupancyImage(*map);
    return r;
  }();
  return office;
}

TEST_P(MatcherVariants, ScanToMapRecoversThePose) {
  MatcherOptions o;
  o.method = GetParam().method;
  o.solver = GetParam().solver;
  const OfficeRoute& office = officeRoute();
  const PreparedTarget target = PreparedTarget::fromMap(office.map, o);
  if (o.method == Method::kP2P || o.method == Method::kP2L) {
    // Not offered (matcher.hpp says why): every match says so.
    const SE2 truth = office.route[7].T_world_robot;
    const Result r = matchScans(target, office.scanAt(truth).toPoints(), truth, o);
    EXPECT_EQ(r.status, Status::kInvalidInput);
    EXPECT_NE(r.message.find("lf or corr"), std::string::npos) << r.message;
    return;
  }
  ASSERT_TRUE(target.error().empty()) << target.error();
  // The office's walls run along cell borders, and a map cannot say on which side of a border its
  // wall lies: within half a cell along each axis (3.5 cm at 5 cm cells) and half a degree.
  const double tol_m = 0.5 * std::sqrt(2.0) * office.map.resolution();
  const SE2 guess_error(0.1, -0.08, 3.0 * std::numbers::pi / 180.0);
  int ok = 0, n = 0;
  for (std::size_t k = 7; k < office.route.size(); k += office.route.size() / 6, ++n) {
    const SE2 truth = office.route[k].T_world_robot;
    const Result r = matchScans(target, office.scanAt(truth).toPoints(), truth * guess_error, o);
    const bool near = test::IsNearPose(truth, r.T_target_source, tol_m, 0.5);
    ok += near ? 1 : 0;
    EXPECT_TRUE(near) << "truth " << truth.x() << " " << truth.y() << " " << truth.theta() << ", got "
                      << r.T_target_source.x() << " " << r.T_target_source.y() << " " << r.T_target_source.theta()
                      << " (" << toString(r.status) << ", " << r.num_inliers << " inliers)";
  }
  EXPECT_EQ(ok, n) << toString(o.method) << "/" << toString(o.solver);
}

TEST(Matcher, MapTargetWithAnOutOfDomainThresholdIsInvalidInput) {
  for (Method m : {Method::kP2P, Method::kP2L, Method::kLikelihoodField, Method::kCorrelative}) {
    MatcherOptions o;
    o.method = m;
    o.map_occupied_min = 0;
    const PreparedTarget target = PreparedTarget::fromMap(officeRoute().map, o);
    const Result r = matchScans(target, officePoints(SE2(2.5, 3.0, 0.3)), SE2(2.5, 3.0, 0.3), o);
    EXPECT_EQ(r.status, Status::kInvalidInput) << toString(m);
    EXPECT_NE(r.message.find("map_occupied_min"), std::string::npos) << r.message;
  }
}

TEST(Matcher, OutOfDomainOptionsAreReportedInTheResult) {
  MatcherOptions o;
  o.method = Method::kLikelihoodField;
  o.lf.resolution_m = -1;
  const Points2 target = officePoints(SE2(2.5, 3.0, 0.3));
  const Result r = matchScans(target, target, SE2(), o);
  EXPECT_EQ(r.status, Status::kInvalidInput);
  EXPECT_NE(r.message.find("resolution"), std::string::npos) << r.message;
  o.method = Method::kCorrelative;
  o.lf = {};
  o.corr.linear_window_m = -1;
  const Result c = matchScans(target, target, SE2(), o);
  EXPECT_EQ(c.status, Status::kInvalidInput);
}

}  // namespace
}  // namespace lidar2d::registration
