// LaserScan: invariants, invalid-beam recognition, and conversion to points.

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <numbers>

#include "lidar2d/core/error.hpp"
#include "lidar2d/core/laser_scan.hpp"

namespace lidar2d {
namespace {

LaserScanFields fourBeams() {
  LaserScanFields f;
  f.time = 12.5;
  f.angle_min = -std::numbers::pi / 2;
  f.angle_increment = std::numbers::pi / 2;
  f.range_min = 0.1;
  f.range_max = 30.0;
  f.ranges = {1.0, 2.0, 3.0, 4.0};
  return f;
}

TEST(LaserScan, InvalidBeamsAreRecognisedOnce) {
  auto f = fourBeams();
  f.ranges = {std::nan(""), std::numeric_limits<double>::infinity(), 0.05, 30.0};
  f.ranges.push_back(-1.0);
  f.ranges.push_back(2.0);
  f.angle_increment = 0.1;
  const auto s = LaserScan::create(f);
  EXPECT_EQ(s.numValid(), 1u);
  for (std::size_t i = 0; i < 5; ++i) EXPECT_FALSE(s.isValid(i)) << i;
  EXPECT_TRUE(s.isValid(5));
  EXPECT_EQ(s.validIndices(), std::vector<std::size_t>{5});
}

TEST(LaserScan, PointsInLaserAndRobotFrames) {
  const auto s = LaserScan::create(fourBeams());
  const Points2 p = s.toPoints();
  ASSERT_EQ(p.size(), 4u);
  EXPECT_NEAR(p[0].x(), 0.0, 1e-12);
  EXPECT_NEAR(p[0].y(), -1.0, 1e-12);
  EXPECT_NEAR(p[1].x(), 2.0, 1e-12);
  EXPECT_NEAR(p[2].y(), 3.0, 1e-12);
  // Laser mounted 0.2 m ahead, turned left by 90 degrees: beam 1 (straight ahead of the laser)
  // points along the robot's +y.
  const Points2 r = s.toPoints(SE2(0.2, 0.0, std::numbers::pi / 2));
  EXPECT_NEAR(r[1].x(), 0.2, 1e-12);
  EXPECT_NEAR(r[1].y(), 2.0, 1e-12);
  EXPECT_NEAR(s.fieldOfView(), 2 * std::numbers::pi, 1e-12);
  EXPECT_NEAR(s.angleMax(), std::numbers::pi, 1e-12);
}

TEST(LaserScan, ViolatedInvariantsNameTheField) {
  auto expectField = [](LaserScanFields f, const std::string& field) {
    try {
      (void)LaserScan::create(std::move(f));
      ADD_FAILURE() << "no error for " << field;
    } catch (const Error& e) {
      EXPECT_EQ(e.where().field, field) << e.what();
      EXPECT_EQ(e.kind(), ErrorKind::kBadInput);
    }
  };
  auto f = fourBeams();
  f.ranges.clear();
  expectField(f, "ranges");
  f = fourBeams();
  f.angle_increment = 0;
  expectField(f, "angle_increment");
  f = fourBeams();
  f.angle_increment = std::nan("");
  expectField(f, "angle_increment");
  f = fourBeams();
  f.angle_increment = 4.0;  // 4 beams over 12 rad
  expectField(f, "angle_increment");
  f = fourBeams();
  f.range_max = 0.05;
  expectField(f, "range_max");
  f = fourBeams();
  f.range_min = -1;
  expectField(f, "range_min");
  f = fourBeams();
  f.intensities = {1, 2};
  expectField(f, "intensities");
  f = fourBeams();
  f.time = std::numeric_limits<double>::infinity();
  expectField(f, "time");
  f = fourBeams();
  f.angle_min = std::nan("");
  expectField(f, "angle_min");
}

}  // namespace
}  // namespace lidar2d
