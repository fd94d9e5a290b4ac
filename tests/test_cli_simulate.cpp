// `lidar2d simulate` and `lidar2d perturb` end to end: logs read back with `info` and io::openLog,
// perturb's noise statistics, and bad input through the CLI.
//
// Exit codes checked here: an unknown --world, a malformed --odom-noise, --beams <= 0 and
// --world together with --map are usage errors (exit 2); a missing map YAML, an unwritable output
// and perturb on a log without truth are bad input (exit 1), and leave no output file.

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <numbers>
#include <sstream>

#include "lidar2d/io/frame_source.hpp"
#include "lidar2d/io/map_file.hpp"
#include "lidar2d/sim/path.hpp"
#include "lidar2d/sim/simulator.hpp"
#include "lidar2d/sim/worlds.hpp"
#include "support/test_support.hpp"

namespace lidar2d {
namespace {

namespace fs = std::filesystem;
using test::runCli;
using test::TempDir;
using test::writeFile;

std::vector<Frame> readAll(const std::string& path) {
  auto src = io::openLog(path);
  std::vector<Frame> frames;
  while (auto f = src->next()) frames.push_back(std::move(*f));
  return frames;
}

nlohmann::json info(const std::string& log) {
  const auto r = runCli({"info", "--json", log});
  EXPECT_EQ(r.exit_code, 0) << r.err;
  return nlohmann::json::parse(r.out);
}

class SimulateWorld : public ::testing::TestWithParam<std::string> {};

TEST_P(SimulateWorld, InfoReportsScansBeamsOdometryAndTruth) {
  TempDir tmp;
  const std::string log = (tmp / "sim.log").string();
  const auto r = runCli({"simulate", "--world", GetParam(), "-o", log, "--scans", "60", "--beams", "181", "--seed", "4"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("60 scans"), std::string::npos) << r.out;
  const auto j = info(log);
  EXPECT_EQ(j["scans"], 60);
  EXPECT_EQ(j["beams"], 181);
  EXPECT_EQ(j["has_truth"], true);
  EXPECT_EQ(j["has_odometry"], true);
  EXPECT_NEAR(j["fov_deg"].get<double>(), 270.0 * 181 / 180, 1e-6);  // n * increment
  EXPECT_NEAR(j["duration_s"].get<double>(), 5.9, 1e-6);
  // The comment line states the world, seed and options.
  const std::string text = test::readFile(log);
  EXPECT_NE(text.find("world=" + GetParam()), std::string::npos);
  EXPECT_NE(text.find("seed=4"), std::string::npos);
  EXPECT_NE(text.find("range_noise_m=0.01"), std::string::npos);
}

INSTANTIATE_TEST_SUITE_P(AllWorlds, SimulateWorld, ::testing::Values("office", "corridor", "symmetric", "open"));

TEST(Simulate, DefaultScanCountIsTheWholeRoute) {
  TempDir tmp;
  const std::string log = (tmp / "s.log").string();
  ASSERT_EQ(runCli({"simulate", "--world", "symmetric", "-o", log}).exit_code, 0);
  const auto expected = sim::samplePath(sim::builtinScenario("symmetric").waypoints, sim::PathOptions{}).size();
  EXPECT_EQ(info(log)["scans"], expected);
}

TEST(Simulate, NoiseFreeLogReadsBackToTheSimulatedFrames) {
  TempDir tmp;
  const std::string log = (tmp / "nf.log").string();
  ASSERT_EQ(runCli({"simulate", "--world", "office", "-o", log, "--scans", "30", "--noise-free", "--beams", "91",
                    "--fov", "180", "--mount", "0.2,0.05,10"})
                .exit_code,
            0);
  const auto frames = readAll(log);
  ASSERT_EQ(frames.size(), 30u);
  const sim::Scenario s = sim::builtinScenario("office");
  sim::SimulatorOptions o;
  o.laser.beams = 91;
  o.laser.fov_rad = std::numbers::pi;
  o.laser.T_robot_laser = SE2(0.2, 0.05, 10 * std::numbers::pi / 180);
  sim::Simulator sim(s.world, sim::samplePath(s.waypoints, sim::PathOptions{}, 30), o.noiseFree());
  for (const Frame& f : frames) {
    ASSERT_TRUE(f.T_world_robot && f.T_odom_robot);
    const SE2 truth = sim.truth()[f.index].T_world_robot;
    EXPECT_TRUE(test::IsNearPose(truth, *f.T_world_robot, 1e-5, 1e-3));
    EXPECT_TRUE(test::IsNearPose(truth, *f.T_odom_robot, 1e-5, 1e-3));  // noise-free odometry = truth
    EXPECT_TRUE(test::IsNearPose(o.laser.T_robot_laser, f.T_robot_laser, 1e-5, 1e-3));
    const auto exact = sim.exactRanges(truth);
    ASSERT_EQ(f.scan.size(), exact.size());
    for (std::size_t i = 0; i < exact.size(); ++i) EXPECT_NEAR(f.scan.ranges()[i], exact[i], 1e-3) << i;
  }
}

TEST(Simulate, MapWorldAndPathFile) {
  TempDir tmp;
  // A 8 x 6 m room with a wall stub, 5 cm cells.
  auto map = OccupancyImage::filled(160, 120, 0.05, SE2(-2, -1, 0), 0);
  for (int r = 0; r < 120; ++r)
    for (int c = 0; c < 160; ++c)
      if (r == 0 || c == 0 || r == 119 || c == 159 || (c == 80 && r < 60)) map.set(c, r, 100);
  io::writeMap((tmp / "room.yaml").string(), map);
  const std::string log = (tmp / "m.log").string();
  auto r = runCli({"simulate", "--map", (tmp / "room.yaml").string(), "-o", log, "--scans", "80", "--seed", "2"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  auto j = info(log);
  EXPECT_EQ(j["scans"], 80);
  EXPECT_EQ(j["has_truth"], true);
  EXPECT_GT(j["valid_beam_fraction"].get<double>(), 0.5);  // a closed room: most beams hit
  // The same map as a bare image with its resolution and origin on the command line: the same log.
  const std::string bare_log = (tmp / "bare.log").string();
  r = runCli({"simulate", "--map", (tmp / "room.pgm").string(), "--resolution", "0.05", "--origin", "-2,-1,0", "-o",
              bare_log, "--scans", "80", "--seed", "2"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  std::string yaml_text = test::readFile(log), bare_text = test::readFile(bare_log);
  // The header comment names the map file; everything after it is the same.
  yaml_text = yaml_text.substr(yaml_text.find("\nROBOTLASER1"));
  bare_text = bare_text.substr(bare_text.find("\nROBOTLASER1"));
  EXPECT_TRUE(yaml_text == bare_text) << "the bare image simulates another log than its YAML";
  // A bare image without its resolution, or the options with --world, are usage errors.
  EXPECT_EQ(runCli({"simulate", "--map", (tmp / "room.pgm").string(), "-o", bare_log + "2"}).exit_code, 2);
  EXPECT_EQ(runCli({"simulate", "--world", "office", "--resolution", "0.05", "-o", bare_log + "3"}).exit_code, 2);
  EXPECT_FALSE(fs::exists(bare_log + "2"));
  EXPECT_FALSE(fs::exists(bare_log + "3"));
  // --path: one scan per trajectory pose, truth = those poses.
  writeFile(tmp / "traj.txt", "# t x y theta\n0.0 1.0 1.0 0.0\n0.1 1.1 1.0 0.1\n0.25 1.2 1.1 0.2\n");
  const std::string log2 = (tmp / "p.log").string();
  r = runCli({"simulate", "--map", (tmp / "room.yaml").string(), "--path", (tmp / "traj.txt").string(), "-o", log2});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto frames = readAll(log2);
  ASSERT_EQ(frames.size(), 3u);
  EXPECT_TRUE(test::IsNearPose(SE2(1.2, 1.1, 0.2), *frames[2].T_world_robot, 1e-6, 1e-4));
  EXPECT_NEAR(frames[2].time, 0.25, 1e-6);
}

TEST(Perturb, OdometryNoiseHasThePerStepStatistics) {
  TempDir tmp;
  const std::string clean = (tmp / "clean.log").string(), noisy = (tmp / "noisy.log").string();
  ASSERT_EQ(runCli({"simulate", "--world", "corridor", "-o", clean, "--noise-free", "--beams", "31"}).exit_code, 0);
  const auto r = runCli({"perturb", clean, "--odom-noise", "0.02,0.01,0.005", "--seed", "5", "-o", noisy});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto in = readAll(clean), out = readAll(noisy);
  ASSERT_EQ(in.size(), out.size());
  ASSERT_GT(out.size(), 1000u);
  double n = 0, sx = 0, sy = 0, st = 0, mx = 0, my = 0, mt = 0;
  for (std::size_t k = 0; k < out.size(); ++k) {
    ASSERT_TRUE(out[k].T_world_robot && out[k].T_odom_robot);
    EXPECT_TRUE(test::IsNearPose(*in[k].T_world_robot, *out[k].T_world_robot, 1e-9, 1e-7));  // truth kept
    EXPECT_EQ(in[k].scan.ranges(), out[k].scan.ranges());                                      // scans kept
    if (k == 0) {
      EXPECT_TRUE(test::IsNearPose(*out[0].T_world_robot, *out[0].T_odom_robot, 1e-9, 1e-7));  // odom_0 = truth_0
      continue;
    }
    const SE2 truth_step = out[k - 1].T_world_robot->inverse() * *out[k].T_world_robot;
    const SE2 odom_step = out[k - 1].T_odom_robot->inverse() * *out[k].T_odom_robot;
    const SE2 e = truth_step.inverse() * odom_step;  // the per-step noise SE2(n_x, n_y, n_theta)
    n += 1;
    mx += e.x();
    my += e.y();
    mt += e.theta();
    sx += e.x() * e.x();
    sy += e.y() * e.y();
    st += e.theta() * e.theta();
  }
  // n > 1000: the standard error of a standard deviation is below 2.3 %; allow 10 %.
  EXPECT_NEAR(std::sqrt(sx / n), 0.02, 0.002);
  EXPECT_NEAR(std::sqrt(sy / n), 0.01, 0.001);
  EXPECT_NEAR(std::sqrt(st / n), 0.005, 0.0005);
  EXPECT_NEAR(mx / n, 0.0, 0.002);
  EXPECT_NEAR(my / n, 0.0, 0.001);
  EXPECT_NEAR(mt / n, 0.0, 0.0005);
  // Deterministic per seed.
  const std::string again = (tmp / "again.log").string(), other = (tmp / "other.log").string();
  ASSERT_EQ(runCli({"perturb", clean, "--odom-noise", "0.02,0.01,0.005", "--seed", "5", "-o", again}).exit_code, 0);
  ASSERT_EQ(runCli({"perturb", clean, "--odom-noise", "0.02,0.01,0.005", "--seed", "6", "-o", other}).exit_code, 0);
  EXPECT_EQ(test::readFile(noisy), test::readFile(again));
  EXPECT_NE(test::readFile(noisy), test::readFile(other));
  EXPECT_EQ(info(noisy)["has_truth"], true);
}

// ---- bad input ----

TEST(Simulate, PeopleAreRecordedInTheLogAndLeaveOdometryAndTruthAlone) {
  TempDir tmp;
  const std::string plain = (tmp / "plain.log").string(), crowd = (tmp / "crowd.log").string();
  ASSERT_EQ(runCli({"simulate", "--world", "corridor", "--scans", "200", "-o", plain}).exit_code, 0);
  ASSERT_EQ(runCli({"simulate", "--world", "corridor", "--scans", "200", "--people", "6", "-o", crowd}).exit_code, 0);
  EXPECT_NE(test::readFile(crowd).find(" people=6"), std::string::npos);
  const auto a = readAll(plain), b = readAll(crowd);
  ASSERT_EQ(a.size(), b.size());
  std::size_t shorter = 0;
  for (std::size_t k = 0; k < a.size(); ++k) {
    EXPECT_TRUE(test::IsNearPose(*a[k].T_odom_robot, *b[k].T_odom_robot, 0.0, 0.0));
    EXPECT_TRUE(test::IsNearPose(*a[k].T_world_robot, *b[k].T_world_robot, 0.0, 0.0));
    for (std::size_t i = 0; i < a[k].scan.size(); ++i) {
      EXPECT_LE(b[k].scan.ranges()[i], a[k].scan.ranges()[i]);
      shorter += b[k].scan.ranges()[i] < a[k].scan.ranges()[i] ? 1 : 0;
    }
  }
  EXPECT_GT(shorter, 500u);
}

TEST(SimulateCli, UsageErrorsExit2) {
  TempDir tmp;
  const std::string out = (tmp / "x.log").string();
  auto r = runCli({"simulate", "--world", "moon", "-o", out});
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.err.find("moon"), std::string::npos) << r.err;
  r = runCli({"simulate", "--world", "office", "--odom-noise", "0.1,0.2", "-o", out});
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.err.find("SX,SY,STH"), std::string::npos) << r.err;
  EXPECT_EQ(runCli({"simulate", "--world", "office", "--odom-noise", "a,b,c", "-o", out}).exit_code, 2);
  EXPECT_EQ(runCli({"simulate", "--world", "office", "--odom-noise", "0.1,-0.2,0.1", "-o", out}).exit_code, 2);
  EXPECT_EQ(runCli({"simulate", "--world", "office", "--beams", "-5", "-o", out}).exit_code, 2);
  EXPECT_EQ(runCli({"simulate", "--world", "office", "--beams", "0", "-o", out}).exit_code, 2);
  EXPECT_EQ(runCli({"simulate", "--world", "office", "--rate", "0", "-o", out}).exit_code, 2);
  EXPECT_EQ(runCli({"simulate", "--world", "office", "--map", "m.yaml", "-o", out}).exit_code, 2);
  EXPECT_EQ(runCli({"simulate", "-o", out}).exit_code, 2);
  EXPECT_EQ(runCli({"simulate", "--world", "office"}).exit_code, 2);  // no output
  EXPECT_EQ(runCli({"simulate", "--world", "office", "--people", "1001", "-o", out}).exit_code, 2);
  EXPECT_EQ(runCli({"simulate", "--world", "office", "--people", "-1", "-o", out}).exit_code, 2);
  // Non-finite numbers: CLI11 reads "nan" and "inf" as numbers, and NaN passed its range checks
  // (--rate nan reached the path sampler; --clearance nan was taken).
  for (const char* opt : {"--rate", "--speed", "--clearance", "--range-noise"}) {
    r = runCli({"simulate", "--world", "office", opt, "nan", "-o", out});
    EXPECT_EQ(r.exit_code, 2) << opt;
    EXPECT_NE(r.err.find("must be a finite number"), std::string::npos) << opt << ": " << r.err;
  }
  r = runCli({"simulate", "--world", "office", "--mount", "1e308,0,0", "-o", out});
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("--mount"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(out));
}

TEST(SimulateCli, BadInputExits1WithoutOutput) {
  TempDir tmp;
  // An output folder that cannot be created (under a regular file); a missing one would be created.
  TempDir other;
  test::writeFile(other / "file", "x");
  auto r = runCli({"simulate", "--world", "office", "--scans", "5", "-o", (other / "file" / "x.log").string()});
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("lidar2d: error:"), std::string::npos) << r.err;
  const std::string out = (tmp / "x.log").string();
  r = runCli({"simulate", "--map", (tmp / "nope.yaml").string(), "-o", out});
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("nope.yaml"), std::string::npos) << r.err;
  // An output that is a directory.
  fs::create_directory(tmp / "dir.log");
  EXPECT_EQ(runCli({"simulate", "--world", "open", "--scans", "3", "-o", (tmp / "dir.log").string()}).exit_code, 1);
  // Range limits that contradict each other are caught by the library (exit 1).
  r = runCli({"simulate", "--world", "open", "--scans", "3", "--min-range", "40", "-o", out});
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("range_max"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(out));
  // A rate so low that 3 scans would drive the route 10^10 times (this looped without end) and,
  // in a map, a random walk of 2.4 * 10^12 m.
  r = runCli({"simulate", "--world", "office", "--scans", "3", "--rate", "1e-12", "-o", out});
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("passes over the route"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(out));
  // Leftover temporary files would be partial output.
  for (const auto& e : fs::directory_iterator(tmp.path())) EXPECT_EQ(e.path().filename(), "dir.log");
}

TEST(PerturbCli, Errors) {
  TempDir tmp;
  // A CARMEN log with odometry only (FLASER poses, no ODOM and no TRUEPOS lines): no truth.
  writeFile(tmp / "odo.log",
            "FLASER 3 1.0 1.5 2.0 0.0 0.0 0.0 0.0 0.0 0.0 1.0 host 1.0\n"
            "FLASER 3 1.0 1.5 2.0 0.1 0.0 0.0 0.1 0.0 0.0 1.1 host 1.1\n");
  const std::string out = (tmp / "p.log").string();
  auto r = runCli({"perturb", (tmp / "odo.log").string(), "--odom-noise", "0.01,0.01,0.01", "-o", out});
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("truth"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(out));
  r = runCli({"perturb", (tmp / "odo.log").string(), "--odom-noise", "0.01;0.01;0.01", "-o", out});
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_EQ(runCli({"perturb", (tmp / "odo.log").string(), "--odom-noise", "0.01,0.01", "-o", out}).exit_code, 2);
  EXPECT_EQ(runCli({"perturb", (tmp / "nope.log").string(), "-o", out}).exit_code, 1);
  EXPECT_FALSE(fs::exists(out));
}

}  // namespace
}  // namespace lidar2d
