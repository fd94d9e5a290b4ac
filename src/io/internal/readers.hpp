#pragma once
// Factories of the concrete readers; only open_log.cpp and the tests call them directly.

#include <memory>
#include <string>

#include "lidar2d/io/frame_source.hpp"

namespace lidar2d::io::internal {

std::unique_ptr<FrameSource> openCarmen(const std::string& path, const ReaderOptions& options);
std::unique_ptr<FrameSource> openRosbag1(const std::string& path, const ReaderOptions& options);
std::unique_ptr<FrameSource> openRosbag2(const std::string& path, const ReaderOptions& options);
/// A range table: `files` (ReaderOptions::range_table, or the three files of a folder).
std::unique_ptr<FrameSource> openRangeTable(const RangeTableFiles& files);
/// The three files of a range table folder (poses.txt, angles.txt, ranges.txt).
RangeTableFiles rangeTableFolder(const std::string& dir);

}  // namespace lidar2d::io::internal
