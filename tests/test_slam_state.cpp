// The SLAM state file: a saved run loads back to the same estimates and the same bytes; a resumed
// session starting elsewhere in the mapped area joins the saved graph, one in an unmapped place
// stays a reported fragment; truncated, corrupted, foreign and future-version files are refused
// with one clear error, and so are files whose checksum holds but whose contents do not (a damaged
// payload compressed again: what tools/fuzz-cli.py --modes state writes).

#include <gtest/gtest.h>
#include <zlib.h>

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <limits>
#include <memory>
#include <ostream>
#include <string>
#include <utility>
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

// ---- damaged contents with a valid checksum (what tools/fuzz-cli.py --modes state found) ----

/// The bytes of a state file around the compressed payload `packed`, whose header states
/// `payload_length`: the compressed length and CRC-32 are `packed`'s own, as a tool that damaged
/// the payload and wrote it again would give.
std::string fileAround(const std::string& packed, std::uint64_t payload_length) {
  std::string out(kStateMagic);
  auto put = [&](const auto& v) { out.append(reinterpret_cast<const char*>(&v), sizeof(v)); };
  put(kStateFormatVersion);
  put(std::uint64_t{4});
  out += "test";
  put(payload_length);
  put(static_cast<std::uint32_t>(
      crc32(0L, reinterpret_cast<const Bytef*>(packed.data()), static_cast<uInt>(packed.size()))));
  put(static_cast<std::uint64_t>(packed.size()));
  return out + packed;
}

std::string deflated(const std::string& payload) {
  uLongf size = compressBound(static_cast<uLong>(payload.size()));
  std::string packed(size, '\0');
  EXPECT_EQ(compress(reinterpret_cast<Bytef*>(packed.data()), &size, reinterpret_cast<const Bytef*>(payload.data()),
                     static_cast<uLong>(payload.size())),
            Z_OK);
  packed.resize(size);
  return packed;
}

/// The payload of a state file encodeState wrote, decompressed.
std::string payloadOf(const std::string& bytes) {
  std::uint64_t writer = 0, length = 0, packed = 0;
  std::memcpy(&writer, bytes.data() + 12, 8);
  const std::size_t at = 20 + writer;
  std::memcpy(&length, bytes.data() + at, 8);
  std::memcpy(&packed, bytes.data() + at + 12, 8);
  std::string payload(length, '\0');
  uLongf size = static_cast<uLongf>(length);
  EXPECT_EQ(uncompress(reinterpret_cast<Bytef*>(payload.data()), &size,
                       reinterpret_cast<const Bytef*>(bytes.data() + at + 20), static_cast<uLong>(packed)),
            Z_OK);
  return payload;
}

/// The field decodeState names when it refuses `bytes` (bad input, in file "state.l2d").
std::string refusedField(const std::string& bytes) {
  try {
    decodeState(bytes, "state.l2d");
  } catch (const Error& e) {
    EXPECT_EQ(e.kind(), ErrorKind::kBadInput) << e.what();
    EXPECT_EQ(e.where().file, "state.l2d") << e.what();
    return e.where().field;
  }
  ADD_FAILURE() << "no error";
  return "";
}

TEST(SlamState, APayloadLengthItsCompressedBytesCannotHoldIsRefusedBeforeItIsAllocated) {
  // Deflate expands at most 1032-fold: 9 compressed bytes never hold a megabyte (the reader used to
  // allocate whatever the header stated, up to 8 GiB, before finding out).
  const std::string packed = deflated("x");
  ASSERT_LT(packed.size() * 1032, 1'000'000u);
  for (const std::uint64_t length : {std::uint64_t{1'000'000}, std::uint64_t{100'000'000}})
    EXPECT_EQ(refusedField(fileAround(packed, length)), "payload_length") << length;
}

TEST(SlamState, BytesAfterTheCompressedStreamAreRefused) {
  // The zlib stream ends before the stated compressed length: those bytes were ignored.
  const std::string payload = payloadOf(savedBytes());
  EXPECT_NO_THROW(decodeState(fileAround(deflated(payload), payload.size()), "state.l2d"));
  EXPECT_EQ(refusedField(fileAround(deflated(payload) + "junk", payload.size())), "payload");
}

