#pragma once
// Shared pieces of the dataset benchmark.

#include <string>
#include <vector>

#include "lidar2d/core/frame.hpp"

namespace lidar2d::bench {

/// Reads every frame of a log into memory (so that timings exclude parsing).
std::vector<Frame> loadFrames(const std::string& path);

void runMapBenchmark(const std::string& data_dir);

}  // namespace lidar2d::bench
