#pragma once
/// @file
/// Turning an `OccupancyMap` into a map_server image, with an optional user-drawn prior layer.

#include <string>
#include <vector>

#include "lidar2d/core/occupancy_image.hpp"
#include "lidar2d/mapping/occupancy_map.hpp"

namespace lidar2d::mapping {

/// The map's classified cells over its bounds (padded by `pad_cells`) as an OccupancyImage: -1
/// unknown, 0 free, 100 occupied; the image origin is the lower-left corner of the padded box.
/// Throws `lidar2d::Error` (kBadInput) when nothing was inserted.
OccupancyImage toOccupancyImage(const OccupancyMap& map, int pad_cells = 1);

/// Applies a prior layer: wherever `prior` says occupied (100) or free (0) it overrides `map`;
/// unknown (-1) prior cells leave the sensor's verdict. The prior is aligned by world coordinates
/// (cell centres of `map` looked up in `prior`), so it may have any extent but must have the same
/// resolution (else kBadInput naming "resolution"). Returns the number of cells overridden.
std::size_t applyPrior(OccupancyImage& map, const OccupancyImage& prior);

/// Applies a prior given as a bare image of exactly `map`'s size (row 0 = bottom row, values as in
/// OccupancyImage). Throws kBadInput naming "size" when the sizes differ.
std::size_t applyPriorSameSize(OccupancyImage& map, const std::vector<std::int8_t>& prior, int width, int height);

}  // namespace lidar2d::mapping
