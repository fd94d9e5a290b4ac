// Range tables (poses.txt, angles.txt, ranges.txt; no times): simulator scans written as a table
// read back as the same frames, the layouts users write (commas, blanks, comments, CRLF, gzip), the
// commands on a table, and bad input: one error naming the file, line and field, exit 1, no output.

#include <gtest/gtest.h>

#include <fmt/format.h>

#include <algorithm>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "lidar2d/io/frame_source.hpp"
#include "lidar2d/sim/path.hpp"
#include "lidar2d/sim/simulator.hpp"
#include "lidar2d/sim/worlds.hpp"
#include "support/test_support.hpp"

namespace lidar2d {
namespace {

namespace fs = std::filesystem;
using test::runCli;
using test::TempDir;

// Scans of the office world (with the simulator's noise and lost echoes), the laser at the robot's
// origin as a table's laser is.
std::vector<Frame> officeFrames(std::size_t n) {
  const sim::Scenario s = sim::builtinScenario("office");
  sim::SimulatorOptions o;
  o.laser.beams = 181;
  o.laser.T_robot_laser = SE2();
  o.seed = 7;
  auto path = sim::samplePath(s.waypoints, sim::PathOptions{}, n);
  return sim::simulate(s.world, path, o);
}

struct Table {
  std::string poses, angles, ranges;
};

// The frames as the three files' text; `sep` between numbers.
Table toTable(const std::vector<Frame>& frames, const std::string& sep = " ") {
  Table t;
  const LaserScan& s0 = frames.front().scan;
  for (std::size_t i = 0; i < s0.size(); ++i) t.angles += fmt::format("{}{:.9f}", i ? sep : "", s0.angle(i));
  t.angles += "\n";
  for (const Frame& f : frames) {
    const SE2& T = *f.T_world_robot;
    t.poses += fmt::format("{:.9f}{}{:.9f}{}{:.9f}\n", T.x(), sep, T.y(), sep, T.theta());
    for (std::size_t i = 0; i < f.scan.size(); ++i) t.ranges += fmt::format("{}{:.6f}", i ? sep : "", f.scan.ranges()[i]);
    t.ranges += "\n";
  }
  return t;
}

void writeTable(const fs::path& dir, const Table& t) {
  fs::create_directories(dir);
  test::writeFile(dir / "poses.txt", t.poses);
  test::writeFile(dir / "angles.txt", t.angles);
  test::writeFile(dir / "ranges.txt", t.ranges);
}

std::vector<Frame> readAll(const std::string& path, const io::ReaderOptions& o = {}) {
  auto src = io::openLog(path, o);
  std::vector<Frame> out;
  while (auto f = src->next()) out.push_back(std::move(*f));
  return out;
}

void expectSameFrames(const std::vector<Frame>& expected, const std::vector<Frame>& got) {
  ASSERT_EQ(got.size(), expected.size());
  for (std::size_t k = 0; k < got.size(); ++k) {
    EXPECT_EQ(got[k].index, k);
    EXPECT_DOUBLE_EQ(got[k].time, static_cast<double>(k) / 10.0);  // synthesized at 10 Hz
    ASSERT_TRUE(got[k].T_world_robot);
    EXPECT_TRUE(test::IsNearPose(*expected[k].T_world_robot, *got[k].T_world_robot, 1e-8, 1e-6));
    EXPECT_FALSE(got[k].T_odom_robot);
    const LaserScan& a = expected[k].scan;
    const LaserScan& b = got[k].scan;
    ASSERT_EQ(b.size(), a.size());
    EXPECT_NEAR(b.angleMin(), a.angleMin(), 1e-9);
    EXPECT_NEAR(b.angleIncrement(), a.angleIncrement(), 1e-9);
    for (std::size_t i = 0; i < a.size(); ++i) {
      EXPECT_NEAR(b.ranges()[i], a.ranges()[i], 5e-7) << "scan " << k << " beam " << i;
      EXPECT_EQ(b.isValid(i), a.isValid(i)) << "scan " << k << " beam " << i;
    }
  }
}

TEST(RangeTable, SimulatorScansReadBackFromAFolderAndFromNamedFiles) {
  TempDir tmp;
  const auto frames = officeFrames(40);
  std::size_t lost = 0;
  for (const Frame& f : frames)
    for (double r : f.scan.ranges()) lost += r == 0.0;
  ASSERT_GT(lost, 0u);  // the table carries lost echoes (0), invalid when read back
  writeTable(tmp / "t", toTable(frames));
  EXPECT_EQ(io::detectFormat((tmp / "t").string()), io::LogFormat::kRangeTable);
  auto src = io::openLog((tmp / "t").string());
  EXPECT_EQ(src->format(), io::LogFormat::kRangeTable);
  EXPECT_EQ(src->sizeHint(), std::optional<std::size_t>(40));
  expectSameFrames(frames, readAll((tmp / "t").string()));

  io::ReaderOptions o;
  o.range_table = io::RangeTableFiles{(tmp / "t" / "poses.txt").string(), (tmp / "t" / "angles.txt").string(),
                                      (tmp / "t" / "ranges.txt").string()};
  expectSameFrames(frames, readAll("ignored", o));
  o.range_table->rate_hz = 40;
  EXPECT_DOUBLE_EQ(readAll("ignored", o).back().time, 39.0 / 40.0);
}

TEST(RangeTable, CommasCommentsBlankLinesCrlfAndGzipAreRead) {
  TempDir tmp;
  const auto frames = officeFrames(12);
  Table t = toTable(frames, ", ");
  // A header comment, blank lines, Windows line ends.
  auto crlf = [](std::string s) {
    std::string out;
    for (char c : s) out += c == '\n' ? std::string("\r\n") : std::string(1, c);
    return out;
  };
  t.poses = "# x, y, theta\n\n" + crlf(t.poses);
  t.ranges = "# one scan per line\n" + t.ranges + "\n\n";
  writeTable(tmp / "t", t);
  test::writeGzip(tmp / "t" / "ranges.txt", t.ranges);  // gzip under the plain name
  expectSameFrames(frames, readAll((tmp / "t").string()));
  // Blanks and tabs only.
  Table b = toTable(frames, "\t ");
  writeTable(tmp / "b", b);
  expectSameFrames(frames, readAll((tmp / "b").string()));
}

TEST(RangeTable, CommandsReadATable) {
  TempDir tmp;
  writeTable(tmp / "t", toTable(officeFrames(60)));
  const std::string dir = (tmp / "t").string();
  auto r = runCli({"info", "--json", dir});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto j = nlohmann::json::parse(r.out);
  EXPECT_EQ(j["format"], "range-table");
  EXPECT_EQ(j["scans"], 60);
  EXPECT_EQ(j["beams"], 181);
  EXPECT_NEAR(j["duration_s"].get<double>(), 5.9, 1e-9);
  EXPECT_TRUE(j["has_truth"].get<bool>());
  EXPECT_FALSE(j["has_odometry"].get<bool>());
  EXPECT_NEAR(j["fov_deg"].get<double>(), 270.0 + 1.5, 1e-6);  // 181 beams over 270 degrees, one step each side
  EXPECT_NE(j["warnings"].dump().find("no times"), std::string::npos);

  const std::vector<std::string> files = {"--ranges", (tmp / "t" / "ranges.txt").string(), "--angles",
                                          (tmp / "t" / "angles.txt").string(), "--poses",
                                          (tmp / "t" / "poses.txt").string()};
  auto with = [&](std::vector<std::string> args) {
    args.insert(args.end(), files.begin(), files.end());
    return runCli(args);
  };
  r = with({"map", "-o", (tmp / "m").string(), "-q"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(fs::exists(tmp / "m.pgm"));
  r = runCli({"map", dir, "-o", (tmp / "m2").string(), "-q"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(test::readFile(tmp / "m.pgm"), test::readFile(tmp / "m2.pgm"));  // same map either way
  r = with({"match", "--init", "identity", "-o", (tmp / "pairs.txt").string(), "-q"});
  EXPECT_EQ(r.exit_code, 0) << r.err;
  r = with({"degeneracy", "-o", (tmp / "d.txt").string(), "-q"});
  EXPECT_EQ(r.exit_code, 0) << r.err;
  r = with({"poses", "-o", (tmp / "p.txt").string()});
  EXPECT_EQ(r.exit_code, 0) << r.err;
  // Usage errors: a table and a LOG, half a table, neither.
  EXPECT_EQ(with({"info", dir}).exit_code, 2);
  EXPECT_EQ(runCli({"info", "--ranges", (tmp / "t" / "ranges.txt").string()}).exit_code, 2);
  EXPECT_EQ(runCli({"info"}).exit_code, 2);
}

// One bad table: the file to change, its content, and what the error must say.
struct BadTable {
  const char* name;
  const char* file;     // poses.txt, angles.txt or ranges.txt; "" = remove ranges.txt
  std::string content;  // replaces the file (a {} is replaced by a valid ranges line)
  std::vector<std::string> says;
};

class RangeTableBadInput : public ::testing::TestWithParam<BadTable> {};

TEST_P(RangeTableBadInput, OneClearErrorExitOneNoOutput) {
  const BadTable& c = GetParam();
  TempDir tmp;
  const auto frames = officeFrames(5);
  Table t = toTable(frames);
  const std::string good_line = t.ranges.substr(0, t.ranges.find('\n'));
  writeTable(tmp / "t", t);
  const fs::path file = tmp / "t" / c.file;
  if (std::string(c.file).empty()) {
    fs::remove(tmp / "t" / "ranges.txt");
  } else {
    std::string content = c.content;
    for (auto at = content.find("{}"); at != std::string::npos; at = content.find("{}")) content.replace(at, 2, good_line);
    if (c.name == std::string("GzipTruncated")) {
      test::writeGzip(file, t.ranges);
      std::string z = test::readFile(file);
      test::writeFile(file, z.substr(0, z.size() / 2));
    } else {
      test::writeFile(file, content);
    }
  }
  const auto r = runCli({"map", (tmp / "t").string(), "-o", (tmp / "out" / "m").string()});
  EXPECT_EQ(r.exit_code, 1) << r.err;
  EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
  for (const auto& s : c.says) EXPECT_NE(r.err.find(s), std::string::npos) << "'" << s << "' not in: " << r.err;
  EXPECT_TRUE(r.out.empty());
  EXPECT_FALSE(fs::exists(tmp / "out" / "m.pgm"));
  EXPECT_FALSE(fs::exists(tmp / "out" / "m.yaml"));
}

std::string repeat(const std::string& s, std::size_t n) {
  std::string out;
  for (std::size_t i = 0; i < n; ++i) out += s;
  return out;
}

INSTANTIATE_TEST_SUITE_P(
    Cases, RangeTableBadInput,
    ::testing::Values(
        BadTable{"NanRange", "ranges.txt", "{}\n1 nan 2\n", {"ranges.txt:2: range 2: must be a finite range >= 0"}},
        BadTable{"InfRange", "ranges.txt", "{}\n{}\n" + repeat("1 ", 180) + "inf\n", {"ranges.txt:3: range 181"}},
        BadTable{"NegativeRange", "ranges.txt", "-1 " + repeat("1 ", 180) + "\n", {"ranges.txt:1: range 1", "got -1"}},
        BadTable{"NotANumber", "ranges.txt", "{}\n1 2 x3\n", {"ranges.txt:2: range 3: 'x3' is not a number"}},
        BadTable{"EmptyFieldBetweenCommas", "ranges.txt", "1,,2\n", {"ranges.txt:1: range 2: empty field"}},
        BadTable{"TruncatedLine", "ranges.txt", "{}\n{}\n1 2 3", {"ranges.txt:3", "3 ranges, but", "181 angles"}},
        BadTable{"MoreScansThanPoses", "poses.txt", "0 0 0\n1 0 0\n", {"poses.txt", "holds 2 poses", "more scans"}},
        BadTable{"MorePosesThanScans", "ranges.txt", "{}\n", {"ranges.txt", "holds 1 scans", "more poses"}},
        BadTable{"PoseWithTwoValues", "poses.txt", "0 0 0\n1 2\n", {"poses.txt:2", "expected 3 values"}},
        BadTable{"NanPose", "poses.txt", "0 0 0\n1 nan 0\n", {"poses.txt:2: y: must be finite"}},
        BadTable{"EmptyRanges", "ranges.txt", "", {"ranges.txt", "holds no scans"}},
        BadTable{"OnlyComments", "ranges.txt", "# nothing\n\n", {"ranges.txt", "holds no scans"}},
        BadTable{"EmptyAngles", "angles.txt", "\n", {"angles.txt", "holds no angles"}},
        BadTable{"UnevenAngles", "angles.txt", "0 0.1 0.25 0.3\n", {"angles.txt:1: angle 3", "evenly spaced"}},
        BadTable{"DecreasingAngles", "angles.txt", "1 0.5 0\n", {"angles.txt:1", "must increase"}},
        BadTable{"TwoAngleLines", "angles.txt", "0 1\n0 1\n", {"angles.txt:2", "one line of beam angles"}},
        BadTable{"InfiniteAngle", "angles.txt", "0 inf\n", {"angles.txt:1: angle 2"}},
        BadTable{"Bzip2", "ranges.txt", "BZh91AY&SY", {"ranges.txt", "bzip2-compressed"}},
        BadTable{"GzipTruncated", "ranges.txt", "", {"ranges.txt", "gzip"}},
        BadTable{"Binary", "poses.txt", std::string("\x01\x02\x03\x00\xff", 5), {"poses.txt:1", "not a text file"}},
        BadTable{"TooManyValues", "ranges.txt", repeat("1 ", (1u << 20) + 1) + "\n", {"ranges.txt:1", "more than 1048576"}},
        BadTable{"MissingRangesFile", "", "", {"ranges.txt is missing"}}),
    [](const auto& info) { return std::string(info.param.name); });

}  // namespace
}  // namespace lidar2d
