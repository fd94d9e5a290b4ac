#include "lidar2d/core/laser_mount.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <utility>

#include "lidar2d/core/error.hpp"

namespace lidar2d {

namespace {

Error mountError(const std::string& message) { return invalidArgument(message, {"", 0, "laser_mount"}); }

}  // namespace

LaserMount LaserMount::planar(const SE2& T_robot_laser, bool upside_down) {
  if (!T_robot_laser.isFinite()) throw mountError("laser mounting pose must be finite");
  LaserMount m;
  m.t_ = Eigen::Vector3d(T_robot_laser.x(), T_robot_laser.y(), 0.0);
  // Upside down: turned over about the upright frame's x axis (roll pi), which is where the
  // mirror a -> -a comes from.
  m.R_ = Eigen::AngleAxisd(T_robot_laser.theta(), Eigen::Vector3d::UnitZ()).toRotationMatrix();
  if (upside_down) m.R_ = m.R_ * Eigen::Vector3d(1.0, -1.0, -1.0).asDiagonal();
  m.T_robot_laser_ = T_robot_laser;
  m.upside_down_ = upside_down;
  m.tilt_ = 0.0;
  return m;
}

LaserMount LaserMount::fromTransform(const Eigen::Vector3d& t_robot_laser, const Eigen::Quaterniond& q_robot_laser) {
  if (!t_robot_laser.allFinite()) throw mountError("laser mounting translation must be finite");
  if (!q_robot_laser.coeffs().allFinite()) throw mountError("laser mounting rotation must be finite");
  // tf2 (BufferCore::setTransform) refuses quaternions whose squared norm is off by more than 0.01.
  const double n2 = q_robot_laser.squaredNorm();
  if (std::abs(n2 - 1.0) > 0.01)
    throw mountError(fmt::format("laser mounting rotation quaternion ({:g}, {:g}, {:g}, {:g}) is not of unit length "
                                 "(norm {:g})",
                                 q_robot_laser.x(), q_robot_laser.y(), q_robot_laser.z(), q_robot_laser.w(), std::sqrt(n2)));
  LaserMount m;
  m.t_ = t_robot_laser;
  m.R_ = q_robot_laser.normalized().toRotationMatrix();
  const double zz = m.R_(2, 2);
  m.upside_down_ = zz < 0.0;
  m.tilt_ = std::acos(std::clamp(std::abs(zz), 0.0, 1.0));
  // Yaw: the rotation part of the polar decomposition of the in-plane block A = R(0:2, 0:2) (with
  // the y column negated when upside down), atan2(A10 - A01, A00 + A11). For a level laser it is
  // exactly the heading of the laser's x axis, atan2(R10, R00). For a tilted one A = Rz(b) *
  // diag(1, cos tilt) * Rz(c), and this yaw (b + c) centres the bearing error of `project`'s uniform
  // bearings on zero (about +-tilt^2/4), where the x axis's heading would put it anywhere up to
  // twice that.
  const double s = m.upside_down_ ? -1.0 : 1.0;
  const double yaw = std::atan2(m.R_(1, 0) - s * m.R_(0, 1), m.R_(0, 0) + s * m.R_(1, 1));
  m.T_robot_laser_ = SE2(m.t_.x(), m.t_.y(), yaw);
  return m;
}

LaserMount LaserMount::fromRollPitchYaw(double x, double y, double z, double roll, double pitch, double yaw) {
  if (!std::isfinite(roll) || !std::isfinite(pitch) || !std::isfinite(yaw))
    throw mountError("laser mounting angles must be finite");
  const Eigen::Quaterniond q = Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()) *
                               Eigen::AngleAxisd(pitch, Eigen::Vector3d::UnitY()) *
                               Eigen::AngleAxisd(roll, Eigen::Vector3d::UnitX());
  return fromTransform(Eigen::Vector3d(x, y, z), q);
}

LaserScan LaserMount::project(LaserScan raw) const {
  if (tilt_ == 0.0 && !upside_down_) return raw;
  if (tilt_ > kMaxProjectableTilt)
    throw mountError(fmt::format("the laser is tilted by {:.1f} deg out of the robot's plane; at most {:.0f} deg can "
                                 "be projected onto it",
                                 tilt_ * 180.0 / std::numbers::pi, kMaxProjectableTilt * 180.0 / std::numbers::pi));
  LaserScanFields f = raw.fields();
  if (tilt_ > 0.0) {
    for (std::size_t i = 0; i < raw.size(); ++i) {
      if (!raw.isValid(i)) continue;
      const double a = raw.angle(i);
      const Eigen::Vector3d d = R_ * Eigen::Vector3d(std::cos(a), std::sin(a), 0.0);
      f.ranges[i] *= std::hypot(d.x(), d.y());
    }
  }
  if (upside_down_) {
    f.angle_min = -raw.angleMax();
    std::reverse(f.ranges.begin(), f.ranges.end());
    std::reverse(f.intensities.begin(), f.intensities.end());
  }
  return LaserScan::create(std::move(f));
}

}  // namespace lidar2d
