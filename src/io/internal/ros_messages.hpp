#pragma once
// Plain copies of the three ROS message types the bag readers need (sensor_msgs/LaserScan,
// nav_msgs/Odometry, tf2_msgs/TFMessage), and bounds-checked decoders for both wire formats:
// ROS1 serialization (packed little-endian, no padding; strings are uint32 length + bytes) and
// ROS2 CDR (a 4-byte encapsulation header, then fields aligned to their own size counted from the
// end of that header; strings are uint32 length including a terminating NUL).
//
// Why our own decoders instead of ros::serialization / the generated message headers: the
// generated ROS1 headers do not compile as C++20 (they use std::allocator<void>::rebind, removed in
// C++20), there is no ROS2 library on Debian 12 at all, and ros::serialization resizes an array to
// the length stated in the message before checking the buffer, so a corrupt length can allocate
// gigabytes. Every read here is checked against the blob size and a bad blob is a lidar2d::Error
// naming the file, the message and the field.

#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

namespace lidar2d::io::internal {

/// Wire format of a serialized message.
enum class RosWire {
  kRos1,  ///< ROS1 serialization (bag format 1.2 / 2.0)
  kCdr,   ///< ROS2 CDR with encapsulation header (little- or big-endian)
};

/// Identifies a message in errors: the file, and e.g. "message 17 on /scan".
struct RosMessageRef {
  std::string file;
  std::string message;
};

/// A ROS time as integer nanoseconds since the epoch (exact for both sec/nsec pairs).
using RosNanos = std::int64_t;

/// Seconds of a ROS time, computed as sec + nsec * 1e-9 like rospy's Time.to_sec().
double rosSeconds(RosNanos t);

struct RosLaserScanMsg {
  RosNanos stamp = 0;  ///< header.stamp
  std::string frame_id;  ///< header.frame_id, leading '/' removed
  float angle_min = 0, angle_max = 0, angle_increment = 0, time_increment = 0, scan_time = 0;
  float range_min = 0, range_max = 0;
  std::vector<float> ranges;
  std::vector<float> intensities;
};

/// A 3D rigid transform as stored in ROS messages (translation [m], unit quaternion).
struct RosTransform3 {
  double tx = 0, ty = 0, tz = 0;
  double qx = 0, qy = 0, qz = 0, qw = 1;
};

struct RosOdometryMsg {
  RosNanos stamp = 0;  ///< header.stamp
  std::string frame_id;        ///< header.frame_id (the odometry frame), leading '/' removed
  std::string child_frame_id;  ///< the robot frame, leading '/' removed
  RosTransform3 pose;          ///< pose.pose: the child frame in the odometry frame
};

struct RosTransformStamped {
  RosNanos stamp = 0;
  std::string parent;  ///< header.frame_id, leading '/' removed
  std::string child;   ///< child_frame_id, leading '/' removed
  RosTransform3 transform;  ///< the child frame in the parent frame
};

/// Decoders. `bytes` is the serialized message (for CDR including the encapsulation header).
/// Throw lidar2d::Error (kBadInput; kUnsupported for an unknown CDR encapsulation) naming
/// `ref.file`, `ref.message` and the field whose read failed.
RosLaserScanMsg decodeLaserScan(std::span<const std::uint8_t> bytes, RosWire wire, const RosMessageRef& ref);
RosOdometryMsg decodeOdometry(std::span<const std::uint8_t> bytes, RosWire wire, const RosMessageRef& ref);
std::vector<RosTransformStamped> decodeTfMessage(std::span<const std::uint8_t> bytes, RosWire wire,
                                                 const RosMessageRef& ref);

/// Removes leading '/' from a tf frame name (tf2 ignores them; ROS1 bags often carry "/laser").
std::string normalizeFrameId(std::string frame);

}  // namespace lidar2d::io::internal
