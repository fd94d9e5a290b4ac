// lidar2d slam: outputs, accuracy through the CLI, config and bad input, the report in headless
// Chromium, and a real raw log (skipped without the data).

#include <gtest/gtest.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>

#include "lidar2d/io/map_file.hpp"
#include "lidar2d/io/trajectory.hpp"
#include "lidar2d/slam/slam.hpp"
#include "support/test_support.hpp"

namespace lidar2d::test {
namespace {

namespace fs = std::filesystem;

/// A small simulated office log shared by the tests of this file.
class CliSlam : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new TempDir();
    const auto r = runCli({"simulate", "--world", "office", "--beams", "181", "--scans", "400", "--seed", "3", "-o",
                           (dir_->path() / "office.log").string()});
    ASSERT_EQ(r.exit_code, 0) << r.err;
    const auto s = runCli({"slam", (dir_->path() / "office.log").string(), "-o", (dir_->path() / "run").string()});
    ASSERT_EQ(s.exit_code, 0) << s.err;
    slam_out_ = new std::string(s.out);
  }
  static void TearDownTestSuite() {
    delete dir_;
    delete slam_out_;
  }
  static fs::path log() { return dir_->path() / "office.log"; }
  static fs::path run() { return dir_->path() / "run"; }
  static TempDir* dir_;
  static std::string* slam_out_;
};
TempDir* CliSlam::dir_ = nullptr;
std::string* CliSlam::slam_out_ = nullptr;

TEST_F(CliSlam, WritesEveryOutput) {
  for (const char* f : {"trajectory.txt", "map.pgm", "map.yaml", "map.png", "graph.txt", "state.l2d", "report.html",
                        "summary.json"}) {
    EXPECT_TRUE(fs::is_regular_file(run() / f)) << f;
    EXPECT_NE(slam_out_->find(f), std::string::npos) << "stdout lists " << f;
  }
  // The trajectory has every scan, the map loads as a map_server map.
  EXPECT_EQ(io::readTrajectory((run() / "trajectory.txt").string()).size(), 400u);
  const auto map = io::readMap((run() / "map.yaml").string());
  EXPECT_GT(map.map.width(), 100);
  const auto summary = nlohmann::json::parse(test::readFile(run() / "summary.json"));
  EXPECT_EQ(summary["scans"], 400);
  EXPECT_GT(summary["nodes"].get<int>(), 10);
  // The simulator's odometry reads distances 0.5% long (sim::OdometryNoise's default scale_bias): the scans
  // measure 1 / 1.005 of them.
  EXPECT_NEAR(summary["odometry_scale"].get<double>(), 1.0 / 1.005, 0.003);
  EXPECT_GE(summary["odometry_scale_evidence_m"].get<double>(), slam::kOdometryScaleMinEvidenceM);
  EXPECT_NE(test::readFile(run() / "report.html").find("m per metre of odometry"), std::string::npos);
  // Nothing moves in the simulated office but the robot: no return is left out as a moving object.
  EXPECT_EQ(summary["moving_points"], 0);
  EXPECT_EQ(summary["scans_with_moving_points"], 0);
  EXPECT_NE(test::readFile(run() / "report.html").find("moving objects left out"), std::string::npos);
  // The loop closures' cycles: the simulator's odometry errs more per step than its matches, so the
  // odometry keeps its links' weights.
  EXPECT_GT(summary["loop_cycles"].get<int>(), 0);
  EXPECT_GT(summary["cycle_odometry_deg"].get<double>(), summary["cycle_front_end_deg"].get<double>());
  EXPECT_GT(summary["cycle_odometry_m"].get<double>(), 0.0);
  EXPECT_GT(summary["cycle_front_end_m"].get<double>(), 0.0);
  EXPECT_FALSE(summary["odometry_weighted_by_cycles"].get<bool>());
  EXPECT_NE(test::readFile(run() / "report.html").find("the odometry links kept their own weights"), std::string::npos);
  // The graph file lists nodes and constraints.
  const std::string graph = test::readFile(run() / "graph.txt");
  EXPECT_NE(graph.find("\nNODE 0 "), std::string::npos);
  EXPECT_NE(graph.find("\nEDGE sequential 0 1 "), std::string::npos);
}

TEST_F(CliSlam, IsAccurateAgainstTheTruth) {
  const auto r = runCli({"eval", (run() / "trajectory.txt").string(), "--truth", log().string()});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto j = nlohmann::json::parse(r.out);
  EXPECT_LT(j["ate_rmse_m"].get<double>(), 0.05);
  // The odometry of the same log is far worse.
  const auto o = runCli({"eval", log().string(), "--truth", log().string(), "--estimate-from", "odometry"});
  ASSERT_EQ(o.exit_code, 0) << o.err;
  EXPECT_GT(nlohmann::json::parse(o.out)["ate_rmse_m"].get<double>(), 2 * j["ate_rmse_m"].get<double>());
}

