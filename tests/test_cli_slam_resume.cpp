// lidar2d slam --resume: a saved map continued with a second log (its second part, placed by global
// localization), the outputs of both sessions, a chain of resumes, bad state files; and lidar2d
// track with a state.l2d as its map.

#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>

#include "lidar2d/io/trajectory.hpp"
#include "support/test_support.hpp"

namespace lidar2d::test {
namespace {

namespace fs = std::filesystem;

/// A simulated office log (40 s), its first 25 s mapped and saved, then resumed with its last 32 s.
class CliSlamResume : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new TempDir();
    auto r = runCli({"simulate", "--world", "office", "--beams", "181", "--scans", "400", "--seed", "3", "-o",
                     log().string()});
    ASSERT_EQ(r.exit_code, 0) << r.err;
    r = runCli({"slam", log().string(), "--to", "25", "-o", first().string(), "-q"});
    ASSERT_EQ(r.exit_code, 0) << r.err;
    r = runCli({"slam", log().string(), "--from", "8", "--resume", (first() / "state.l2d").string(), "-o",
                second().string(), "-q"});
    ASSERT_EQ(r.exit_code, 0) << r.err;
  }
  static void TearDownTestSuite() { delete dir_; }
  static fs::path log() { return dir_->path() / "office.log"; }
  static fs::path first() { return dir_->path() / "first"; }
  static fs::path second() { return dir_->path() / "second"; }
  static double ate(const fs::path& trajectory) {
    const auto r = runCli({"eval", trajectory.string(), "--truth", log().string()});
    EXPECT_EQ(r.exit_code, 0) << r.err;
    return nlohmann::json::parse(r.out)["ate_rmse_m"].get<double>();
  }
  static TempDir* dir_;
};
TempDir* CliSlamResume::dir_ = nullptr;

TEST_F(CliSlamResume, BothSessionsAreOneMapInTheSavedFrame) {
  // The time window: the first run mapped scans [0, 25 s), the second [8 s, 40 s).
  EXPECT_EQ(io::readTrajectory((first() / "trajectory.txt").string()).size(), 250u);
  const auto earlier = io::readTrajectory((second() / "trajectory_session1.txt").string());
  const auto now = io::readTrajectory((second() / "trajectory.txt").string());
  EXPECT_EQ(earlier.size(), 250u);
  EXPECT_EQ(now.size(), 320u);
  const auto j = nlohmann::json::parse(readFile(second() / "summary.json"));
  ASSERT_EQ(j["sessions"].size(), 2u);
  EXPECT_EQ(j["sessions"][0]["trajectory"], "trajectory_session1.txt");
  EXPECT_EQ(j["sessions"][1]["scans"], 320);
  EXPECT_EQ(j["fragments"], 1);
  EXPECT_GE(j["relocalizations"].get<int>(), 1);
  EXPECT_EQ(j["resumed_from"], (first() / "state.l2d").string());
  // The simulator's odometry starts at the truth, so the saved recording's frame is the truth's; the
  // resumed recording, placed in it, is as accurate as the saved one (its own odometry alone is not).
  EXPECT_LT(ate(second() / "trajectory_session1.txt"), 0.05);
  EXPECT_LT(ate(second() / "trajectory.txt"), 0.05);
  for (const char* f : {"map.pgm", "map.yaml", "graph.txt", "state.l2d", "report.html"})
    EXPECT_TRUE(fs::is_regular_file(second() / f)) << f;
  // The report draws each session's trajectory on its own and lists the sessions.
  const std::string html = readFile(second() / "report.html");
  EXPECT_NE(html.find("id=\"trajectory\""), std::string::npos);
  EXPECT_NE(html.find("id=\"trajectory-session2\""), std::string::npos);
  EXPECT_NE(html.find("<th>sessions</th>"), std::string::npos);
}

