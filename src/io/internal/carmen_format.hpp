#pragma once
// Conventions shared by the CARMEN reader and writer (not installed).

namespace lidar2d::io::internal {

/// First line of every log written by `CarmenWriter`. When the reader (with CarmenPoses::kAuto)
/// finds it before the first laser message, it reads the log with the writer's own rules: the
/// ROBOTLASER1 robot pose is the odometry exactly when an ODOM line with the same timestamp follows
/// the laser line, and truth comes only from TRUEPOS lines. This is what makes a frame without
/// odometry read back without odometry, instead of with a made-up zero pose.
inline constexpr const char* kCarmenWriterMarker = "# lidar2d CARMEN log";

/// Host name written by `CarmenWriter` in the `host` field of its messages.
inline constexpr const char* kCarmenWriterHost = "lidar2d";

}  // namespace lidar2d::io::internal
