#pragma once
/// @file
/// How a 2D laser sits on the robot: a full 3D rigid mounting, and its projection onto the robot's
/// plane, which is all the 2D pipeline uses.
///
/// The scan of a laser mounted upside down (roll or pitch of 180 degrees) is the mirror image of
/// what an upright laser at the same place sees: a beam at angle a in the laser frame points at -a
/// (roll pi) or pi - a (pitch pi) in the robot frame, and its beams run clockwise. lidar2d applies
/// that mirror once, where a frame is made (`LaserMount::project`): the frame's scan is given in the
/// *upright laser frame* (z up, the robot's), so `Frame::T_robot_laser` is an ordinary SE2 and every
/// consumer turns ranges into robot-frame points with `LaserScan::toPoints(T_robot_laser)` and nothing
/// else. Frames: robot (x forward, y left, z up), laser (the scanner's own; its beams lie in its xy
/// plane), upright laser (the laser frame turned over when upside down, so that its z is the robot's).

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <numbers>

#include "lidar2d/core/laser_scan.hpp"
#include "lidar2d/core/se2.hpp"

namespace lidar2d {

/// A laser mounting: the laser frame in the robot frame, with its planar projection.
///
/// Projection onto the robot's plane (exact when the scan plane is parallel to the floor, i.e.
/// roll and pitch each 0 or 180 degrees): with R the rotation robot <- laser and t the translation,
/// - upside down when R(2,2) < 0 (the laser's z axis points down);
/// - yaw = atan2(R(1,0), R(0,0)), the heading of the laser's x axis in the robot's plane (for a
///   tilted laser, the rotation part of the polar decomposition of R's in-plane block, which centres
///   the bearing error of `project` on zero);
/// - position (t.x, t.y); the height t.z plays no role;
/// - tilt = the angle between the scan plane and the robot's plane, acos(|R(2,2)|), in [0, pi/2].
/// A tilted mounting (tilt > 0) is projected beam by beam (see `project`).
class LaserMount {
 public:
  /// Tilts up to this angle can be projected onto the floor plane; a steeper laser scans the floor
  /// or the ceiling rather than the walls, and `project` refuses it [rad].
  static constexpr double kMaxProjectableTilt = std::numbers::pi / 4;

  /// Identity: an upright laser at the robot's origin, looking forward.
  LaserMount() = default;

  /// A laser whose scan plane is the robot's plane: the upright laser frame's pose `T_robot_laser`
  /// and whether the laser is upside down. Throws `lidar2d::Error` (kInvalidArgument, field
  /// "laser_mount") when the pose is not finite.
  static LaserMount planar(const SE2& T_robot_laser, bool upside_down = false);

  /// Any rigid mounting: the laser frame's origin [m] and orientation in the robot frame. The
  /// quaternion is normalized; tf2's tolerance applies (|q|^2 within 0.01 of 1). Throws
  /// `lidar2d::Error` (kInvalidArgument, field "laser_mount") for a non-finite translation or
  /// quaternion, or a quaternion too far from unit length.
  static LaserMount fromTransform(const Eigen::Vector3d& t_robot_laser, const Eigen::Quaterniond& q_robot_laser);

  /// `fromTransform` with the rotation given as roll, pitch, yaw about the robot's fixed x, y, z axes
  /// (R = Rz(yaw) * Ry(pitch) * Rx(roll), as tf and URDF's rpy) [m, rad].
  static LaserMount fromRollPitchYaw(double x, double y, double z, double roll, double pitch, double yaw);

  /// Pose of the upright laser frame in the robot's plane (what `Frame::T_robot_laser` holds).
  const SE2& T_robot_laser() const { return T_robot_laser_; }
  /// Whether the laser is upside down: its scans are mirrored images of an upright laser's.
  bool upsideDown() const { return upside_down_; }
  /// Angle between the scan plane and the robot's plane [rad], in [0, pi/2]; 0 for `planar`.
  double tilt() const { return tilt_; }
  /// The full 3D mounting: translation [m] and rotation (robot <- laser).
  const Eigen::Vector3d& translation3() const { return t_; }
  const Eigen::Matrix3d& rotation3() const { return R_; }

  /// This mounting with its tilt dropped: the same position, yaw and upside-down flag, as if the
  /// scan plane were exactly parallel to the floor (for a tilt within the readers' tolerance).
  LaserMount levelled() const { return planar(T_robot_laser_, upside_down_); }

  /// The scan `raw` (as the laser recorded it, in the laser frame) as seen in the upright laser
  /// frame, so that `toPoints(T_robot_laser())` gives its points in the robot frame.
  /// - Upside down: the mirror image. Beam i of `raw` becomes beam n-1-i (ranges and intensities
  ///   reversed) and the angles are negated, so angle_min' = -angleMax() with the same increment:
  ///   the beams keep running counter-clockwise when `raw`'s did. Exact.
  /// - Tilted (tilt() > 0): each valid range is shortened to its horizontal part, r * |d_xy| where
  ///   d = R * (cos a, sin a, 0) is the beam's direction in the robot frame; the beams keep their
  ///   uniform bearings (yaw -+ a), which differ from the true bearings atan2(d_y, d_x) by at most
  ///   about tilt^2 / 4 rad (0.03 deg at 2 degrees, 0.44 deg at 10). A valid range that falls to
  ///   range_min or below becomes invalid; invalid beams (no return, NaN) stay as they were.
  /// - Otherwise `raw` unchanged.
  /// Throws `lidar2d::Error` (kInvalidArgument, field "laser_mount") when tilt() exceeds
  /// kMaxProjectableTilt.
  LaserScan project(LaserScan raw) const;

 private:
  Eigen::Vector3d t_ = Eigen::Vector3d::Zero();
  Eigen::Matrix3d R_ = Eigen::Matrix3d::Identity();
  SE2 T_robot_laser_;
  bool upside_down_ = false;
  double tilt_ = 0.0;
};

}  // namespace lidar2d