/// A state damaged through the library's own types (then written with a valid checksum), and the
/// field the reader must name.
struct Damage {
  const char* name;
  void (*apply)(State&);
  const char* field;
};
void PrintTo(const Damage& d, std::ostream* os) { *os << d.name; }

std::size_t firstAccepted(const State& s, Constraint::Kind kind) {
  for (std::size_t k = 0; k < s.constraints.size(); ++k)
    if (s.constraints[k].accepted && s.constraints[k].kind == kind) return k;
  ADD_FAILURE() << "no such constraint";
  return 0;
}
/// The index of constraint k's edge (edges are the accepted constraints', in order).
std::size_t edgeOf(const State& s, std::size_t k) {
  return static_cast<std::size_t>(std::count_if(s.constraints.begin(),
                                                s.constraints.begin() + static_cast<std::ptrdiff_t>(k),
                                                [](const Constraint& c) { return c.accepted; }));
}
std::size_t firstUnmatchedScanOfANode(const State& s) {
  for (std::size_t k = 0; k < s.scans.size(); ++k)
    if (!s.scans[k].is_node) return k;
  ADD_FAILURE() << "every scan is a node";
  return 0;
}

class DamagedState : public ::testing::TestWithParam<Damage> {};

TEST_P(DamagedState, IsRefusedNamingTheField) {
  State s = decodeState(savedBytes(), "mem");
  ASSERT_GE(s.submaps.size(), 3u);
  GetParam().apply(s);
  EXPECT_EQ(refusedField(encodeState(s)), GetParam().field);
}

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr double kInf = std::numeric_limits<double>::infinity();

// Each of these decoded before the reader checked it; resumed, several crashed the pipeline (an
// edge walk past the first edge, the node before node 0) or failed deep in it without naming the file.
INSTANTIATE_TEST_SUITE_P(
    FoundByFuzzing, DamagedState,
    ::testing::Values(
        // Edges: as the pose graph takes them, and the accepted constraints' in the same order.
        Damage{"EdgeFromANodeToItself", [](State& s) { s.edges[3].to = s.edges[3].from; }, "edge.to"},
        Damage{"NegativeHuberScale", [](State& s) { s.edges[0].huber_scale = -1.0; }, "edge.huber_scale"},
        Damage{"EdgeMissing", [](State& s) { s.edges.pop_back(); }, "edges"},
        Damage{"AcceptedConstraintWithoutItsEdge",
               [](State& s) { s.constraints[firstAccepted(s, Constraint::Kind::kSequential)].accepted = false; },
               "edges"},
        Damage{"EdgesSwapped", [](State& s) { std::swap(s.edges[0], s.edges.back()); }, "edges"},
        // The odometry across a lost track: the constraint and edge it names, from the node before.
        Damage{"RestartOdometryAtNodeZero",
               [](State& s) {
                 s.restart_odometry = State::RestartOdometry{0, 0, 0};
               },
               "restart_odometry"},
        Damage{"RestartOdometryNamingAnotherEdge",
               [](State& s) {
                 const std::size_t k = firstAccepted(s, Constraint::Kind::kOdometry);
                 s.restart_odometry = State::RestartOdometry{edgeOf(s, k) + 1, k, s.constraints[k].to};
               },
               "restart_odometry"},
        Damage{"RestartOdometryNotAnOdometryConstraint",
               [](State& s) {
                 const std::size_t k = firstAccepted(s, Constraint::Kind::kSequential);
                 s.restart_odometry = State::RestartOdometry{edgeOf(s, k), k, s.constraints[k].to};
               },
               "restart_odometry"},
        // Node indices of the back end.
        Damage{"LastLoopNodeOutOfRange", [](State& s) { s.last_loop_node = s.nodes.size(); }, "last_loop_node"},
        Damage{"UntiedSinceOutOfRange", [](State& s) { s.untied_since = s.nodes.size() + 7; }, "untied_since"},
        Damage{"RestartsOutOfOrder",
               [](State& s) {
                 s.restarts = {5, 3};
               },
               "restart"},
        // The submaps partition the nodes; a node's scan is the one scan that says it is the node.
        Damage{"NodeTwiceInASubmap", [](State& s) { s.submaps[1].nodes.push_back(s.submaps[1].nodes.back()); },
               "submap.node"},
        Damage{"NodeNamingAnotherSubmap", [](State& s) { s.nodes[s.submaps[1].nodes[1]].node.submap = 0; },
               "submap.node"},
        Damage{"NodeInNoSubmap", [](State& s) { s.submaps[1].nodes.pop_back(); }, "submap.nodes"},
        Damage{"ScanClaimingAnotherScansNode", [](State& s) { s.scans[firstUnmatchedScanOfANode(s)].is_node = true; },
               "scan.is_node"},
        // Times, directions and durations: finite, as the writer writes them.
        Damage{"NodeTimeNaN", [](State& s) { s.nodes[2].node.time = kNaN; }, "node.time"},
        Damage{"DegenerateDirectionInf", [](State& s) { s.nodes[2].node.degenerate_dir_rad = kInf; },
               "node.degenerate_dir_rad"},
        Damage{"ScanTimeInf", [](State& s) { s.scans[5].time = -kInf; }, "scan.time"},
        Damage{"ScanSecondsNaN", [](State& s) { s.scans[5].seconds = kNaN; }, "scan.seconds"},
        Damage{"EventTimeNaN",
               [](State& s) {
                 s.events.push_back({0, kNaN, "x"});
               },
               "event.time"},
        Damage{"StatsSecondsInf", [](State& s) { s.stats.total_seconds = kInf; }, "stats"},
        // Positions beyond 10^7 m: the grids built from them overflow.
        Damage{"NodeFarAway", [](State& s) { s.nodes[4].node.T_world_robot = SE2(2e7, 0.0, 0.0); },
               "node.T_world_robot"},
        Damage{"WorldFrameFarAway", [](State& s) { s.T_world_local = SE2(0.0, -1e300, 0.0); }, "T_world_local"},
        Damage{"LaserMountedFarAway", [](State& s) { s.nodes[0].T_robot_laser = SE2(1e9, 0.0, 0.0); },
               "node.T_robot_laser"},
        Damage{"EdgeSpanningTooFar", [](State& s) { s.edges[2].T_from_to = SE2(0.0, 1e8, 0.0); }, "edge.T_from_to"}),
    [](const auto& info) { return std::string(info.param.name); });

