// lidar2d map end to end: outputs per model, --poses, --prior, and bad input (exit 1, no files).

#include <fmt/format.h>
#include <gtest/gtest.h>

#include <filesystem>
#include <algorithm>
#include <fstream>

#include "lidar2d/io/frame_source.hpp"
#include "lidar2d/io/map_file.hpp"
#include "lidar2d/io/trajectory.hpp"
#include "support/test_support.hpp"

namespace lidar2d {
namespace {

namespace fs = std::filesystem;
using test::runCli;

class CliMap : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new test::TempDir();
    const auto r = runCli({"simulate", "--world", "office", "--scans", "150", "--seed", "3", "-o", log()});
    ASSERT_EQ(r.exit_code, 0) << r.err;
  }
  static void TearDownTestSuite() { delete dir_; }
  static std::string log() { return (*dir_ / "office.log").string(); }
  static std::string path(const std::string& name) { return (*dir_ / name).string(); }
  static bool noFilesWithPrefix(const std::string& prefix) {
    for (const auto& e : fs::directory_iterator(dir_->path()))
      if (e.path().filename().string().rfind(prefix, 0) == 0) return false;
    return true;
  }
  static test::TempDir* dir_;
};
test::TempDir* CliMap::dir_ = nullptr;

TEST_F(CliMap, WritesMapServerFilesForEveryModel) {
  for (const std::string model : {"logodds", "count", "tsdf"}) {
    const std::string prefix = path("m-" + model);
    const auto r = runCli({"map", log(), "--model", model, "-o", prefix});
    ASSERT_EQ(r.exit_code, 0) << r.err;
    EXPECT_NE(r.out.find(prefix + ".pgm"), std::string::npos);
    const io::MapFile m = io::readMap(prefix + ".yaml");
    EXPECT_DOUBLE_EQ(m.map.resolution(), 0.05);
    // The office is 20 x 15 m and closed: the map covers its width and nothing beyond its outer
    // walls (the simulator's lost echoes are error readings, which clear nothing; when they were
    // written as "no return", each cleared 5 m through the wall and the map was about 28 m wide).
    EXPECT_GT(m.map.width() * 0.05, 20.0);
    EXPECT_LT(m.map.width() * 0.05, 21.0);
    std::size_t occ = 0, free_cells = 0;
    for (auto v : m.map.cells()) {
      occ += v == OccupancyImage::kOccupied;
      free_cells += v == OccupancyImage::kFree;
    }
    EXPECT_GT(occ, 1000u) << model;
    // Mostly free space inside the walls (15-19 free cells per occupied one; the 20 this asked for
    // counted the free rays outside the building).
    EXPECT_GT(free_cells, 10 * occ) << model;
    EXPECT_TRUE(fs::exists(prefix + ".png"));
    EXPECT_EQ(fs::exists(prefix + ".surface.txt"), model == "tsdf");
  }
}

TEST_F(CliMap, PosesFileGivesTheSameMapAsTheLogsTruth) {
  Trajectory traj;
  auto src = io::openLog(log());
  while (auto f = src->next()) traj.push_back({f->time, *f->T_world_robot});
  io::writeTrajectory(path("truth.txt"), traj);
  ASSERT_EQ(runCli({"map", log(), "-o", path("from-log")}).exit_code, 0);
  ASSERT_EQ(runCli({"map", log(), "--poses", path("truth.txt"), "-o", path("from-traj")}).exit_code, 0);
  EXPECT_EQ(io::readMap(path("from-log.yaml")).map.cells(), io::readMap(path("from-traj.yaml")).map.cells());
  // Odometry instead of truth gives a different (drifted) map.
  ASSERT_EQ(runCli({"map", log(), "--pose-source", "odometry", "-o", path("from-odom")}).exit_code, 0);
  EXPECT_NE(io::readMap(path("from-log.yaml")).map.cells(), io::readMap(path("from-odom.yaml")).map.cells());
}