TEST_F(CliSlam, ReportIsSelfContained) {
  const std::string html = test::readFile(run() / "report.html");
  EXPECT_NE(html.find("data:image/png;base64,"), std::string::npos);
  EXPECT_NE(html.find("id=\"trajectory\""), std::string::npos);
  EXPECT_NE(html.find("id=\"time-plot\""), std::string::npos);
  EXPECT_EQ(html.find("http://"), html.find("http://www.w3.org/2000/svg"));  // no external resources
  EXPECT_EQ(html.find("https://"), std::string::npos);
}

TEST_F(CliSlam, ReportRendersInHeadlessChromium) {
  const char* chromium = "/usr/bin/chromium";
  if (!fs::exists(chromium)) GTEST_SKIP() << "chromium is not installed (tools/install-deps.sh installs it)";
  TempDir profile;
  const fs::path dom = profile.path() / "dom.html";
  const fs::path shot = profile.path() / "shot.png";
  const std::string flags = "--headless --no-sandbox --disable-gpu --disable-quic --no-first-run "
                            "--disable-background-networking --disable-component-update --disable-sync "
                            "--user-data-dir=" + (profile.path() / "p").string();
  const std::string url = "file://" + fs::absolute(run() / "report.html").string();
  ASSERT_EQ(std::system((std::string(chromium) + " " + flags + " --dump-dom " + url + " > " + dom.string() +
                         " 2>/dev/null").c_str()),
            0);
  const std::string out = test::readFile(dom);
  // The browser parsed the page: the map image, the trajectory and the summary table are in its DOM.
  EXPECT_NE(out.find("id=\"map\""), std::string::npos);
  EXPECT_NE(out.find("<polyline id=\"trajectory\""), std::string::npos);
  EXPECT_NE(out.find("id=\"summary\""), std::string::npos);
  ASSERT_EQ(std::system((std::string(chromium) + " " + flags + " --window-size=1200,900 --screenshot=" + shot.string() +
                         " " + url + " > /dev/null 2>&1").c_str()),
            0);
  EXPECT_GT(fs::file_size(shot), 10000u);  // a rendered page, not a blank one
}

TEST_F(CliSlam, ConfigFileOverridesDefaultsAndRejectsMistakes) {
  TempDir t;
  writeFile(t.path() / "ok.yaml", "submap_nodes: 20\nloop_angular_window_deg: 20\nuse_odometry: false\n");
  auto r = runCli({"slam", log().string(), "-o", (t.path() / "a").string(), "--config", (t.path() / "ok.yaml").string(), "-q"});
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(nlohmann::json::parse(test::readFile(t.path() / "a" / "summary.json"))["used_odometry"], false);

  const auto used = nlohmann::json::parse(test::readFile(t.path() / "a" / "summary.json"))["options"];
  EXPECT_EQ(used["submap_nodes"], 20);
  EXPECT_EQ(used["loop_angular_window_deg"], 20.0);
  EXPECT_EQ(used["use_odometry"], false);
  EXPECT_EQ(used["loop_min_score"], 0.55);  // a default

  writeFile(t.path() / "bad.yaml", "submap_nodes: 20\nsubmap_size: 3\n");
  r = runCli({"slam", log().string(), "-o", (t.path() / "b").string(), "--config", (t.path() / "bad.yaml").string()});
  EXPECT_EQ(r.exit_code, 1);
  // One line naming the file, line and key.
  EXPECT_EQ(r.err, "lidar2d: error: " + (t.path() / "bad.yaml").string() +
                       ":2: submap_size: unknown option (lidar2d slam --dump-config lists them)\n");
  EXPECT_FALSE(fs::exists(t.path() / "b"));

  writeFile(t.path() / "type.yaml", "submap_nodes: many\n");
  r = runCli({"slam", log().string(), "-o", (t.path() / "c").string(), "--config", (t.path() / "type.yaml").string()});
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("submap_nodes"), std::string::npos) << r.err;

  writeFile(t.path() / "range.yaml", "submap_nodes: 20\nloop_min_score: 2\n");
  r = runCli({"slam", log().string(), "-o", (t.path() / "d").string(), "--config", (t.path() / "range.yaml").string()});
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_EQ(r.err, "lidar2d: error: " + (t.path() / "range.yaml").string() + ":2: loop_min_score: must be in (0, 1]\n");
  writeFile(t.path() / "angle.yaml", "loop_angular_window_deg: 0\n");
  r = runCli({"slam", log().string(), "-o", (t.path() / "d").string(), "--config", (t.path() / "angle.yaml").string()});
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_EQ(r.err, "lidar2d: error: " + (t.path() / "angle.yaml").string() +
                       ":1: loop_angular_window_deg: must be a finite value > 0\n");
  EXPECT_FALSE(fs::exists(t.path() / "d"));

  // The descriptor loop-closure options (issue 7).
  writeFile(t.path() / "desc.yaml", "descriptor_loops: true\ndescriptor_every_nodes: 5\ndescriptor_max_rotation_deg: 20\n");
  r = runCli({"slam", log().string(), "-o", (t.path() / "e").string(), "--config", (t.path() / "desc.yaml").string(), "-q"});
  EXPECT_EQ(r.exit_code, 0) << r.err;
  const auto summary = nlohmann::json::parse(test::readFile(t.path() / "e" / "summary.json"));
  EXPECT_TRUE(summary.contains("descriptor_queries"));
  EXPECT_TRUE(summary.contains("descriptor_closures_accepted"));
  writeFile(t.path() / "desc_type.yaml", "submap_nodes: 20\ndescriptor_loops: maybe\n");
  r = runCli({"slam", log().string(), "-o", (t.path() / "f").string(), "--config", (t.path() / "desc_type.yaml").string()});
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("desc_type.yaml:2"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("descriptor_loops"), std::string::npos) << r.err;
  writeFile(t.path() / "desc_range.yaml", "descriptor_max_see_through: 1.5\n");
  r = runCli({"slam", log().string(), "-o", (t.path() / "g").string(), "--config", (t.path() / "desc_range.yaml").string()});
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("descriptor_max_see_through"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(t.path() / "g"));
}

