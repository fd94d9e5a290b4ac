// What a new user meets in the first hour: a mistyped command, --help, output folders that do not
// exist yet, and `info` on a log whose clock is broken.

#include <gtest/gtest.h>

#include <algorithm>
#include <cctype>
#include <filesystem>
#include <cstdlib>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "apps/lidar2d/progress.hpp"
#include "support/test_support.hpp"

namespace lidar2d {
namespace {

namespace fs = std::filesystem;
using test::CliResult;
using test::runCli;
using test::TempDir;

std::size_t lines(const std::string& s) { return static_cast<std::size_t>(std::count(s.begin(), s.end(), '\n')); }

// A FLASER line of 5 beams of 2 m at time t (pose triples at the origin).
std::string flaser(const std::string& t) { return "FLASER 5 2 2 2 2 2 0 0 0 0 0 0 " + t + " host " + t + "\n"; }

TEST(FirstHour, UnknownCommandNamesItAndTheNearestOne) {
  const CliResult r = runCli({"slma", "log.txt"});
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_EQ(lines(r.err), 1u) << r.err;
  EXPECT_NE(r.err.find("unknown command 'slma'"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("did you mean 'slam'?"), std::string::npos) << r.err;
  const CliResult far = runCli({"qqqqqqq"});
  EXPECT_EQ(far.exit_code, 2);
  EXPECT_NE(far.err.find("unknown command 'qqqqqqq'"), std::string::npos) << far.err;
  EXPECT_EQ(far.err.find("did you mean"), std::string::npos) << far.err;
  // Known commands and options still work.
  EXPECT_EQ(runCli({"--version"}).exit_code, 0);
  EXPECT_EQ(runCli({"map", "--help"}).exit_code, 0);
}

TEST(FirstHour, HelpShowsChoicesInWordsWithTheirDefault) {
  for (const std::string cmd : {"info", "simulate", "perturb", "eval", "map", "poses", "match", "slam", "degeneracy",
                                "localize-index", "localize"}) {
    const CliResult r = runCli({cmd, "--help"});
    ASSERT_EQ(r.exit_code, 0) << cmd;
    for (const std::string internal : {"ENUM", "BOOLEAN", "->", "value in {"})
      EXPECT_EQ(r.out.find(internal), std::string::npos) << cmd << " --help shows '" << internal << "':\n" << r.out;
    // CLI11's parser type and check names, as whole words.
    std::string word;
    for (const char c : r.out + " ") {
      if (std::isalnum(static_cast<unsigned char>(c)) || c == '_') {
        word += c;
        continue;
      }
      for (const char* type : {"TEXT", "FLOAT", "DOUBLE", "INT", "UINT", "POSITIVE", "NONNEGATIVE"})
        EXPECT_NE(word, type) << cmd << " --help shows the parser's type name " << type << ":\n" << r.out;
      word.clear();
    }
  }
  // Values in words, with their bounds and defaults.
  const std::string perturb = runCli({"perturb", "--help"}).out;
  EXPECT_NE(perturb.find("--time-jitter NUMBER >= 0=0"), std::string::npos) << perturb;
  EXPECT_NE(perturb.find("--time-bursts INTEGER in 1..1099511627776=1"), std::string::npos) << perturb;
  EXPECT_NE(perturb.find("-o,--output PATH REQUIRED"), std::string::npos) << perturb;
  EXPECT_NE(perturb.find("--odom-noise SX,SY,STH"), std::string::npos) << perturb;
  EXPECT_NE(runCli({"map", "--help"}).out.find("--model logodds|count|tsdf=logodds"), std::string::npos);
  EXPECT_NE(runCli({"slam", "--help"}).out.find("--pose-frame robot|laser=robot"), std::string::npos);
  EXPECT_NE(runCli({"match", "--help"}).out.find("--method p2p|p2l|lf|corr=p2l"), std::string::npos);
  EXPECT_NE(runCli({"map", "--help"}).out.find("--carmen-poses auto|truth|odometry=auto"), std::string::npos);
  // The words still parse, case-insensitively, and a wrong one is a usage error naming the option.
  TempDir tmp;
  const CliResult bad = runCli({"map", "x.log", "--model", "voxel", "-o", (tmp / "m").string()});
  EXPECT_EQ(bad.exit_code, 2);
  EXPECT_NE(bad.err.find("--model"), std::string::npos) << bad.err;
}

class OutputPaths : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new TempDir();
    ASSERT_EQ(runCli({"simulate", "--world", "corridor", "--scans", "20", "--beams", "91", "--seed", "2", "-o",
                      (dir_->path() / "c.log").string()})
                  .exit_code,
              0);
    // The same log with a malformed last line: a command that reads it fails at the end of its work.
    std::string log = test::readFile(dir_->path() / "c.log");
    test::writeFile(dir_->path() / "broken-at-end.log", log + "ROBOTLASER1 0 -2.3 5.8 1.1 30 0 0 5 1 abc\n");
  }
  static void TearDownTestSuite() { delete dir_; }
  static std::string file(const std::string& name) { return (dir_->path() / name).string(); }
  // Arguments of each command that writes a file, with the output path `out`.
  static std::vector<std::vector<std::string>> commands(const std::string& log, const std::string& out) {
    return {{"map", log, "-o", out},        {"match", log, "-o", out},   {"degeneracy", log, "-o", out},
            {"poses", log, "-o", out},      {"perturb", log, "--odom-noise", "0.01,0.01,0.01", "-o", out},
            {"eval", log, "--truth", log, "-o", out}};
  }
  static TempDir* dir_;
};
TempDir* OutputPaths::dir_ = nullptr;

TEST_F(OutputPaths, MissingOutputFoldersAreCreated) {
  int k = 0;
  for (auto args : commands(file("c.log"), "")) {
    const fs::path out = dir_->path() / ("new" + std::to_string(k++)) / "deeper" / "out";
    std::replace(args.begin(), args.end(), std::string(), out.string());
    const CliResult r = runCli(args);
    EXPECT_EQ(r.exit_code, 0) << args[0] << ": " << r.err;
    EXPECT_TRUE(fs::is_directory(out.parent_path())) << args[0];
    bool wrote = false;
    for (const auto& e : fs::directory_iterator(out.parent_path())) wrote |= e.path().filename().string().rfind("out", 0) == 0;
    EXPECT_TRUE(wrote) << args[0] << " wrote nothing into " << out.parent_path();
  }
}

TEST_F(OutputPaths, UnusableOutputFailsBeforeTheWork) {
  // A folder under a regular file cannot be created. The log is broken at its end, so an error
  // about the output (not the log's last line) shows that the output was checked first.
  test::writeFile(dir_->path() / "plain-file", "x\n");
  const std::string out = file("plain-file") + "/sub/out";
  for (const auto& args : commands(file("broken-at-end.log"), out)) {
    const CliResult r = runCli(args);
    EXPECT_EQ(r.exit_code, 1) << args[0];
    EXPECT_EQ(lines(r.err), 1u) << args[0] << ": " << r.err;
    EXPECT_NE(r.err.find("plain-file/sub"), std::string::npos) << args[0] << ": " << r.err;
    EXPECT_EQ(r.err.find("broken-at-end.log"), std::string::npos) << args[0] << " read the log first: " << r.err;
    EXPECT_TRUE(r.out.empty()) << args[0];
  }
  // A command that fails after creating its output folders removes them again.
  for (const auto& args : commands(file("broken-at-end.log"), file("fresh/deeper/out"))) {
    if (args[0] == "eval" || args[0] == "perturb") continue;  // they fail before reading the last line
    const CliResult r = runCli(args);
    EXPECT_EQ(r.exit_code, 1) << args[0] << ": " << r.err;
    EXPECT_NE(r.err.find("broken-at-end.log"), std::string::npos) << args[0] << ": " << r.err;
    EXPECT_FALSE(fs::exists(file("fresh"))) << args[0] << " left the folder it created";
  }
  const CliResult slam = runCli({"slam", file("broken-at-end.log"), "-o", out, "-q"});
  EXPECT_EQ(slam.exit_code, 1);
  EXPECT_NE(slam.err.find("plain-file/sub"), std::string::npos) << slam.err;
  EXPECT_EQ(slam.err.find("broken-at-end.log"), std::string::npos) << slam.err;
}

// The progress line of `args` run on a pseudo-terminal (util-linux `script`), or nullopt without it.
std::optional<std::string> onTerminal(const std::vector<std::string>& args, const fs::path& capture) {
  if (!fs::exists("/usr/bin/script")) return std::nullopt;
  std::string cmd = lidar2d::test::cliPath();
  for (const auto& a : args) cmd += " '" + a + "'";
  const std::string shell = "/usr/bin/script -qec \"" + cmd + "\" /dev/null > '" + capture.string() + "' 2>&1";
  if (std::system(shell.c_str()) != 0) return std::nullopt;
  return test::readFile(capture);
}

TEST_F(OutputPaths, ProgressIsShownOnATerminalOnly) {
  const std::string log = file("c.log");
  for (const std::vector<std::string>& args : {std::vector<std::string>{"map", log, "-o", file("p-map")},
                                              {"match", log, "-o", file("p-match.txt")},
                                              {"degeneracy", log, "-o", file("p-deg.txt")}}) {
    const CliResult r = runCli(args);
    ASSERT_EQ(r.exit_code, 0) << r.err;
    EXPECT_EQ(r.err.find('\r'), std::string::npos) << args[0] << " drew progress into a pipe: " << r.err;
  }
  const auto map = onTerminal({"map", log, "-o", file("t-map")}, dir_->path() / "t-map.tty");
  if (!map) GTEST_SKIP() << "util-linux 'script' is not available to run on a terminal";
  EXPECT_NE(map->find("mapping "), std::string::npos) << *map;
  EXPECT_NE(map->find(" scans/s"), std::string::npos) << *map;
}

TEST(FirstHour, ProgressShowsTimeLeftWhenTheLogKnowsItsLength) {
  LIDAR2D_REQUIRE_DATA("bags/laser_scan_matcher_demo.bag");
  TempDir tmp;
  const auto out = onTerminal({"match", test::dataFile("bags/laser_scan_matcher_demo.bag").string(), "--init",
                               "identity", "-o", (tmp / "p.txt").string()},
                              tmp / "tty");
  if (!out) GTEST_SKIP() << "util-linux 'script' is not available to run on a terminal";
  EXPECT_NE(out->find("/359 pairs"), std::string::npos) << *out;
  EXPECT_NE(out->find(" pairs/s"), std::string::npos) << *out;
}

TEST(FirstHour, ProgressTextHasRateAndTimeLeft) {
  EXPECT_EQ(cli::progressText("mapping", 300, 1200, 10.0, "scans"),
            "mapping [#######.......................]  25% 300/1200 scans, 30.0 scans/s, 0:30 left ");
  EXPECT_EQ(cli::progressText("mapping", 300, std::nullopt, 10.0, "scans"), "mapping 300 scans, 30.0 scans/s ");
  EXPECT_EQ(cli::progressText("matching", 0, 10, 0.0, "pairs"),
            "matching [..............................]   0% 0/10 pairs ");
  EXPECT_EQ(cli::progressText("indexing", 10, 4000, 1.0, "positions"),
            "indexing [..............................]   0% 10/4000 positions, 10.0 positions/s, 6:39 left ");
}

nlohmann::json infoJson(const fs::path& log) {
  const CliResult r = runCli({"info", "--json", log.string()});
  EXPECT_EQ(r.exit_code, 0) << r.err;
  return nlohmann::json::parse(r.out);
}

TEST(FirstHour, InfoDurationIsUnknownWhenTheClockIsBroken) {
  TempDir tmp;
  // Negative times written through an unsigned 32-bit number, as in MIT's infinite-corridor log.
  test::writeFile(tmp / "wrapped.log", flaser("-0.45") + flaser("-0.91") + flaser("4.29497e+09") + flaser("4.29497e+09"));
  nlohmann::json j = infoJson(tmp / "wrapped.log");
  EXPECT_TRUE(j["duration_s"].is_null()) << j.dump(2);
  EXPECT_NE(j["duration_unknown"].get<std::string>().find("jumps from -0.91 to 4294970000 at scan 2"), std::string::npos)
      << j.dump(2);
  EXPECT_NE(j["warnings"].dump().find("2 scans have timestamps near 2^32 s"), std::string::npos) << j.dump(2);
  const CliResult text = runCli({"info", (tmp / "wrapped.log").string()});
  EXPECT_NE(text.out.find("duration:    unknown: the timestamp jumps"), std::string::npos) << text.out;

  test::writeFile(tmp / "frozen.log", flaser("0") + flaser("0") + flaser("0"));
  j = infoJson(tmp / "frozen.log");
  EXPECT_TRUE(j["duration_s"].is_null());
  EXPECT_NE(j["duration_unknown"].get<std::string>().find("all 3 scans have the timestamp 0"), std::string::npos);

  // A sound clock, even one that steps back a little (as intel's does), has a duration.
  test::writeFile(tmp / "ok.log", flaser("10") + flaser("10.5") + flaser("10.4") + flaser("12.5"));
  j = infoJson(tmp / "ok.log");
  EXPECT_DOUBLE_EQ(j["duration_s"].get<double>(), 2.5);
  EXPECT_EQ(j["duration_unknown"].get<std::string>(), "");
}

TEST(FirstHour, InfoSaysWhenTheReadingsContradictTheDeclaredRangeMax) {
  TempDir tmp;
  // A declared range max of 10 m, a laser that reads walls at 12-15 m and 51.15 for no return (as
  // edmonton's log): the readings prove the declared value wrong, so the range max becomes 99% of
  // the no-return code and info says so; --laser-range-max 10 keeps the declared one, and then
  // info warns that the 12-15 m returns are dropped (the no-return code not counted).
  auto scan = [](const std::string& t) {
    return "FLASER 5 2 12.5 15 51.15 51.15 0 0 0 0 0 0 " + t + " host " + t + "\n";
  };
  const std::string scans = scan("1") + scan("2") + scan("3");
  test::writeFile(tmp / "short.log", "PARAM robot_front_laser_max 10 nohost 0\n" + scans);
  nlohmann::json j = infoJson(tmp / "short.log");
  EXPECT_EQ(j["beams_beyond_range_max"].get<int>(), 0) << j.dump(2);
  EXPECT_NEAR(j["range_max_m"].get<double>(), 50.64, 0.01) << j.dump(2);
  EXPECT_NE(j["warnings"].dump().find("the log's range max (10.00 m) is below what its laser measured: 40.0% of "
                                      "the beams of its first 3 scans read beyond it"),
            std::string::npos)
      << j.dump(2);
  CliResult r = runCli({"info", "--json", (tmp / "short.log").string(), "--laser-range-max", "10"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  j = nlohmann::json::parse(r.out);
  EXPECT_EQ(j["beams_beyond_range_max"].get<int>(), 6) << j.dump(2);
  EXPECT_NE(j["warnings"].dump().find("40.0% of the beams read beyond the range max (10.00 m"), std::string::npos)
      << j.dump(2);
  EXPECT_EQ(j["warnings"].dump().find("below what its laser measured"), std::string::npos) << j.dump(2);
  // --laser-range-max 50 reads them: below it returns, the no-return code above it none.
  r = runCli({"info", "--json", (tmp / "short.log").string(), "--laser-range-max", "50"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  j = nlohmann::json::parse(r.out);
  EXPECT_EQ(j["beams_beyond_range_max"].get<int>(), 0) << j.dump(2);
  EXPECT_EQ(j["warnings"].dump().find("beyond"), std::string::npos) << j.dump(2);
  r = runCli({"info", (tmp / "short.log").string(), "--laser-range-max", "-1"});
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.err.find("--laser-range-max: must be a finite number > 0"), std::string::npos) << r.err;
  r = runCli({"info", (tmp / "short.log").string(), "--laser-range-max", "2000"});
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("laser range max must be in (0, 1000] m"), std::string::npos) << r.err;
  EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
  // With the default range max (80 m) they are returns, and 51.15 too.
  test::writeFile(tmp / "long.log", scans);
  j = infoJson(tmp / "long.log");
  EXPECT_EQ(j["beams_beyond_range_max"].get<int>(), 0) << j.dump(2);
  EXPECT_EQ(j["warnings"].dump().find("beyond"), std::string::npos) << j.dump(2);
}

// The commands that process a log say what info would: a user who runs slam first still learns
// that the log's declared range max drops real returns, or that its timestamps repeat.
TEST(FirstHour, CommandsThatReadALogWarnAsInfoDoes) {
  TempDir tmp;
  auto scan = [](const std::string& t) {
    return "FLASER 5 2 12.5 15 51.15 51.15 0 0 0 0 0 0 " + t + " host " + t + "\n";
  };
  const std::string log = (tmp / "short.log").string();
  test::writeFile(log, "PARAM robot_front_laser_max 10 nohost 0\n" + scan("1") + scan("2") + scan("2"));
  const std::string beyond = "lidar2d: warning: " + log + ": the log's range max (10.00 m) is below what its laser measured";
  const std::string repeats = "lidar2d: warning: " + log + ": timestamps repeat 1 times";  // the CARMEN reader's words
  const std::vector<std::vector<std::string>> commands = {
      {"map", log, "-o", (tmp / "m").string(), "-q"},
      {"slam", log, "-o", (tmp / "s").string(), "-q"},
      {"match", log, "-o", (tmp / "p.txt").string(), "-q"},
  };
  for (const auto& args : commands) {
    const CliResult r = runCli(args);
    ASSERT_EQ(r.exit_code, 0) << args[0] << ": " << r.err;
    EXPECT_NE(r.err.find(beyond), std::string::npos) << args[0] << ": " << r.err;
    EXPECT_NE(r.err.find(repeats), std::string::npos) << args[0] << ": " << r.err;
  }
  const nlohmann::json summary = nlohmann::json::parse(test::readFile(tmp / "s" / "summary.json"));
  EXPECT_NE(summary["log_warnings"].dump().find("the log's range max (10.00 m) is below"), std::string::npos)
      << summary["log_warnings"].dump();
  const std::string report = test::readFile(tmp / "s" / "report.html");
  const std::size_t list = report.find("<ul id=\"log-warnings\">");
  EXPECT_NE(list, std::string::npos);
  EXPECT_NE(report.find("<li>the log's range max (10.00 m) is below", list), std::string::npos) << report.substr(list, 400);
  // Read with a range max that takes the returns: no warning about them.
  const CliResult r = runCli({"map", log, "-o", (tmp / "m2").string(), "-q", "--laser-range-max", "50"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(r.err.find("range max"), std::string::npos) << r.err;
}

TEST(FirstHour, InfoOnTheInfiniteCorridorSaysWhyItHasNoDuration) {
  LIDAR2D_REQUIRE_DATA("corrected/infinite-corridor.log.gz");
  const nlohmann::json j = infoJson(test::dataFile("corrected/infinite-corridor.log.gz"));
  EXPECT_EQ(j["scans"].get<int>(), 1941);
  EXPECT_TRUE(j["duration_s"].is_null()) << j.dump(2);
  EXPECT_NE(j["warnings"].dump().find("1937 scans have timestamps near 2^32 s"), std::string::npos) << j.dump(2);
}

}  // namespace
}  // namespace lidar2d