TEST_F(CliMap, PriorOverridesTheSensor) {
  ASSERT_EQ(runCli({"map", log(), "-o", path("base")}).exit_code, 0);
  const io::MapFile base = io::readMap(path("base.yaml"));
  // A prior map of the same geometry: a 10 x 10 cell occupied block in the middle, the rest no-opinion.
  OccupancyImage prior = OccupancyImage::filled(base.map.width(), base.map.height(), base.map.resolution(),
                                                        base.map.origin(), OccupancyImage::kUnknown);
  const int c0 = base.map.width() / 2, r0 = base.map.height() / 2;
  for (int r = r0; r < r0 + 10; ++r)
    for (int c = c0; c < c0 + 10; ++c) prior.set(c, r, OccupancyImage::kOccupied);
  io::writeMap(path("prior.yaml"), prior);
  const auto r = runCli({"map", log(), "--prior", path("prior.yaml"), "-o", path("with-prior")});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const io::MapFile out = io::readMap(path("with-prior.yaml"));
  for (int rr = r0; rr < r0 + 10; ++rr)
    for (int c = c0; c < c0 + 10; ++c) EXPECT_EQ(out.map.at(c, rr), OccupancyImage::kOccupied);
  // Elsewhere the sensor's verdict stands.
  EXPECT_EQ(out.map.at(0, 0), base.map.at(0, 0));
  // The YAML says so in a comment (which map_server ignores; readMap just did too).
  const std::string yaml = test::readFile(path("with-prior.yaml"));
  EXPECT_NE(yaml.find("# prior layer prior.yaml overrides the sensor in 100 cells"), std::string::npos) << yaml;
  EXPECT_EQ(test::readFile(path("base.yaml")).find("prior layer"), std::string::npos);
  // The same prior as a bare image works too (the written PGM is exactly the map's size).
  const auto r2 = runCli({"map", log(), "--prior", path("prior.pgm"), "-o", path("with-prior-pgm")});
  ASSERT_EQ(r2.exit_code, 0) << r2.err;
  EXPECT_EQ(io::readMap(path("with-prior-pgm.yaml")).map.cells(), out.map.cells());
  // A bare image with --prior-resolution and --prior-origin is aligned by world coordinates, as its
  // YAML is: here a prior image cropped to its block's 10 x 10 cells.
  OccupancyImage block = OccupancyImage::filled(10, 10, base.map.resolution(),
                                                SE2(base.map.origin().x() + c0 * base.map.resolution(),
                                                    base.map.origin().y() + r0 * base.map.resolution(), 0.0),
                                                OccupancyImage::kOccupied);
  io::writeMap(path("block.yaml"), block);
  const auto r3 = runCli({"map", log(), "--prior", path("block.pgm"), "--prior-resolution",
                          fmt::format("{}", base.map.resolution()), "--prior-origin",
                          fmt::format("{},{},0", block.origin().x(), block.origin().y()), "-o", path("with-bare")});
  ASSERT_EQ(r3.exit_code, 0) << r3.err;
  EXPECT_EQ(io::readMap(path("with-bare.yaml")).map.cells(), out.map.cells());
  // The options without --prior, or on a YAML prior, are usage errors, before any work.
  EXPECT_EQ(runCli({"map", log(), "--prior-resolution", "0.05", "-o", path("no-prior")}).exit_code, 2);
  EXPECT_EQ(runCli({"map", log(), "--prior", path("prior.yaml"), "--prior-resolution", "0.05", "-o", path("yaml-prior")})
                .exit_code,
            2);
  EXPECT_FALSE(fs::exists(path("no-prior.yaml")));
  EXPECT_FALSE(fs::exists(path("yaml-prior.yaml")));
}

