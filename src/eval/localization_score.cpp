#include "lidar2d/eval/localization_score.hpp"

#include <cmath>
#include <limits>

namespace lidar2d::eval {
namespace {

double ratio(std::size_t a, std::size_t b) {
  return b ? static_cast<double>(a) / static_cast<double>(b) : std::numeric_limits<double>::quiet_NaN();
}

}  // namespace

bool PoseTolerance::accepts(const SE2& T_error) const {
  return T_error.translation().norm() <= max_translation_m && std::abs(T_error.theta()) <= max_rotation_rad;
}

void LocalizationTally::add(const std::optional<SE2>& T_world_robot, const std::optional<SE2>& T_world_robot_truth,
                            const std::optional<SE2>& T_odom_robot) {
  ++scans;
  if (T_world_robot) {
    ++answered;
  } else {
    ++declined;
  }
  if (T_world_robot_truth) {
    ++with_truth;
    if (T_world_robot && tolerance.accepts(T_world_robot_truth->inverse() * *T_world_robot)) ++correct;
  }
  if (T_world_robot && T_odom_robot && prev_pose_ && prev_odom_) {
    const SE2 T_odom = prev_odom_->inverse() * *T_odom_robot;
    const SE2 T_estimate = prev_pose_->inverse() * *T_world_robot;
    ++odometry_pairs;
    if (tolerance.accepts(T_odom.inverse() * T_estimate)) ++odometry_consistent;
  }
  prev_pose_ = T_world_robot;
  prev_odom_ = T_odom_robot;
}

double LocalizationTally::successRate() const { return ratio(correct, with_truth); }
double LocalizationTally::precision() const { return ratio(correct, answered); }
double LocalizationTally::odometryConsistency() const { return ratio(odometry_consistent, odometry_pairs); }

}  // namespace lidar2d::eval
