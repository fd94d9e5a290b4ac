// The SLAM state file: a saved run loads back to the same estimates and the same bytes; a resumed
// session starting elsewhere in the mapped area joins the saved graph, one in an unmapped place
// stays a reported fragment; truncated, corrupted, foreign and future-version files are refused
// with one clear error.

#include <gtest/gtest.h>

#include <cmath>
#include <cstddef>
#include <cstring>
#include <memory>
#include <string>
#include <vector>

#include "lidar2d/core/error.hpp"
#include "lidar2d/mapping/export.hpp"
#include "lidar2d/sim/simulator.hpp"
#include "lidar2d/sim/worlds.hpp"
#include "lidar2d/slam/slam.hpp"
#include "lidar2d/slam/state_file.hpp"

namespace lidar2d::slam {
namespace {

/// The office route of the simulator (seed 5, a 181-beam laser: quick), as test_slam uses it.
const std::vector<Frame>& office() {
  static const std::vector<Frame> frames = [] {
    const sim::Scenario sc = sim::builtinScenario("office");
    sim::SimulatorOptions so;
    so.seed = 5;
    so.laser.beams = 181;
    return sim::simulate(sc.world, sim::samplePath(sc.waypoints, sim::PathOptions{}, 0), so);
  }();
  return frames;
}

/// Frames [from, to) of the office route as a log of their own: indices from 0, time going on
/// after `after`, odometry in another frame (a new log's odometry starts anywhere).
std::vector<Frame> secondLog(std::size_t from, std::size_t to, double after) {
  const SE2 T_other_odom(-3.0, 7.0, 2.0);
  std::vector<Frame> out;
  for (std::size_t i = from; i < to; ++i) {
    Frame f = office()[i];
    f.index = i - from;
    f.time = after + 1.0 + (f.time - office()[from].time);
    f.T_odom_robot = T_other_odom * *f.T_odom_robot;
    out.push_back(std::move(f));
  }
  return out;
}

std::vector<Frame> firstFrames(std::size_t n) { return {office().begin(), office().begin() + static_cast<std::ptrdiff_t>(n)}; }

std::unique_ptr<Slam> run(std::unique_ptr<Slam> slam, const std::vector<Frame>& frames) {
  for (const Frame& f : frames) slam->add(f);
  slam->finish();
  return slam;
}

/// The first 600 scans mapped and saved (the fixture of most tests).
const std::string& savedBytes() {
  static const std::string bytes = encodeState(run(std::make_unique<Slam>(SlamOptions{}, "first"), firstFrames(600))->state());
  return bytes;
}

std::string eventText(const Slam& slam) {
  std::string all;
  for (const auto& ev : slam.events()) all += ev.what + "\n";
  return all;
}

TEST(SlamState, SavedLoadedAndSavedAgainIsTheSameBytesAndEstimates) {
  auto slam = run(std::make_unique<Slam>(SlamOptions{}, "first"), firstFrames(600));
  const State saved = slam->state();
  const std::string bytes = encodeState(saved);
  EXPECT_TRUE(bytes == encodeState(saved));  // deterministic
  const State loaded = decodeState(bytes, "mem");
  ASSERT_EQ(loaded.nodes.size(), slam->nodes().size());
  ASSERT_EQ(loaded.sessions.size(), 1u);
  EXPECT_EQ(loaded.sessions[0].name, "first");
  // Loaded into a Slam (node points, lines, submaps and descriptor indexes rebuilt) and saved again:
  // nothing changed.
  Slam again(loaded, "second");
  EXPECT_TRUE(encodeState(again.state()) == bytes);
  const auto a = slam->trajectory();
  const auto b = again.trajectory();
  ASSERT_EQ(a.size(), b.size());
  for (std::size_t i = 0; i < a.size(); ++i) {
    EXPECT_EQ(a[i].T_world_robot.x(), b[i].T_world_robot.x()) << i;
    EXPECT_EQ(a[i].T_world_robot.y(), b[i].T_world_robot.y()) << i;
    EXPECT_EQ(a[i].T_world_robot.theta(), b[i].T_world_robot.theta()) << i;
    EXPECT_EQ(a[i].frame_index, b[i].frame_index);
    EXPECT_EQ(b[i].session, 0u);
  }
  EXPECT_EQ(again.stats().loop_accepted, slam->stats().loop_accepted);
  EXPECT_EQ(again.constraints().size(), slam->constraints().size());
  // The saved options are the run's.
  EXPECT_EQ(loaded.options.submap_nodes, SlamOptions{}.submap_nodes);
}

TEST(SlamState, ASessionStartingInTheMappedAreaJoinsTheSavedGraph) {
  // The second log drives frames 250-550 again (a stretch the first one mapped), its odometry in
  // another frame, its first pose unknown: it must be relocalized in the saved submaps and end in
  // the saved map's frame (the simulator's truth frame).
  const std::vector<Frame> second = secondLog(250, 550, office()[599].time);
  auto slam = run(std::make_unique<Slam>(decodeState(savedBytes(), "mem"), "second"), second);
  const std::string all = eventText(*slam);
  EXPECT_NE(all.find("session 2 ('second') starts"), std::string::npos) << all;
  EXPECT_NE(all.find("relocalized"), std::string::npos) << all;
  EXPECT_GE(slam->stats().relocalizations, 1u);
  EXPECT_EQ(slam->stats().fragments, 1u) << all;
  const auto est = slam->trajectory();
  ASSERT_EQ(est.size(), 600u + second.size());
  double sum2 = 0.0, worst = 0.0;
  for (std::size_t i = 0; i < est.size(); ++i) {
    const bool first = i < 600;
    EXPECT_EQ(est[i].session, first ? 0u : 1u);
    const Frame& f = first ? office()[i] : second[i - 600];
    const double d = (est[i].T_world_robot.translation() - f.T_world_robot->translation()).norm();
    sum2 += d * d;
    worst = std::max(worst, d);
  }
  EXPECT_LT(std::sqrt(sum2 / static_cast<double>(est.size())), 0.05);
  EXPECT_LT(worst, 0.15);
  // Both sessions are in the state saved after it, which resumes again.
  const State both = slam->state();
  ASSERT_EQ(both.sessions.size(), 2u);
  EXPECT_EQ(both.sessions[1].name, "second");
  EXPECT_EQ(both.sessions[1].first_scan, 600u);
  EXPECT_EQ(decodeState(encodeState(both), "mem").scans.size(), est.size());
}

TEST(SlamState, ASessionInAnUnmappedPlaceStaysAReportedFragment) {
  // The saved map covers frames 0-250; the second log drives frames 1050-1250, in another room.
  const std::string bytes = encodeState(run(std::make_unique<Slam>(SlamOptions{}), firstFrames(250))->state());
  auto slam = run(std::make_unique<Slam>(decodeState(bytes, "mem"), "elsewhere"),
                  secondLog(1050, 1250, office()[249].time));
  const std::string all = eventText(*slam);
  EXPECT_EQ(slam->stats().relocalizations, 0u) << all;
  EXPECT_EQ(slam->stats().fragments, 2u) << all;
  EXPECT_NE(all.find("fragment from node"), std::string::npos) << all;
  for (const auto& e : slam->trajectory()) EXPECT_TRUE(e.T_world_robot.isFinite());
  // Resumed again: a third session over that room joins the second one's fragment (still not the
  // first's); each fragment beyond the first is reported once, not once per run that saw it.
  auto third = run(std::make_unique<Slam>(slam->state(), "third"), secondLog(1000, 1300, office()[1249].time + 30.0));
  const std::string again = eventText(*third);
  std::size_t reported = 0;
  for (const auto& ev : third->events()) reported += ev.what.starts_with("fragment from node") ? 1 : 0;
  EXPECT_EQ(reported + 1, third->stats().fragments) << again;
  EXPECT_EQ(third->stats().fragments, 2u) << again;
}

TEST(SlamState, TheSavedMapIsTheNodeScansAtTheirPoses) {
  const State s = decodeState(savedBytes(), "mem");
  auto all = mapping::makeMap(mapping::MapModel::kLogOdds, {});
  insertNodeScans(s, *all);
  const OccupancyImage image = mapping::toOccupancyImage(*all);
  EXPECT_GT(image.width(), 100);
  EXPECT_GT(image.height(), 100);
  auto none = mapping::makeMap(mapping::MapModel::kLogOdds, {});
  insertNodeScans(s, *none, 0);  // the sessions before the first: nothing
  EXPECT_THROW(mapping::toOccupancyImage(*none), Error);
}

/// decodeState's error for `bytes`: its kind and message (fails the test when it does not throw).
std::pair<ErrorKind, std::string> errorOf(const std::string& bytes) {
  try {
    decodeState(bytes, "state.l2d");
  } catch (const Error& e) {
    EXPECT_EQ(e.where().file, "state.l2d");
    return {e.kind(), e.what()};
  }
  ADD_FAILURE() << "no error";
  return {ErrorKind::kIo, ""};
}

TEST(SlamState, BadFilesAreRefusedWithOneClearError) {
  const std::string& good = savedBytes();
  // Truncated anywhere: in the magic, the header, the payload, one byte short.
  for (const std::size_t keep : {std::size_t{0}, std::size_t{5}, std::size_t{14}, std::size_t{30}, good.size() / 2,
                                 good.size() - 1}) {
    const auto [kind, what] = errorOf(good.substr(0, keep));
    EXPECT_EQ(kind, ErrorKind::kBadInput) << keep;
    EXPECT_TRUE(what.find("truncated") != std::string::npos || what.find("bad magic") != std::string::npos)
        << keep << ": " << what;
  }
  {
    std::string flipped = good;
    flipped[flipped.size() / 2] = static_cast<char>(flipped[flipped.size() / 2] ^ 0x10);
    const auto [kind, what] = errorOf(flipped);
    EXPECT_EQ(kind, ErrorKind::kBadInput);
    EXPECT_NE(what.find("corrupt"), std::string::npos) << what;
  }
  {
    std::string foreign = good;
    foreign[0] = 'X';
    EXPECT_NE(errorOf(foreign).second.find("not a lidar2d SLAM state file"), std::string::npos);
    EXPECT_NE(errorOf("P5\n10 10\n255\n").second.find("not a lidar2d SLAM state file"), std::string::npos);
  }
  {
    std::string future = good;
    const std::uint32_t v = kStateFormatVersion + 1;
    std::memcpy(future.data() + 8, &v, sizeof(v));
    const auto [kind, what] = errorOf(future);
    EXPECT_EQ(kind, ErrorKind::kUnsupported);
    EXPECT_NE(what.find("version " + std::to_string(v) + " is not supported"), std::string::npos) << what;
  }
  {
    std::string trailing = good + "x";
    EXPECT_NE(errorOf(trailing).second.find("after its payload"), std::string::npos);
  }
  EXPECT_THROW(readStateFile("/nonexistent/state.l2d"), Error);
}

}  // namespace
}  // namespace lidar2d::slam