TEST(CliSlamConfig, DumpConfigReadsBackToTheSameOptions) {
  TempDir t;
  // The defaults, without a log or an output folder.
  const auto d = runCli({"slam", "--dump-config"});
  ASSERT_EQ(d.exit_code, 0) << d.err;
  EXPECT_NE(d.out.find("\nloop_angular_window_deg: 15\n"), std::string::npos) << d.out;
  EXPECT_NE(d.out.find("\n# [m] > 0: returns at or beyond this range are not matched\nmax_range_m: 30\n"),
            std::string::npos)
      << d.out;
  writeFile(t.path() / "defaults.yaml", d.out);
  auto r = runCli({"slam", "--dump-config", "--config", (t.path() / "defaults.yaml").string()});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(r.out, d.out);

  // Other values, angles included, come back the same through a file.
  writeFile(t.path() / "some.yaml", "loop_angular_window_deg: 12.3\nsequential_sigma_deg: 0.1\nscan_voxel_m: 0.07\n"
                                    "descriptor_loops: false\ndescriptor_max_lines: 9\n");
  const auto s = runCli({"slam", "--config", (t.path() / "some.yaml").string(), "--dump-config"});
  ASSERT_EQ(s.exit_code, 0) << s.err;
  EXPECT_NE(s.out.find("\nloop_angular_window_deg: 12.3\n"), std::string::npos) << s.out;
  EXPECT_NE(s.out.find("\ndescriptor_loops: false\n"), std::string::npos) << s.out;
  writeFile(t.path() / "some-dumped.yaml", s.out);
  r = runCli({"slam", "--dump-config", "--config", (t.path() / "some-dumped.yaml").string()});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(r.out, s.out);

  // --markdown needs --dump-config; LOG and -o are needed without it.
  EXPECT_EQ(runCli({"slam", "--markdown"}).exit_code, 2);
  EXPECT_EQ(runCli({"slam", "--config", (t.path() / "some.yaml").string()}).exit_code, 2);
}

