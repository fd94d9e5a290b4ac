// MapBuilder and FramePoses: the pose of each frame (truth, odometry, auto, a trajectory by index
// then nearest time), errors naming the scan, and the map equal cell for cell to inserting every
// frame directly, on the simulated office (noisy odometry, so truth and odometry differ).

#include <gtest/gtest.h>

#include <optional>
#include <string>
#include <tuple>
#include <vector>

#include "lidar2d/core/error.hpp"
#include "lidar2d/mapping/map_builder.hpp"
#include "lidar2d/sim/path.hpp"
#include "lidar2d/sim/simulator.hpp"
#include "lidar2d/sim/worlds.hpp"
#include "support/test_support.hpp"

namespace lidar2d::mapping {

void PrintTo(MapModel m, std::ostream* os) { *os << toString(m); }
void PrintTo(PoseSource s, std::ostream* os) {
  *os << (s == PoseSource::kAuto ? "auto" : s == PoseSource::kTruth ? "truth" : "odometry");
}

namespace {

using test::throwsError;

const std::vector<Frame>& officeFrames() {
  static const std::vector<Frame> frames = [] {
    const sim::Scenario scenario = sim::builtinScenario("office");
    sim::PathOptions p;
    p.rate_hz = 2.0;  // a scan every 0.4 m keeps the test fast
    return sim::simulate(scenario.world, sim::samplePath(scenario.waypoints, p), sim::SimulatorOptions{});
  }();
  return frames;
}

// A frame stream over `frames` (copies, as a log reader returns them).
MapBuilder::FrameStream streamOf(const std::vector<Frame>& frames) {
  auto next = std::make_shared<std::size_t>(0);
  return [&frames, next]() -> std::optional<Frame> {
    if (*next >= frames.size()) return std::nullopt;
    return frames[(*next)++];
  };
}

Frame frameAt(std::size_t index, double time) {
  Frame f;
  f.index = index;
  f.time = time;
  return f;
}

// Every cell of both maps' bounds agrees exactly (probability and classification), and so do the
// bounds and the work counters.
void expectSameMap(const OccupancyMap& a, const OccupancyMap& b) {
  ASSERT_FALSE(a.bounds().empty());
  ASSERT_EQ(a.bounds().min, b.bounds().min);
  ASSERT_EQ(a.bounds().max, b.bounds().max);
  EXPECT_EQ(a.cellUpdates(), b.cellUpdates());
  EXPECT_EQ(a.cellVisits(), b.cellVisits());
  std::size_t differ = 0;
  for (std::int32_t y = a.bounds().min.y; y <= a.bounds().max.y; ++y)
    for (std::int32_t x = a.bounds().min.x; x <= a.bounds().max.x; ++x)
      differ += a.probability({x, y}) != b.probability({x, y}) || a.state({x, y}) != b.state({x, y});
  EXPECT_EQ(differ, 0u);
}

TEST(FramePoses, TruthOdometryAndAuto) {
  Frame f = frameAt(4, 1.5);
  f.T_world_robot = SE2(1, 2, 0.3);
  f.T_odom_robot = SE2(-1, 0, 0.1);
  EXPECT_EQ(FramePoses::fromFrames(PoseSource::kTruth).T_world_robot(f).translation(), Eigen::Vector2d(1, 2));
  EXPECT_EQ(FramePoses::fromFrames(PoseSource::kOdometry).T_world_robot(f).translation(), Eigen::Vector2d(-1, 0));
  EXPECT_EQ(FramePoses::fromFrames(PoseSource::kAuto).T_world_robot(f).translation(), Eigen::Vector2d(1, 2));
  f.T_world_robot.reset();
  EXPECT_EQ(FramePoses::fromFrames(PoseSource::kAuto).T_world_robot(f).translation(), Eigen::Vector2d(-1, 0));
}

TEST(FramePoses, MissingPoseIsAnErrorNamingTheScan) {
  Frame f = frameAt(7, 2.25);
  f.T_odom_robot = SE2(1, 0, 0);
  EXPECT_TRUE(throwsError([&] { FramePoses::fromFrames(PoseSource::kTruth).T_world_robot(f); }, ErrorKind::kBadInput,
                          {"scan 7 (time 2.250000) has no truth pose"}));
  f.T_odom_robot.reset();
  EXPECT_TRUE(throwsError([&] { FramePoses::fromFrames(PoseSource::kAuto, "give poses").T_world_robot(f); },
                          ErrorKind::kBadInput, {"scan 7 (time 2.250000) has no odometry pose (give poses)"}));
}

TEST(FramePoses, TrajectoryByIndexThenNearestTime) {
  // Times repeat (1.0 twice): the index keeps them apart.
  const Trajectory traj{{0.0, SE2(0, 0, 0)}, {1.0, SE2(1, 0, 0)}, {1.0, SE2(2, 0, 0)}, {3.0, SE2(3, 0, 0)}};
  const FramePoses poses = FramePoses::fromTrajectory(traj, 0.01, "traj.txt");
  EXPECT_EQ(poses.T_world_robot(frameAt(1, 1.0)).x(), 1.0);
  EXPECT_EQ(poses.T_world_robot(frameAt(2, 1.0)).x(), 2.0);
  // Index and time disagree: the nearest time within max_dt (the first of repeated times).
  EXPECT_EQ(poses.T_world_robot(frameAt(0, 3.005)).x(), 3.0);
  EXPECT_EQ(poses.T_world_robot(frameAt(3, 1.0)).x(), 1.0);
  EXPECT_EQ(poses.T_world_robot(frameAt(9, 0.0)).x(), 0.0);
  EXPECT_TRUE(throwsError([&] { poses.T_world_robot(frameAt(3, 2.0)); }, ErrorKind::kBadInput,
                          {"traj.txt: timestamp: has no pose within 0.01 s of scan 3 (time 2.000000)"}));
}

class MapBuilderEqualsDirectInsertion : public ::testing::TestWithParam<std::tuple<MapModel, PoseSource>> {};

TEST_P(MapBuilderEqualsDirectInsertion, CellForCell) {
  const auto [model, source] = GetParam();
  const std::vector<Frame>& frames = officeFrames();
  ASSERT_GT(frames.size(), 50u);
  MapOptions o;
  o.resolution_m = 0.05;
  auto direct = makeMap(model, o);
  for (const Frame& f : frames)
    direct->insert(f.scan, (source == PoseSource::kOdometry ? *f.T_odom_robot : *f.T_world_robot) * f.T_robot_laser);
  auto built = makeMap(model, o);
  MapBuilder builder(*built, FramePoses::fromFrames(source), {.source_name = "office", .read_ahead = 4});
  std::vector<std::size_t> progress;
  EXPECT_EQ(builder.insert(streamOf(frames), [&](std::size_t n) { progress.push_back(n); }), frames.size());
  ASSERT_EQ(progress.size(), frames.size());
  for (std::size_t i = 0; i < progress.size(); ++i) EXPECT_EQ(progress[i], i + 1);
  expectSameMap(*direct, *built);
}

INSTANTIATE_TEST_SUITE_P(Models, MapBuilderEqualsDirectInsertion,
                         ::testing::Combine(::testing::Values(MapModel::kLogOdds, MapModel::kCount, MapModel::kTsdf),
                                            ::testing::Values(PoseSource::kTruth, PoseSource::kOdometry)),
                         [](const auto& info) {
                           return std::string(toString(std::get<0>(info.param))) +
                                  (std::get<1>(info.param) == PoseSource::kTruth ? "_truth" : "_odometry");
                         });

TEST(MapBuilder, TrajectoryPosesGiveTheDirectMapAndStreamsAddUp) {
  const std::vector<Frame>& frames = officeFrames();
  Trajectory truth;
  for (const Frame& f : frames) truth.push_back({f.time, *f.T_world_robot});
  auto direct = makeMap(MapModel::kLogOdds);
  for (const Frame& f : frames) direct->insert(f.scan, *f.T_world_robot * f.T_robot_laser);
  auto from_traj = makeMap(MapModel::kLogOdds);
  MapBuilder(*from_traj, FramePoses::fromTrajectory(truth, 0.0, "truth")).insert(streamOf(frames));
  expectSameMap(*direct, *from_traj);
  // A builder may insert several streams into one map: the second pass of the same frames adds to it.
  auto twice = makeMap(MapModel::kLogOdds);
  MapBuilder builder(*twice, FramePoses::fromFrames(PoseSource::kTruth));
  EXPECT_EQ(builder.insert(streamOf(frames)), frames.size());
  EXPECT_EQ(builder.insert(streamOf(frames)), frames.size());
  for (const Frame& f : frames) direct->insert(f.scan, *f.T_world_robot * f.T_robot_laser);
  expectSameMap(*direct, *twice);
}

TEST(MapBuilder, FrameWithoutThePoseIsAnErrorNamingTheScanAndSource) {
  std::vector<Frame> frames(officeFrames().begin(), officeFrames().begin() + 20);
  frames[12].T_world_robot.reset();
  auto map = makeMap(MapModel::kCount);
  MapBuilder builder(*map, FramePoses::fromFrames(PoseSource::kTruth, "use --poses"), {.source_name = "office.log"});
  EXPECT_TRUE(throwsError([&] { builder.insert(streamOf(frames)); }, ErrorKind::kBadInput,
                          {"office.log: scan 12 (time ", ") has no truth pose (use --poses)"}));
  // A trajectory error keeps the trajectory's name.
  MapBuilder from_traj(*map, FramePoses::fromTrajectory({{-5.0, SE2()}}, 0.001, "poses.txt"),
                       {.source_name = "office.log"});
  EXPECT_TRUE(throwsError([&] { from_traj.insert(streamOf(frames)); }, ErrorKind::kBadInput,
                          {"poses.txt: timestamp: has no pose within 0.001 s of scan 0 (time "}));
}

TEST(MapBuilder, ScanTheMapRejectsIsNamed) {
  std::vector<Frame> frames(officeFrames().begin(), officeFrames().begin() + 5);
  frames[3].T_world_robot = SE2(1e12, 0, 0);
  frames[3].time = 42.5;
  auto map = makeMap(MapModel::kLogOdds);
  MapBuilder builder(*map, FramePoses::fromFrames(PoseSource::kTruth), {.source_name = "far.log"});
  EXPECT_TRUE(throwsError([&] { builder.insert(streamOf(frames)); }, ErrorKind::kBadInput,
                          {"far.log: scan 3 (time 42.500000) pose: laser pose is absurdly far"}));
  // Over the cell budget at insertion (the second half, on the calling thread).
  MapOptions o;
  o.insert.cell_budget = 1000;
  auto small = makeMap(MapModel::kLogOdds, o);
  MapBuilder tight(*small, FramePoses::fromFrames(PoseSource::kTruth), {.source_name = "big.log"});
  EXPECT_TRUE(throwsError([&] { tight.insert(streamOf(frames)); }, ErrorKind::kBadInput, {"big.log: scan 0 (time "}));
  EXPECT_TRUE(small->bounds().empty());
}

TEST(MapBuilder, StreamErrorsPassThroughAndAnEmptyStreamInsertsNothing) {
  auto map = makeMap(MapModel::kLogOdds);
  MapBuilder builder(*map, FramePoses::fromFrames(), {.source_name = "x.log"});
  int calls = 0;
  EXPECT_TRUE(throwsError(
      [&] {
        builder.insert([&]() -> std::optional<Frame> {
          if (++calls < 3) return officeFrames()[static_cast<std::size_t>(calls)];
          throw badInput("truncated record", ErrorLocation("x.log", 17, "FLASER"));
        });
      },
      ErrorKind::kBadInput, {"x.log:17: FLASER: truncated record"}));
  auto empty = makeMap(MapModel::kLogOdds);
  EXPECT_EQ(MapBuilder(*empty, FramePoses::fromFrames()).insert([] { return std::optional<Frame>(); }), 0u);
  EXPECT_TRUE(empty->bounds().empty());
}

}  // namespace
}  // namespace lidar2d::mapping
