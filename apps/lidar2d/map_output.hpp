#pragma once
// Writing an occupancy image the way every command does: map_server PGM + YAML and a PNG for people.

#include <cstdint>
#include <string>
#include <vector>

#include "lidar2d/io/map_file.hpp"

namespace lidar2d::cli {

/// PNG bytes of `map`: occupied black, free white, unknown grey; image row 0 is the top (largest y).
/// `path` only names the output in an error.
std::vector<std::uint8_t> encodeMapPng(const OccupancyImage& map, const std::string& path);

/// Writes PREFIX.pgm, PREFIX.yaml (map_server) and PREFIX.png, each atomically; returns the paths.
std::vector<std::string> writeMapFiles(const std::string& prefix, const OccupancyImage& map,
                                       const std::string& yaml_comment = {});

}  // namespace lidar2d::cli
