// eval::PoseTolerance and eval::LocalizationTally: the figures of `lidar2d localize --json`.

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <optional>

#include "lidar2d/eval/localization_score.hpp"

namespace lidar2d::eval {
namespace {

constexpr double kDeg = std::numbers::pi / 180.0;

TEST(PoseTolerance, AcceptsErrorsWithinBothBoundsInclusive) {
  const PoseTolerance tol{0.3, 5.0 * kDeg};
  EXPECT_TRUE(tol.accepts(SE2(0.0, 0.0, 0.0)));
  EXPECT_TRUE(tol.accepts(SE2(0.3, 0.0, 0.0)));
  EXPECT_TRUE(tol.accepts(SE2(0.0, -0.2, -5.0 * kDeg)));
  EXPECT_FALSE(tol.accepts(SE2(0.25, 0.25, 0.0)));  // 0.354 m
  EXPECT_FALSE(tol.accepts(SE2(0.0, 0.0, 5.1 * kDeg)));
  EXPECT_FALSE(tol.accepts(SE2(std::nan(""), 0.0, 0.0)));
}

TEST(LocalizationTally, CountsSuccessPrecisionAndDeclines) {
  LocalizationTally t;
  const SE2 truth(1.0, 2.0, 0.5);
  t.add(truth * SE2(0.1, 0.0, 0.0), truth, std::nullopt);  // right
  t.add(truth * SE2(1.0, 0.0, 0.0), truth, std::nullopt);  // wrong
  t.add(std::nullopt, truth, std::nullopt);                 // declined
  t.add(truth, std::nullopt, std::nullopt);                 // answered, no truth
  EXPECT_EQ(t.scans, 4u);
  EXPECT_EQ(t.answered, 3u);
  EXPECT_EQ(t.declined, 1u);
  EXPECT_EQ(t.with_truth, 3u);
  EXPECT_EQ(t.correct, 1u);
  EXPECT_DOUBLE_EQ(t.successRate(), 1.0 / 3.0);
  EXPECT_DOUBLE_EQ(t.precision(), 1.0 / 3.0);
  EXPECT_TRUE(std::isnan(t.odometryConsistency()));
}

TEST(LocalizationTally, OdometryConsistencyUsesConsecutiveAnsweredScansWithOdometry) {
  LocalizationTally t;
  // The estimates move 1 m forward each scan in a rotated world frame; odometry agrees on the
  // first step and disagrees by 0.5 m on the second; the third scan is declined, so the fourth
  // has no pair; the fifth pairs with the fourth.
  const SE2 T_world_odom(5.0, -3.0, 1.0);
  auto pose = [&](double x) { return T_world_odom * SE2(x, 0.0, 0.0); };
  t.add(pose(0.0), std::nullopt, SE2(0.0, 0.0, 0.0));
  t.add(pose(1.0), std::nullopt, SE2(1.0, 0.0, 0.0));   // consistent
  t.add(pose(2.0), std::nullopt, SE2(2.5, 0.0, 0.0));   // 0.5 m off
  t.add(std::nullopt, std::nullopt, SE2(3.5, 0.0, 0.0));  // declined: no pair
  t.add(pose(4.0), std::nullopt, SE2(4.5, 0.0, 0.0));   // previous declined: no pair
  t.add(pose(5.0), std::nullopt, std::nullopt);           // no odometry: no pair
  t.add(pose(6.0), std::nullopt, SE2(6.5, 0.0, 0.0));   // previous without odometry: no pair
  t.add(pose(7.0), std::nullopt, SE2(7.5, 0.0, 0.1));   // 5.7 deg off
  EXPECT_EQ(t.odometry_pairs, 3u);
  EXPECT_EQ(t.odometry_consistent, 1u);
  EXPECT_TRUE(std::isnan(t.successRate()));
}

}  // namespace
}  // namespace lidar2d::eval
