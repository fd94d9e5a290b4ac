#pragma once
/// @file
/// Writes frames as a CARMEN text log that lidar2d's CARMEN reader reads back to equal frames.
/// Each frame becomes a `ROBOTLASER1` line (which keeps the start angle, field of view, angular
/// resolution, max range and the laser mounting pose; its robot pose is the odometry), followed by
/// an `ODOM` line when the frame has odometry and a `TRUEPOS` line (truth, then odometry) when it
/// has truth. Written atomically: nothing appears at `path` until `commit()`.

#include <memory>
#include <string>

#include "lidar2d/core/frame.hpp"

namespace lidar2d::io {

class CarmenWriter {
 public:
  /// Throws `lidar2d::Error` (kIo) when `path` cannot be written.
  explicit CarmenWriter(const std::string& path);
  ~CarmenWriter();
  CarmenWriter(const CarmenWriter&) = delete;
  CarmenWriter& operator=(const CarmenWriter&) = delete;

  /// Adds a `# comment` line (e.g. how the log was made).
  void comment(const std::string& text);
  /// Appends one frame. Ranges are written with millimetre precision or better; invalid beams at or
  /// beyond range_max (and +inf) as the scan's range_max (CARMEN's "no return"), the other invalid
  /// beams (error readings: 0, at or below range_min, -inf, NaN) as 0.
  void write(const Frame& frame);
  /// Finishes the file and renames it into place. Throws `lidar2d::Error` (kIo) on failure.
  void commit();

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace lidar2d::io
