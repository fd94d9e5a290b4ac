#pragma once
// The simulated office as the localization tests use it: a map of its noise-free run at truth poses
// (as `lidar2d map` would build it) and a noisy run along the same route (5 scans per second,
// about 0.16 m apart; 361 beams, seed 7).

#include <vector>

#include "lidar2d/core/frame.hpp"
#include "lidar2d/core/occupancy_image.hpp"

namespace lidar2d::test {

struct OfficeRun {
  OccupancyImage map;
  std::vector<Frame> frames;  // noisy scans and odometry along the route
};

/// Built once per process.
const OfficeRun& officeMapAndRun();

}  // namespace lidar2d::test
