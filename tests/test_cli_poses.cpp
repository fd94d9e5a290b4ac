// lidar2d poses: a log's truth or odometry as plain or TUM trajectory files, read back equal.

#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>

#include "lidar2d/io/frame_source.hpp"
#include "lidar2d/io/trajectory.hpp"
#include "support/test_support.hpp"

namespace lidar2d {
namespace {

TEST(CliPoses, TruthAndOdometryInBothFormatsReadBackEqual) {
  test::TempDir dir;
  const std::string log = (dir / "sym.log").string();
  ASSERT_EQ(test::runCli({"simulate", "--world", "symmetric", "--scans", "40", "-o", log}).exit_code, 0);
  std::vector<Frame> frames;
  auto src = io::openLog(log);
  while (auto f = src->next()) frames.push_back(std::move(*f));
  for (const std::string source : {"truth", "odometry"})
    for (const std::string format : {"plain", "tum"}) {
      const std::string out = (dir / (source + "-" + format + ".txt")).string();
      const auto r = test::runCli({"poses", log, "--source", source, "--format", format, "-o", out});
      ASSERT_EQ(r.exit_code, 0) << r.err;
      const Trajectory t = io::readTrajectory(out);
      ASSERT_EQ(t.size(), frames.size());
      for (std::size_t i = 0; i < t.size(); ++i) {
        const SE2& expected = source == "truth" ? *frames[i].T_world_robot : *frames[i].T_odom_robot;
        EXPECT_NEAR(t[i].time, frames[i].time, 1e-9);
        EXPECT_TRUE(test::IsNearPose(expected, t[i].pose, 1e-6, 1e-4)) << source << " " << format << " pose " << i;
      }
    }
}

TEST(CliPoses, LogWithoutThePosesIsBadInput) {
  test::TempDir dir;
  // A raw log: odometry but no truth.
  const std::string log = (dir / "raw.log").string();
  test::writeFile(log, "FLASER 3 1.0 2.0 3.0 0.5 0.25 0.1 0.5 0.25 0.1 10.0 host 10.0\n");
  const std::string out = (dir / "t.txt").string();
  const auto r = test::runCli({"poses", log, "--source", "truth", "-o", out});
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("has no truth pose"), std::string::npos) << r.err;
  EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1);
  EXPECT_FALSE(std::filesystem::exists(out));
  // Its odometry works.
  EXPECT_EQ(test::runCli({"poses", log, "--source", "odometry", "-o", out}).exit_code, 0);
  EXPECT_EQ(test::runCli({"poses", log, "--source", "bogus", "-o", out}).exit_code, 2);
}

}  // namespace
}  // namespace lidar2d