TEST(CliSlamConfig, DocsTableIsTheOptionTable) {
  const std::string doc = test::readFile(test::sourceFile("docs/slam.md"));
  const std::string open = "<!-- options table: the output of `lidar2d slam --dump-config --markdown` -->\n";
  const std::string close = "<!-- end of the options table -->";
  const auto a = doc.find(open);
  const auto b = doc.find(close);
  ASSERT_NE(a, std::string::npos);
  ASSERT_NE(b, std::string::npos);
  const auto r = runCli({"slam", "--dump-config", "--markdown"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(doc.substr(a + open.size(), b - a - open.size()), r.out)
      << "docs/slam.md's options table is out of date: paste `lidar2d slam --dump-config --markdown` there";
}

TEST_F(CliSlam, BadInputIsOneClearError) {
  TempDir t;
  auto r = runCli({"slam", (t.path() / "missing.log").string(), "-o", (t.path() / "x").string()});
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("missing.log"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(t.path() / "x"));

  writeFile(t.path() / "bad.log", "FLASER 3 1.0 1.0 abc 0 0 0 0 0 0 1.0 host 0.1\n");
  r = runCli({"slam", (t.path() / "bad.log").string(), "-o", (t.path() / "y").string()});
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("bad.log:1"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(t.path() / "y"));

  writeFile(t.path() / "file", "x");
  r = runCli({"slam", log().string(), "-o", (t.path() / "file").string()});
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("not a directory"), std::string::npos) << r.err;

  r = runCli({"slam", log().string(), "-o", (t.path() / "z").string(), "--resolution", "-1"});
  EXPECT_EQ(r.exit_code, 1);
  r = runCli({"slam", log().string()});
  EXPECT_EQ(r.exit_code, 2);  // usage: -o missing
}

TEST_F(CliSlam, AFailedOutputLeavesTheFolderAsItWas) {
  // The outputs appear together or not at all: report.html cannot be written (a folder has its
  // name), so the earlier run's trajectory stays, and no new file nor staging folder is left.
  TempDir t;
  const fs::path out = t.path() / "out";
  fs::create_directories(out / "report.html");
  writeFile(out / "trajectory.txt", "old\n");
  const auto r = runCli({"slam", log().string(), "-o", out.string(), "--quiet"});
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("report.html"), std::string::npos) << r.err;
  EXPECT_TRUE(test::readFile(out / "trajectory.txt") == "old\n") << "the earlier trajectory was replaced";
  std::vector<std::string> left;
  for (const auto& e : fs::directory_iterator(out)) left.push_back(e.path().filename().string());
  EXPECT_EQ(left.size(), 2u) << ::testing::PrintToString(left);
}

TEST(CliSlamRealData, MitCsailRawBagBeatsItsOdometry) {
  LIDAR2D_REQUIRE_DATA("raw/mit-csail.orig.bag");
  TempDir t;
  const std::string bag = dataFile("raw/mit-csail.orig.bag").string();
  const std::string rel = dataFile("raw/mit-csail.relations").string();
  auto r = runCli({"slam", bag, "-o", (t.path() / "run").string(), "-q"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  r = runCli({"eval", (t.path() / "run/trajectory.txt").string(), "--truth", rel});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto j = nlohmann::json::parse(r.out)["relations"];
  // Cartographer's published figure on this log is 0.0319 m / 0.369 deg; raw odometry is 1.68 m.
  EXPECT_LT(j["trans_mean_m"].get<double>(), 0.05);
  EXPECT_LT(j["rot_mean_deg"].get<double>(), 0.6);
  EXPECT_GT(j["count"].get<int>(), 1000);
}

// Freiburg-101's corridor through a 5.6 m laser, with its truth as the odometry: the track is lost
// after the log's gaps, and the first relocalization ties the scans to a look-alike stretch of the
// corridor, 4-7 odometry sigmas from where the exact odometry puts them. A match within the
// odometry's gate explains the scan as well, so nothing shows the robot carried: the odometry
// link across the lost track must stay (it was dropped as a kidnapping before).
TEST(CliSlamData, ALookAlikeJustBeyondTheOdometrysGateDoesNotDropExactOdometry) {
  LIDAR2D_REQUIRE_DATA("corrected/freiburg-101.log.gz");
  TempDir t;
  const std::string log = (t.path() / "fr101.log").string();
  auto r = runCli({"perturb", dataFile("corrected/freiburg-101.log.gz").string(), "--odom-noise", "0,0,0",
                   "--laser-range-max", "5.6", "-o", log});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  r = runCli({"slam", log, "-o", (t.path() / "run").string(), "-q"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto j = nlohmann::json::parse(readFile(t.path() / "run/summary.json"));
  std::size_t lost = 0, kept = 0, dropped = 0;
  std::string all;
  for (const auto& e : j["events"]) {
    const std::string what = e["what"].get<std::string>();
    all += what + "\n";
    lost += what.find("local map restarted") != std::string::npos;
    kept += what.find("a match within the odometry's gate explains") != std::string::npos;
    dropped += what.find("the odometry link is dropped") != std::string::npos;
  }
  // The closures the rule refused are listed in graph.txt with the reason.
  const std::string graph = readFile(t.path() / "run/graph.txt");
  for (std::size_t at = 0; (at = graph.find("a match within the odometry's gate explains", at)) != std::string::npos;
       ++at)
    ++kept;
  ASSERT_GT(lost, 0u) << "the case no longer arises\n" << all;
  EXPECT_GT(kept, 0u) << all;
  EXPECT_EQ(dropped, 0u) << all;
}

}  // namespace
}  // namespace lidar2d::test
