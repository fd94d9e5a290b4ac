#pragma once
// Factories of the concrete readers; only open_log.cpp and the tests call them directly.

#include <memory>
#include <string>

#include "lidar2d/io/frame_source.hpp"

namespace lidar2d::io::internal {

std::unique_ptr<FrameSource> openCarmen(const std::string& path, const ReaderOptions& options);
std::unique_ptr<FrameSource> openRosbag1(const std::string& path, const ReaderOptions& options);
std::unique_ptr<FrameSource> openRosbag2(const std::string& path, const ReaderOptions& options);

}  // namespace lidar2d::io::internal
