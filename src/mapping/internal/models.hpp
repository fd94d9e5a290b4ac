#pragma once
// The three map models behind OccupancyMap (makeMap), each in its own source file. Private to the
// mapping module.

#include <memory>

#include "lidar2d/mapping/occupancy_map.hpp"

namespace lidar2d::mapping::internal {

std::unique_ptr<OccupancyMap> makeLogOddsMap(const MapOptions& options);
std::unique_ptr<OccupancyMap> makeCountMap(const MapOptions& options);
std::unique_ptr<OccupancyMap> makeTsdfMap(const MapOptions& options);

}  // namespace lidar2d::mapping::internal