TEST_F(CliSlamResume, ResumesChainAndTheOptionsAreTheSaved) {
  TempDir t;
  auto r = runCli({"slam", log().string(), "--from", "30", "--resume", (second() / "state.l2d").string(), "-o",
                   (t.path() / "third").string(), "-q"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto j = nlohmann::json::parse(readFile(t.path() / "third" / "summary.json"));
  EXPECT_EQ(j["sessions"].size(), 3u);
  EXPECT_TRUE(fs::is_regular_file(t.path() / "third" / "trajectory_session2.txt"));
  // Another --config would make the sessions disagree: a usage error, nothing written.
  writeFile(t.path() / "c.yaml", "submap_nodes: 20\n");
  r = runCli({"slam", log().string(), "--resume", (second() / "state.l2d").string(), "--config",
              (t.path() / "c.yaml").string(), "-o", (t.path() / "x").string()});
  EXPECT_EQ(r.exit_code, 2) << r.err;
  EXPECT_NE(r.err.find("--resume"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(t.path() / "x"));
}

TEST_F(CliSlamResume, BadStateFilesAreOneLineAndExitOne) {
  TempDir t;
  const std::string good = readFile(first() / "state.l2d");
  const auto refused = [&](const std::string& name, const std::string& content, const std::string& what) {
    writeFile(t.path() / name, content);
    const auto r = runCli({"slam", log().string(), "--resume", (t.path() / name).string(), "-o",
                           (t.path() / "out").string()});
    EXPECT_EQ(r.exit_code, 1) << name;
    EXPECT_TRUE(r.err.starts_with("lidar2d: error: " + (t.path() / name).string())) << r.err;
    EXPECT_NE(r.err.find(what), std::string::npos) << r.err;
    EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
    EXPECT_FALSE(fs::exists(t.path() / "out")) << name;
    const auto tr = runCli({"track", (t.path() / name).string(), log().string(), "-o", (t.path() / "t.txt").string()});
    EXPECT_EQ(tr.exit_code, 1) << name;
    EXPECT_FALSE(fs::exists(t.path() / "t.txt")) << name;
  };
  refused("truncated.l2d", good.substr(0, good.size() / 3), "truncated");
  std::string flipped = good;
  flipped[good.size() - 10] = static_cast<char>(flipped[good.size() - 10] ^ 1);
  refused("flipped.l2d", flipped, "corrupt");
  std::string future = good;
  future[8] = static_cast<char>(future[8] + 1);
  refused("future.l2d", future, "is not supported");
  // A map or a log given as the state: not a state file.
  const auto r = runCli({"slam", log().string(), "--resume", log().string(), "-o", (t.path() / "out").string()});
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("not a lidar2d SLAM state file"), std::string::npos) << r.err;
}

TEST_F(CliSlamResume, TrackLocalizesInAStateWithoutAnInitialPose) {
  // The state of both sessions covers the whole route: the log is tracked from its first scans on.
  TempDir t;
  const auto r = runCli({"track", (second() / "state.l2d").string(), log().string(), "-o",
                         (t.path() / "track.txt").string(), "--json", (t.path() / "track.json").string(), "--eval",
                         "-q"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto j = nlohmann::json::parse(readFile(t.path() / "track.json"));
  EXPECT_GT(j["status"]["tracking"].get<double>(), 0.95);
  EXPECT_EQ(j["eval"]["wrong_while_tracking"], 0);
  EXPECT_GT(j["eval"]["tracking_within_share"].get<double>(), 0.95);
  EXPECT_LT(j["time_to_first_fix_s"].get<double>(), 1.0);
  // A bare image's options do not apply to a state: usage errors, no output.
  for (const char* option : {"--origin=1,2,0", "--image-rows-up"}) {
    const auto bad = runCli({"track", (second() / "state.l2d").string(), log().string(), option, "-o",
                             (t.path() / "bad.txt").string(), "-q"});
    EXPECT_EQ(bad.exit_code, 2) << option << ": " << bad.err;
    EXPECT_NE(bad.err.find("not to a SLAM state"), std::string::npos) << bad.err;
    EXPECT_FALSE(std::filesystem::exists(t.path() / "bad.txt")) << option;
  }
}

// The mit-csail bag's first half saved, its second half resumed: the new session is found in the
// first half's map. Its searches over whole submaps once refined only the best-scoring candidate,
// and at the node in the right place a corridor elsewhere that sees through its submap's walls
// outscored the right submap (0.91 against 0.88): two fragments, 0.455 m, with one scan's change to
// the first half's graph deciding it. The whole bag scores 0.0269 m against its relations.
TEST(CliSlamResumeData, TheMitCsailBagsSecondHalfIsFoundInItsFirst) {
  LIDAR2D_REQUIRE_DATA("raw/mit-csail.orig.bag");
  TempDir t;
  const std::string bag = dataFile("raw/mit-csail.orig.bag").string();
  auto r = runCli({"slam", bag, "--to", "212", "-o", (t / "first").string(), "-q"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  r = runCli({"slam", bag, "--from", "212", "--resume", (t / "first" / "state.l2d").string(), "-o",
              (t / "second").string(), "-q"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto j = nlohmann::json::parse(readFile(t / "second" / "summary.json"));
  EXPECT_EQ(j["fragments"], 1);
  EXPECT_GE(j["relocalizations"].get<int>(), 1);
  writeFile(t / "both.txt",
            readFile(t / "second" / "trajectory_session1.txt") + readFile(t / "second" / "trajectory.txt"));
  r = runCli({"eval", (t / "both.txt").string(), "--truth", dataFile("raw/mit-csail.relations").string()});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_LT(nlohmann::json::parse(r.out)["relations"]["trans_mean_m"].get<double>(), 0.0296);  // 1.1 x the whole bag
}

}  // namespace
}  // namespace lidar2d::test
