// SLAM loop closure through the localization module's line-pair descriptors: a return to known
// ground after a drift far beyond the proximity search's radius is closed (and only then does the
// map come back together), and aliased places (the four identical rooms of the symmetric world,
// the office's repeated rooms) never enter the graph as closures.

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <fstream>
#include <iterator>
#include <nlohmann/json.hpp>
#include <sstream>
#include <numbers>
#include <string>

#include "lidar2d/core/error.hpp"
#include "lidar2d/eval/metrics.hpp"
#include "lidar2d/io/carmen_writer.hpp"
#include "lidar2d/io/trajectory.hpp"
#include "lidar2d/localization/lines.hpp"
#include "lidar2d/localization/localizer.hpp"
#include "lidar2d/sim/simulator.hpp"
#include "lidar2d/sim/worlds.hpp"
#include "lidar2d/slam/slam.hpp"
#include "support/test_support.hpp"

namespace lidar2d::slam {
namespace {

using V = Eigen::Vector2d;

/// The corridor world driven west room -> east room -> west room. The odometry reads every metre
/// driven eastwards along the corridor `bias` too long (and westwards correctly), and in the
/// featureless corridor the front end can only take the translation along it from the odometry:
/// the robot comes back to the west room with the estimate about 64 * bias metres off.
std::vector<Frame> corridorThereAndBack(double bias, std::uint64_t seed) {
  const sim::Scenario sc = sim::builtinScenario("corridor");
  const std::vector<V> route{V(-6, -2.5), V(-6, 2.5), V(-2, 2.5), V(-2, 0),    V(62, 0),  V(62, -2.5), V(66, -2.5),
                             V(66, 2.5), V(62.5, 2.5), V(62, 0), V(-2, 0), V(-2, -2.5), V(-6, -2.5), V(-6, 2.5), V(-2, 2.5), V(-2, -2.5), V(-6, -2.5)};
  sim::PathOptions po;
  sim::SimulatorOptions so;
  so.seed = seed;
  so.laser.beams = 181;
  std::vector<Frame> frames = sim::simulate(sc.world, sim::samplePath(route, po), so);
  double extra = 0.0;
  for (std::size_t i = 1; i < frames.size(); ++i) {
    const V a = frames[i - 1].T_world_robot->translation(), b = frames[i].T_world_robot->translation();
    if (b.x() > a.x() && a.x() > 2.0 && b.x() < 58.0) extra += bias * (b.x() - a.x());
    frames[i].T_odom_robot = SE2(extra, 0.0, 0.0) * *frames[i].T_odom_robot;
  }
  return frames;
}

struct RunResult {
  double ate = 0.0;  ///< after an SE(2) alignment [m]
  double end_error = 0.0;  ///< largest position error of the last 50 scans (no alignment) [m]
  SlamStats stats;
  std::size_t descriptor_loops = 0;        ///< accepted closures found through descriptors
  double worst_descriptor_error_m = 0.0;   ///< of those, against the truth [m]
  double worst_descriptor_error_rad = 0.0;
  std::size_t wrong_loops = 0;             ///< accepted descriptor closures more than 0.5 m / 5 deg off the truth
  std::size_t aliases_rejected = 0;        ///< rejected descriptor closures more than 1 m or 10 deg off the truth
  std::string events;                      ///< every event, one a line
};

RunResult runSlam(const std::vector<Frame>& frames, const SlamOptions& o) {
  Slam slam(o);
  for (const auto& f : frames) slam.add(f);
  slam.finish();
  const auto traj = slam.trajectory();
  Trajectory est, truth;
  for (std::size_t i = 0; i < frames.size(); ++i) {
    est.push_back({frames[i].time, traj[i].T_world_robot});
    truth.push_back({frames[i].time, *frames[i].T_world_robot});
  }
  RunResult r;
  r.ate = eval::evaluateTrajectory(est, truth).ate.trans_m.rmse;
  r.stats = slam.stats();
  for (const auto& ev : slam.events()) r.events += ev.what + "\n";
  for (std::size_t i = frames.size() > 50 ? frames.size() - 50 : 0; i < frames.size(); ++i)
    r.end_error = std::max(r.end_error, (traj[i].T_world_robot.translation() - frames[i].T_world_robot->translation()).norm());
  for (const auto& c : slam.constraints()) {
    if (c.kind != Constraint::Kind::kLoop || !c.searched) continue;
    const SE2& a = *frames[traj[slam.nodes()[c.from].scan].frame_index].T_world_robot;
    const SE2& b = *frames[traj[slam.nodes()[c.to].scan].frame_index].T_world_robot;
    const SE2 err = (a.inverse() * b).inverse() * c.T_from_to;
    const double em = err.translation().norm(), er = std::abs(err.theta());
    if (!c.descriptor) continue;
    if (!c.accepted) {
      if (em > 1.0 || er > 10.0 * kDeg) ++r.aliases_rejected;
      continue;
    }
    if (em > 0.5 || er > 5.0 * kDeg) ++r.wrong_loops;
    ++r.descriptor_loops;
    r.worst_descriptor_error_m = std::max(r.worst_descriptor_error_m, em);
    r.worst_descriptor_error_rad = std::max(r.worst_descriptor_error_rad, er);
  }
  return r;
}

TEST(SlamDescriptorLoops, ClosesALoopAfterDriftBeyondTheSearchRadius) {
  const auto frames = corridorThereAndBack(0.15, 1);
  SlamOptions off;
  off.descriptor_loops = false;
  const RunResult without = runSlam(frames, off);
  const RunResult with = runSlam(frames, SlamOptions{});
  // The proximity search alone cannot reconnect: the drift (~9 m) exceeds its 5 m radius.
  EXPECT_GT(without.ate, 1.0);
  EXPECT_EQ(without.descriptor_loops, 0u);
  EXPECT_GT(with.descriptor_loops, 0u);
  EXPECT_GT(with.stats.descriptor_accepted, 0u);
  EXPECT_LT(with.worst_descriptor_error_m, 0.2);
  EXPECT_LT(with.worst_descriptor_error_rad, 2.0 * kDeg);
  EXPECT_EQ(with.wrong_loops, 0u);
  EXPECT_NE(with.events.find("loop closure found by descriptors"), std::string::npos) << with.events;
  std::printf("ATE %.3f m -> %.3f m, last scans' error %.2f m -> %.2f m, %zu descriptor closures (worst %.3f m)\n",
              without.ate, with.ate, without.end_error, with.end_error, with.descriptor_loops,
              with.worst_descriptor_error_m);
  // Back in the west room the estimate is where the robot is again (the odometry's bias, which the
  // graph cannot know to be eastbound only, is spread over the whole corridor: the ATE improves less).
  EXPECT_GT(without.end_error, 5.0);
  EXPECT_LT(with.end_error, 0.5);
  EXPECT_LT(with.ate, 0.8 * without.ate) << "without descriptors " << without.ate;
}

// The proximity search's window (`loop_linear_window_m`) has to reach a revisit from where the
// running estimate puts it: back in the west room after metres of drift along the corridor,
// the search alone (no descriptors) closes the loop with the default window, not with 2 m.
TEST(SlamDescriptorLoops, TheProximitySearchReachesARevisitMetresOff) {
  const auto frames = corridorThereAndBack(0.06, 1);
  SlamOptions defaults;
  defaults.descriptor_loops = false;
  SlamOptions narrow = defaults;
  narrow.loop_linear_window_m = 2.0;
  const RunResult wide = runSlam(frames, defaults), two = runSlam(frames, narrow);
  std::printf("end error %.2f m with the default window, %.2f m with 2 m\n", wide.end_error, two.end_error);
  EXPECT_LT(wide.end_error, 0.5);
  EXPECT_GT(two.end_error, 1.5);
}

// The window widens with the path travelled since the latest accepted closure: after 5 m of drift
// along the corridor (beyond the 3 m least window and the 5 m radius's margin), a window that grows
// with the open path reaches the west room again; a fixed 3 m one does not. (The proximity search
// alone: no descriptors.)
TEST(SlamDescriptorLoops, TheWindowGrowsWithThePathSinceTheLastClosure) {
  const auto frames = corridorThereAndBack(0.09, 1);
  SlamOptions growing;
  growing.descriptor_loops = false;
  growing.loop_window_per_m = 0.1;
  SlamOptions fixed = growing;
  fixed.loop_window_per_m = 0.0;
  const RunResult grown = runSlam(frames, growing), three = runSlam(frames, fixed);
  std::printf("end error %.2f m with the growing window, %.2f m with a fixed 3 m one\n", grown.end_error,
              three.end_error);
  EXPECT_LT(grown.end_error, 0.5);
  EXPECT_GT(three.end_error, 2.0);
}

TEST(SlamDescriptorLoops, CliRecordsDescriptorClosuresInGraphSummaryAndReport) {
  const auto frames = corridorThereAndBack(0.15, 1);
  test::TempDir t;
  const std::string log = (t.path() / "corridor.log").string();
  {
    io::CarmenWriter w(log);
    for (const auto& f : frames) w.write(f);
    w.commit();
  }
  const auto r = test::runCli({"slam", log, "-o", (t.path() / "out").string(), "-q"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  std::ifstream graph(t.path() / "out" / "graph.txt");
  std::size_t accepted = 0;
  for (std::string line; std::getline(graph, line);) {
    std::istringstream in(line);
    std::string tag, kind;
    std::size_t from = 0, to = 0;
    double dx = 0, dy = 0, dth = 0;
    int acc = 0, searched = 0;
    in >> tag >> kind >> from >> to >> dx >> dy >> dth >> acc >> searched;
    if (tag == "EDGE" && kind == "loop_descriptor" && acc == 1) {
      EXPECT_EQ(searched, 1) << line;
      ++accepted;
    }
  }
  EXPECT_GE(accepted, 2u);  // the closure and the one confirming it
  std::ifstream sj(t.path() / "out" / "summary.json");
  const auto summary = nlohmann::json::parse(sj);
  EXPECT_EQ(summary.at("descriptor_closures_accepted").get<std::size_t>(), accepted);
  EXPECT_GT(summary.at("descriptor_queries").get<std::size_t>(), 0u);
  std::ifstream html(t.path() / "out" / "report.html");
  const std::string page((std::istreambuf_iterator<char>(html)), std::istreambuf_iterator<char>());
  EXPECT_NE(page.find("class=\"loop-descriptor\""), std::string::npos);
  EXPECT_NE(page.find("loop closure found by descriptors"), std::string::npos);
}

TEST(SlamDescriptorLoops, AliasedPlacesAreNotClosed) {
  // Four identical rooms (the symmetric world) and an office of look-alike rooms along a corridor,
  // with and without odometry, looked up far more often than by default: the descriptors propose
  // the look-alikes and the verification passes some of them, but none may enter the graph.
  std::size_t aliases = 0;
  for (const std::string world : {"symmetric", "office"})
    for (const bool odometry : {true, false}) {
      const sim::Scenario sc = sim::builtinScenario(world);
      sim::SimulatorOptions so;
      so.seed = 7;
      so.laser.beams = 181;
      const auto frames = sim::simulate(sc.world, sim::samplePath(sc.waypoints, sim::PathOptions{}), so);
      SlamOptions o;
      o.use_odometry = odometry;
      o.descriptor_every_nodes = 2;
      o.descriptor_quiet_nodes = 0;
      const RunResult r = runSlam(frames, o);
      SCOPED_TRACE(world + (odometry ? " with odometry" : " without odometry"));
      EXPECT_GT(r.stats.descriptor_hypotheses, 0u);
      EXPECT_EQ(r.wrong_loops, 0u);
      EXPECT_LT(r.worst_descriptor_error_m, 0.2);
      EXPECT_LT(r.ate, 0.1);
      aliases += r.aliases_rejected;
    }
  // The test has something to catch: look-alike places passed the branch-and-bound and ICP checks.
  EXPECT_GT(aliases, 0u);
}

TEST(SlamDescriptorLoops, VoteLinePairsFindsTheRelativePoseOfTwoScans) {
  // The lookup SLAM shares with the localizer, on a database of real scans: one scan of the office
  // as the database position (at its true pose) and another scan from 10 cm away, turned by 50
  // degrees, as the query (the keys are the lines' distances: invariant to the rotation only).
  const sim::Scenario sc = sim::builtinScenario("office");
  const SE2 T_a(3.0, 3.0, 0.3), T_b(3.08, 2.95, 1.2);
  sim::SimulatorOptions so;
  so.laser.fov_rad = 2.0 * std::numbers::pi;
  const auto frames = sim::simulate(sc.world, {{0.0, T_a}, {0.1, T_b}}, so);
  ASSERT_EQ(frames.size(), 2u);
  auto linesOf = [](const Frame& f) {
    return localization::extractLines(f.scan.toPoints(f.T_robot_laser), localization::LineExtractionOptions{});
  };
  const auto la = linesOf(frames[0]), lb = linesOf(frames[1]);
  ASSERT_GE(la.size(), 4u);
  ASSERT_GE(lb.size(), 4u);
  localization::Database::Position pos;
  pos.x = static_cast<float>(T_a.x());
  pos.y = static_cast<float>(T_a.y());
  pos.num_lines = static_cast<std::uint32_t>(la.size());
  std::vector<localization::Database::LineFeature> features;
  for (const auto& l : la)
    features.push_back({static_cast<float>(wrapAngle(l.normal_angle + T_a.theta())), static_cast<float>(l.distance),
                        static_cast<float>(l.length)});
  const auto db = localization::Database::fromParts(localization::DatabaseOptions{}, 0, {pos}, features);
  std::size_t hits = 0;
  const auto votes = localization::voteLinePairs(db, lb, localization::LocalizerOptions{}, 3, &hits);
  ASSERT_FALSE(votes.empty());
  EXPECT_GT(hits, 0u);
  EXPECT_LE(votes.size(), 3u);
  for (std::size_t i = 1; i < votes.size(); ++i) EXPECT_GE(votes[i - 1].votes, votes[i].votes);
  EXPECT_LT((votes[0].T_world_robot.translation() - T_b.translation()).norm(), 0.3);
  EXPECT_LT(std::abs(angleDiff(votes[0].T_world_robot.theta(), T_b.theta())), 6.0 * kDeg);
  // An empty database answers nothing.
  const auto empty = localization::Database::fromParts(localization::DatabaseOptions{}, 0, {}, {});
  EXPECT_TRUE(localization::voteLinePairs(empty, lb, localization::LocalizerOptions{}, 3).empty());
}

TEST(SlamDescriptorLoops, OptionsAreValidated) {
  auto bad = [](auto set) {
    SlamOptions o;
    set(o);
    EXPECT_THROW(o.validate(), Error);
  };
  bad([](SlamOptions& o) { o.descriptor_every_nodes = 0; });
  bad([](SlamOptions& o) { o.descriptor_quiet_nodes = -1; });
  bad([](SlamOptions& o) { o.descriptor_min_age_nodes = -1; });
  bad([](SlamOptions& o) { o.descriptor_min_votes = 0.5; });
  bad([](SlamOptions& o) { o.descriptor_max_candidates = 0; });
  bad([](SlamOptions& o) { o.descriptor_max_lines = 1; });
  bad([](SlamOptions& o) { o.descriptor_linear_window_m = 0.0; });
  bad([](SlamOptions& o) { o.descriptor_angular_window_rad = -1.0; });
  bad([](SlamOptions& o) { o.descriptor_max_correction_m = -1.0; });
  bad([](SlamOptions& o) { o.descriptor_drift_fraction = std::nan(""); });
  bad([](SlamOptions& o) { o.descriptor_max_rotation_rad = -0.1; });
  EXPECT_NO_THROW(SlamOptions{}.validate());
}

}  // namespace
}  // namespace lidar2d::slam
