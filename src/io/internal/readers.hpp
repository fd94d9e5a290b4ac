#pragma once
// Factories of the concrete readers; only open_log.cpp and the tests call them directly.

#include <memory>
#include <string>
#include <vector>

#include "lidar2d/core/error.hpp"
#include "lidar2d/core/laser_mount.hpp"
#include "lidar2d/io/frame_source.hpp"

namespace lidar2d::io::internal {

std::unique_ptr<FrameSource> openCarmen(const std::string& path, const ReaderOptions& options);
std::unique_ptr<FrameSource> openRosbag1(const std::string& path, const ReaderOptions& options);
std::unique_ptr<FrameSource> openRosbag2(const std::string& path, const ReaderOptions& options);
/// A range table: `files` (ReaderOptions::range_table, or the three files of a folder).
std::unique_ptr<FrameSource> openRangeTable(const RangeTableFiles& files);
/// The three files of a range table folder (poses.txt, angles.txt, ranges.txt).
RangeTableFiles rangeTableFolder(const std::string& dir);

/// The mounting frames get from `mount` (described as `what`, e.g. "base_link -> laser from
/// /tf_static") under ReaderOptions' tilt rule: level within `options.max_laser_tilt_deg` (tilt
/// dropped); beyond it projected when `options.allow_tilted_laser`, with a note in `warnings`;
/// else a kBadInput error at `where`. Also refuses tilts beyond LaserMount::kMaxProjectableTilt.
LaserMount applyTiltRule(const LaserMount& mount, const ReaderOptions& options, const ErrorLocation& where,
                         const std::string& what, std::vector<std::string>& warnings);
/// Fills the informational mounting fields of `frame` and its scan from `mount` (the result of
/// applyTiltRule): the scan projected, T_robot_laser, laser_upside_down and laser_tilt_rad.
void mountFrame(Frame& frame, const LaserMount& mount);

}  // namespace lidar2d::io::internal
