// `lidar2d degeneracy` end to end: the simulated corridor (flagged in its middle, along its axis),
// snapshots, the real Infinite Corridor log, and bad input / usage errors through the CLI.

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <numbers>
#include <sstream>
#include <string>
#include <vector>

#include "support/test_support.hpp"

namespace lidar2d {
namespace {

namespace fs = std::filesystem;
using test::runCli;
using test::TempDir;

struct Line {
  double t, score, direction;
  int degenerate;
};

std::vector<Line> readOutput(const fs::path& path, std::size_t* comments = nullptr) {
  std::ifstream in(path);
  std::vector<Line> out;
  std::string s;
  std::size_t c = 0;
  while (std::getline(in, s)) {
    if (s.empty() || s[0] == '#') {
      ++c;
      continue;
    }
    std::istringstream ss(s);
    Line l{};
    std::string score, dir;
    ss >> l.t >> l.degenerate >> score >> dir;
    EXPECT_FALSE(ss.fail()) << s;
    l.score = std::stod(score);
    l.direction = std::stod(dir);
    out.push_back(l);
  }
  if (comments) *comments = c;
  return out;
}

TEST(CliDegeneracy, SimulatedCorridorIsFlaggedAlongItsAxis) {
  TempDir tmp;
  const std::string log = (tmp / "corridor.log").string();
  // 500 scans: the west room, then the corridor up to about x = 28 m (the robot drives along +x there).
  auto r = runCli({"simulate", "--world", "corridor", "-o", log, "--scans", "500", "--beams", "361", "--seed", "2"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const fs::path out = tmp / "deg.txt";
  const fs::path snaps = tmp / "snaps";
  r = runCli({"degeneracy", log, "-o", out.string(), "--snapshots", snaps.string(), "--snapshot-every", "100",
              "--max-snapshots", "3"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  std::size_t comments = 0;
  const auto lines = readOutput(out, &comments);
  ASSERT_EQ(lines.size(), 500u);
  EXPECT_GE(comments, 3u);  // the header explains the columns
  // The last 150 scans are in the corridor's featureless middle (x ~ 16..28 m).
  for (std::size_t i = 350; i < 500; ++i) {
    EXPECT_EQ(lines[i].degenerate, 1) << i;
    EXPECT_LT(lines[i].score, 0.01) << i;
    EXPECT_LT(std::abs(lines[i].direction), 3.0 * std::numbers::pi / 180.0) << i;  // the robot faces along the corridor
  }
  // The first scans are in the furnished west room.
  for (std::size_t i = 0; i < 20; ++i) EXPECT_EQ(lines[i].degenerate, 0) << i;
  for (std::size_t i = 1; i < lines.size(); ++i) EXPECT_GT(lines[i].t, lines[i - 1].t);
  std::size_t pngs = 0;
  for (const auto& e : fs::directory_iterator(snaps)) pngs += e.path().extension() == ".png";
  EXPECT_EQ(pngs, 3u);
  EXPECT_TRUE(fs::exists(snaps / "scan_000000.png"));
  EXPECT_TRUE(fs::exists(snaps / "scan_000100.png"));
}

TEST(CliDegeneracy, SnapshotsOfFlaggedScansOnly) {
  TempDir tmp;
  const std::string log = (tmp / "corridor.log").string();
  ASSERT_EQ(runCli({"simulate", "--world", "corridor", "-o", log, "--scans", "400", "--beams", "181"}).exit_code, 0);
  const fs::path out = tmp / "deg.txt";
  const auto r = runCli({"degeneracy", log, "-o", out.string(), "--snapshots", (tmp / "s").string(),
                         "--snapshot-degenerate", "--snapshot-every", "1000", "-q"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(r.err.empty()) << r.err;
  const auto lines = readOutput(out);
  std::size_t first = lines.size();
  for (std::size_t i = 0; i < lines.size() && first == lines.size(); ++i)
    if (lines[i].degenerate) first = i;
  ASSERT_LT(first, lines.size());
  std::vector<fs::path> files;
  for (const auto& e : fs::directory_iterator(tmp / "s")) files.push_back(e.path().filename());
  ASSERT_EQ(files.size(), 1u);
  char name[32];
  std::snprintf(name, sizeof(name), "scan_%06zu.png", first);
  EXPECT_EQ(files[0].string(), name);
}

TEST(CliDegeneracy, CannotDecideScansAreFlaggedWithNanScore) {
  TempDir tmp;
  // Three scans: a corridor, then all beams invalid, then only five valid beams.
  std::ostringstream s;
  auto flaser = [&s](const std::vector<double>& r, double t) {
    s << "FLASER " << r.size();
    for (double v : r) s << " " << v;
    s << " 0 0 0 0 0 0 " << t << " host " << t << "\n";
  };
  std::vector<double> corridor(181), invalid(181, 0.0), few(181, 0.0);
  for (int i = 0; i < 181; ++i) {
    const double a = (-90.0 + i) * std::numbers::pi / 180.0;
    corridor[i] = std::min(50.0, 1.0 / std::max(std::abs(std::sin(a)), 1e-9));
  }
  for (int i = 80; i < 85; ++i) few[i] = 2.0;
  flaser(corridor, 1.0);
  flaser(invalid, 1.1);
  flaser(few, 1.2);
  const fs::path log = tmp / "x.log";
  test::writeFile(log, s.str());
  const fs::path out = tmp / "deg.txt";
  const auto r = runCli({"degeneracy", log.string(), "-o", out.string()});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto lines = readOutput(out);
  ASSERT_EQ(lines.size(), 3u);
  EXPECT_EQ(lines[0].degenerate, 1);
  EXPECT_FALSE(std::isnan(lines[0].score));
  for (std::size_t i : {1u, 2u}) {
    EXPECT_EQ(lines[i].degenerate, 1) << i;  // never a false "fine"
    EXPECT_TRUE(std::isnan(lines[i].score)) << i;
    EXPECT_TRUE(std::isnan(lines[i].direction)) << i;
  }
  EXPECT_NE(r.err.find("2 cannot decide"), std::string::npos) << r.err;
}

TEST(CliDegeneracy, InfiniteCorridorLog) {
  LIDAR2D_REQUIRE_DATA("corrected/infinite-corridor.log.gz");
  TempDir tmp;
  const fs::path out = tmp / "ic.txt";
  const auto r =
      runCli({"degeneracy", test::dataFile("corrected/infinite-corridor.log.gz").string(), "-o", out.string()});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto lines = readOutput(out);
  ASSERT_EQ(lines.size(), 1941u);
  std::size_t flagged = 0, undecided = 0;
  for (const auto& l : lines) {
    flagged += l.degenerate;
    undecided += std::isnan(l.score);
  }
  // A long corridor: some scans are flagged, most are not (doors, pillars, crossings, the ends).
  EXPECT_GT(flagged, 10u);
  EXPECT_LT(flagged, lines.size() / 2);
  EXPECT_EQ(undecided, 0u);
  EXPECT_NE(r.err.find("repeat the previous scan's timestamp"), std::string::npos) << r.err;
}

TEST(CliDegeneracy, BadInput) {
  TempDir tmp;
  const std::string out = (tmp / "out.txt").string();
  auto r = runCli({"degeneracy", (tmp / "missing.log").string(), "-o", out});
  EXPECT_EQ(r.exit_code, 1) << r.err;
  EXPECT_NE(r.err.find("lidar2d: error:"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("missing.log"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(out));

  const fs::path bad = tmp / "bad.log";
  test::writeFile(bad, "FLASER 3 1.0 1.0\n");  // truncated: fewer ranges than announced
  r = runCli({"degeneracy", bad.string(), "-o", out});
  EXPECT_EQ(r.exit_code, 1) << r.err;
  EXPECT_NE(r.err.find("bad.log"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(out));

  const fs::path empty = tmp / "empty.log";
  test::writeFile(empty, "# nothing\n");
  r = runCli({"degeneracy", empty.string(), "-o", out});
  EXPECT_EQ(r.exit_code, 1) << r.err;
  EXPECT_FALSE(fs::exists(out));

  // Usage errors: exit 2.
  EXPECT_EQ(runCli({"degeneracy", bad.string()}).exit_code, 2);  // no -o
  EXPECT_EQ(runCli({"degeneracy", bad.string(), "-o", out, "--snapshot-every", "0"}).exit_code, 2);
  // An option out of its domain: one error line, exit 1.
  const std::string log = (tmp / "ok.log").string();
  ASSERT_EQ(runCli({"simulate", "--world", "office", "-o", log, "--scans", "3", "--beams", "91"}).exit_code, 0);
  r = runCli({"degeneracy", log, "-o", out, "--eps", "-1"});
  EXPECT_EQ(r.exit_code, 1) << r.err;
  EXPECT_NE(r.err.find("cluster_eps_m"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(out));
  // An unwritable output.
  r = runCli({"degeneracy", log, "-o", (tmp / "ok.log" / "x.txt").string()});  // a folder under a regular file
  EXPECT_EQ(r.exit_code, 1) << r.err;
}

}  // namespace
}  // namespace lidar2d