TEST_F(CliMap, AFailedOutputLeavesNoneOfTheFiles) {
  // The files appear together or not at all: PREFIX.png cannot be written (a folder has its name),
  // so neither PREFIX.pgm nor PREFIX.yaml is left, nor a staging folder.
  test::TempDir t;
  fs::create_directories(t.path() / "m.png");
  const auto r = runCli({"map", log(), "-o", (t.path() / "m").string()});
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("m.png"), std::string::npos) << r.err;
  std::vector<std::string> left;
  for (const auto& e : fs::directory_iterator(t.path())) left.push_back(e.path().filename().string());
  EXPECT_EQ(left, std::vector<std::string>{"m.png"});
}

struct BadMapCase {
  std::string name;
  std::vector<std::string> extra;  // arguments after "map LOG"
  std::string expect;              // substring of the error line
  friend void PrintTo(const BadMapCase& c, std::ostream* os) { *os << c.name; }
};

class CliMapBad : public CliMap, public ::testing::WithParamInterface<BadMapCase> {};

TEST_P(CliMapBad, OneLineExit1NoFiles) {
  const BadMapCase& c = GetParam();
  // Fixtures the cases refer to.
  test::writeFile(*dir_ / "short-traj.txt", "0.0 0 0 0\n0.1 0 0 0\n");
  test::writeFile(*dir_ / "tiny-mask.pgm", std::string("P5\n3 2\n255\n") + std::string(6, '\0'));
  test::writeFile(*dir_ / "noposes.log", "RAWLASER1 0 -1.5708 3.14159 0.0174533 80 0.01 0 3 1 2 3 0 10.0 host 10.0\n");
  // The second scan's odometry lies 10^12 m out.
  test::writeFile(*dir_ / "farpose.log",
                  "FLASER 3 1 2 3 0 0 0 0 0 0 0.0 host 0.0\n"
                  "FLASER 3 1 2 3 0 0 0 0 1e12 0 1.0 host 1.0\n");
  std::vector<std::string> args{"map"};
  for (const std::string& a : c.extra) {
    // "LOG" is the simulated log; bare file names live in the test folder.
    if (a == "LOG")
      args.push_back(log());
    else if (a.find('.') != std::string::npos && a.find_first_of("0123456789-") != 0)
      args.push_back(path(a));
    else
      args.push_back(a);
  }
  args.push_back("-o");
  args.push_back(path("bad-" + c.name));
  const auto r = runCli(args);
  EXPECT_EQ(r.exit_code, 1) << r.err;
  EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
  EXPECT_NE(r.err.find(c.expect), std::string::npos) << r.err;
  EXPECT_TRUE(noFilesWithPrefix("bad-" + c.name)) << c.name;
}

INSTANTIATE_TEST_SUITE_P(
    Cases, CliMapBad,
    ::testing::Values(
        BadMapCase{"ZeroResolution", {"LOG", "--resolution", "0"}, "resolution"},
        BadMapCase{"NegativeResolution", {"LOG", "--resolution", "-0.05"}, "resolution"},
        BadMapCase{"AbsurdResolution",
                   {"LOG", "--resolution", "1e-9"},
                   "resolution: must be between 0.0001 and 100 m (got 1e-09)"},
        BadMapCase{"OverCellBudget", {"LOG", "--resolution", "0.001", "--cell-budget", "1000000"}, "budget"},
        BadMapCase{"NegativeSurfaceGuard", {"LOG", "--surface-guard", "-1"}, "surface_guard"},
        BadMapCase{"ZeroThreads", {"LOG", "--threads", "0"}, "threads"},
        BadMapCase{"TrajectoryMissingTimestamp", {"LOG", "--poses", "short-traj.txt"}, "timestamp"},
        BadMapCase{"MaskOfAnotherSize", {"LOG", "--prior", "tiny-mask.pgm"}, "size"},
        BadMapCase{"LogWithoutPoses", {"noposes.log"}, "has no odometry pose"},
        BadMapCase{
            "PoseAbsurdlyFar", {"farpose.log"}, "farpose.log: scan 1 (time 1.000000) pose: laser pose is absurdly far"},
        BadMapCase{"MissingLog", {"does-not-exist.log"}, "no such file"}),
    [](const auto& info) { return info.param.name; });

}  // namespace
}  // namespace lidar2d