// These the reader refused before the fuzzer ran (kept here as the fuzzer's checks of them).
INSTANTIATE_TEST_SUITE_P(
    AlwaysRefused, DamagedState,
    ::testing::Values(
        Damage{"NodeNamingNoSubmap", [](State& s) { s.nodes[3].node.submap = s.submaps.size(); }, "node.submap"},
        Damage{"EdgeNamingNoNode", [](State& s) { s.edges[1].to = s.nodes.size(); }, "edge.to"},
        Damage{"ConstraintKind7", [](State& s) { s.constraints[0].kind = static_cast<Constraint::Kind>(7); },
               "constraint.kind"},
        Damage{"PoseNaN", [](State& s) { s.nodes[1].node.T_local_robot = SE2(kNaN, 0.0, 0.0); }, "node.T_local_robot"},
        Damage{"SubmapAnchorNotItsFirstNode", [](State& s) { s.submaps[2].anchor = s.submaps[2].nodes[1]; },
               "submap.nodes"}),
    [](const auto& info) { return std::string(info.param.name); });

TEST(SlamState, ConsistentOptionalFieldsAndFarButPlausibleFramesAreRead) {
  // What the checks above must still let through: the odometry across a lost track as SLAM
  // records it, a fragment, a latest closure, and an odometry frame as far out as UTM's.
  State s = decodeState(savedBytes(), "mem");
  const std::size_t k = firstAccepted(s, Constraint::Kind::kOdometry);
  s.restart_odometry = State::RestartOdometry{edgeOf(s, k), k, s.constraints[k].to};
  s.untied_since = s.constraints[k].to;
  s.last_loop_node = s.nodes.size() - 1;
  s.restarts = {s.constraints[k].to};
  s.nodes[3].T_odom_robot = SE2(6.5e5, 9.9e6, 1.0);
  const State loaded = decodeState(encodeState(s), "mem");
  ASSERT_TRUE(loaded.restart_odometry);
  EXPECT_EQ(loaded.restart_odometry->edge, edgeOf(s, k));
  EXPECT_EQ(loaded.untied_since, s.untied_since);
}

}  // namespace
}  // namespace lidar2d::slam
