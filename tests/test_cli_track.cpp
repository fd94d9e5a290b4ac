// lidar2d track end to end: output format (one line per scan, `t x y theta status score`, `nan`
// pose when lost), the JSON summary with --eval, a log without odometry, a database of another map
// and bad input (exit 1, one line, no output file).

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include "support/table_rows.hpp"
#include "support/test_support.hpp"

namespace lidar2d {
namespace {

namespace fs = std::filesystem;
using test::runCli;

class CliTrack : public ::testing::Test {
 protected:
  // One office map and one run (made once per process): the map from a run's truth poses, the
  // tracked run another seed's noisy odometry.
  static void SetUpTestSuite() {
    dir_ = new test::TempDir();
    auto r = runCli({"simulate", "--world", "office", "--scans", "200", "--seed", "5", "-o", path("office.log")});
    ASSERT_EQ(r.exit_code, 0) << r.err;
    r = runCli({"simulate", "--world", "office", "--scans", "60", "--seed", "9", "-o", path("run.log")});
    ASSERT_EQ(r.exit_code, 0) << r.err;
    r = runCli({"map", path("office.log"), "-o", path("office"), "-q"});
    ASSERT_EQ(r.exit_code, 0) << r.err;
  }
  static void TearDownTestSuite() { delete dir_; }
  static std::string path(const std::string& name) { return (*dir_ / name).string(); }
  static std::vector<std::vector<std::string>> rows(const std::string& file) { return test::tableRows(file); }
  static void expectFormat(const std::string& file, std::size_t scans) {
    const auto lines = rows(file);
    ASSERT_EQ(lines.size(), scans);
    const std::set<std::string> statuses{"global", "tracking", "lost"};
    for (const auto& f : lines) {
      ASSERT_EQ(f.size(), 6u);
      EXPECT_TRUE(statuses.count(f[4])) << f[4];
      if (f[4] == "lost") {
        EXPECT_EQ(f[1], "nan");
        EXPECT_EQ(f[5], "0");
      } else {
        EXPECT_TRUE(std::isfinite(std::stod(f[1])));
        EXPECT_GE(std::stod(f[5]), 0.0);
      }
    }
  }
  static test::TempDir* dir_;
};
test::TempDir* CliTrack::dir_ = nullptr;

// Scans read mirrored (an upright laser given as upside down, `--laser-mount 0,0,0,flipped`) are
// never placed in the open world's map (its rooms are not their own mirror images, as the office's
// are); the command says that their mirror images would be, and how to fix it.
TEST_F(CliTrack, ScansReadMirroredAreLostAndToldSo) {
  auto r = runCli({"simulate", "--world", "open", "--scans", "200", "--seed", "5", "-o", path("open.log")});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  r = runCli({"simulate", "--world", "open", "--scans", "30", "--seed", "9", "-o", path("open-run.log")});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  r = runCli({"map", path("open.log"), "-o", path("open"), "-q"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  r = runCli({"track", path("open.yaml"), path("open-run.log"), "--laser-mount", "0,0,0,flipped", "-o",
              path("mirrored.txt"), "--json", path("mirrored.json"), "-q"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  auto j = nlohmann::json::parse(test::readFile(path("mirrored.json")));
  EXPECT_GE(j["status"]["lost"].get<double>(), 0.9) << j.dump();
  EXPECT_TRUE(j["mirror_check"]["mirrored"].get<bool>()) << j.dump();
  EXPECT_NE(r.err.find("mirror images of each other"), std::string::npos) << r.err;
  // Read as they are, they track, and nothing is said about mirrors.
  r = runCli({"track", path("open.yaml"), path("open-run.log"), "-o", path("upright.txt"), "--json",
              path("upright.json"), "-q"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  j = nlohmann::json::parse(test::readFile(path("upright.json")));
  EXPECT_GE(j["status"]["tracking"].get<double>(), 0.9) << j.dump();
  EXPECT_FALSE(j.contains("mirror_check"));
  EXPECT_EQ(r.err.find("mirror"), std::string::npos) << r.err;
}

TEST_F(CliTrack, WritesOneLinePerScanAndTheSummary) {
  auto r = runCli({"track", path("office.yaml"), path("run.log"), "-o", path("t.txt"), "--json", path("t.json"),
                   "--eval"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  ASSERT_NO_FATAL_FAILURE(expectFormat(path("t.txt"), 60));
  const auto j = nlohmann::json::parse(test::readFile(path("t.json")));
  EXPECT_EQ(j["scans"], 60);
  const double sum = j["status"]["global"].get<double>() + j["status"]["tracking"].get<double>() +
                     j["status"]["lost"].get<double>();
  EXPECT_NEAR(sum, 1.0, 1e-9);
  EXPECT_GE(j["status"]["tracking"].get<double>(), 0.9);
  EXPECT_EQ(j["eval"]["wrong_while_tracking"], 0);
  EXPECT_GE(j["eval"]["tracking_within_share"].get<double>(), 0.9);
  EXPECT_TRUE(j["time_to_first_fix_s"].is_number());
  EXPECT_TRUE(j["scans_to_first_fix"].is_number());
  EXPECT_TRUE(j["tracked_scan_ms"]["median"].is_number());
  // global_fix_ms: the queries that placed a scan (status global); global_query_ms: every query.
  const auto fixes = j["global_fix_ms"]["count"].get<std::size_t>();
  EXPECT_EQ(fixes, j["status_counts"]["global"].get<std::size_t>());
  EXPECT_GE(j["global_query_ms"]["count"].get<std::size_t>(), fixes);
  EXPECT_TRUE(j["global_fix_ms"]["median"].is_number());
  EXPECT_TRUE(j.contains("relocalizations"));
  EXPECT_EQ(j["odometry_frozen_scans"], 0);  // the simulator's odometry never reads one pose twice
}

TEST_F(CliTrack, TimesGoingBackwardsBeforeTheFirstFixGiveNoTimeToIt) {
  // The run's first three scans see nothing (every beam at the range limit: lost) and are stamped
  // 100 s later than the rest, as logs with broken clocks are: the first fix is then "earlier"
  // than the first scan. The summary must not print a negative time, only the scans before it.
  std::ofstream out(path("backwards.log"));
  int scan = 0;
  for (auto f : rows(path("run.log"))) {
    if (f[0] == "ROBOTLASER1") {
      if (scan < 3)
        for (int i = 0; i < std::stoi(f[8]); ++i) f[9 + static_cast<std::size_t>(i)] = f[5];  // range max
      ++scan;
    }
    if (scan <= 3 && (f[0] == "ROBOTLASER1" || f[0] == "ODOM" || f[0] == "TRUEPOS")) {
      f[f.size() - 3] = std::to_string(std::stod(f[f.size() - 3]) + 100.0);
      f[f.size() - 1] = std::to_string(std::stod(f[f.size() - 1]) + 100.0);
    }
    for (std::size_t i = 0; i < f.size(); ++i) out << (i ? " " : "") << f[i];
    out << "\n";
  }
  out.close();
  ASSERT_EQ(scan, 60);
  auto r = runCli({"track", path("office.yaml"), path("backwards.log"), "-o", path("backwards.txt"), "--json",
                   path("backwards.json"), "-q"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto j = nlohmann::json::parse(test::readFile(path("backwards.json")));
  EXPECT_EQ(j["status_counts"]["lost"].get<int>(), 3);
  EXPECT_TRUE(j["time_to_first_fix_s"].is_null()) << j["time_to_first_fix_s"];
  EXPECT_EQ(j["scans_to_first_fix"].get<int>(), 3);
  EXPECT_NE(r.err.find("timestamps repeat or go backwards"), std::string::npos) << r.err;
  // The log's own warnings, as every command that reads a log gives them (docs/file-formats.md).
  EXPECT_NE(r.err.find("lidar2d: warning: " + path("backwards.log") + ": timestamps"), std::string::npos) << r.err;
  EXPECT_NE(j["log_warnings"].dump().find("go backwards 1 times"), std::string::npos) << j["log_warnings"];
  r = runCli(
      {"localize", path("office.yaml"), path("backwards.log"), "-o", path("l.txt"), "--json", path("l.json"), "-q"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto l = nlohmann::json::parse(test::readFile(path("l.json")));
  EXPECT_NE(l["log_warnings"].dump().find("go backwards 1 times"), std::string::npos) << l["log_warnings"];
}

TEST_F(CliTrack, WithoutOdometryAndWithADatabase) {
  auto r = runCli({"localize-index", path("office.yaml"), "-o", path("office.db"), "-q"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  r = runCli({"track", path("office.yaml"), path("run.log"), "--db", path("office.db"), "--no-odometry", "-o",
              path("n.txt"), "--json", path("n.json"), "--eval", "-q"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  ASSERT_NO_FATAL_FAILURE(expectFormat(path("n.txt"), 60));
  const auto j = nlohmann::json::parse(test::readFile(path("n.json")));
  EXPECT_EQ(j["eval"]["wrong_while_tracking"], 0);
  EXPECT_GE(j["status"]["tracking"].get<double>(), 0.8);
}

TEST_F(CliTrack, BadInputIsOneLineAndExitOne) {
  // A YAML whose image is missing.
  test::writeFile(path("noimage.yaml"), "image: missing.pgm\nresolution: 0.05\norigin: [0, 0, 0]\n");
  auto r = runCli({"track", path("noimage.yaml"), path("run.log"), "-o", path("a.txt")});
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("lidar2d: error:"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(path("a.txt")));
  // A map without free space.
  test::writeFile(path("full.pgm"), "P5\n10 10\n255\n" + std::string(100, '\0'));
  test::writeFile(path("full.yaml"), "image: full.pgm\nresolution: 0.05\norigin: [0, 0, 0]\n");
  r = runCli({"track", path("full.yaml"), path("run.log"), "-o", path("b.txt")});
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("free"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("full.yaml"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(path("b.txt")));
  // Not a database.
  test::writeFile(path("junk.db"), "hello");
  r = runCli({"track", path("office.yaml"), path("run.log"), "--db", path("junk.db"), "-o", path("c.txt")});
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("junk.db"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(path("c.txt")));
  // A truncated log: the error names the log; no output.
  const std::string log = test::readFile(path("run.log"));
  test::writeFile(path("cut.log"), log.substr(0, log.size() / 2) + "FLASER 3 1.0 nan");
  r = runCli({"track", path("office.yaml"), path("cut.log"), "-o", path("d.txt"), "-q"});
  EXPECT_EQ(r.exit_code, 1) << r.err;
  EXPECT_NE(r.err.find("cut.log"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(path("d.txt")));
  // --eval on a log without truth.
  test::writeFile(path("notruth.log"), "");
  r = runCli({"track", path("office.yaml"), path("notruth.log"), "-o", path("e.txt"), "-q"});
  EXPECT_EQ(r.exit_code, 1) << r.err;
  EXPECT_FALSE(fs::exists(path("e.txt")));
}

}  // namespace
}  // namespace lidar2d
