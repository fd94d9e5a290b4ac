#pragma once
// Writing an occupancy image the way every command does: map_server PGM + YAML and a PNG for people.

#include <cstdint>
#include <string>
#include <vector>

#include "lidar2d/io/atomic_file.hpp"
#include "lidar2d/io/map_file.hpp"

namespace lidar2d::cli {

/// PNG bytes of `map`: occupied black, free white, unknown grey; image row 0 is the top (largest y).
/// `path` only names the output in an error.
std::vector<std::uint8_t> encodeMapPng(const OccupancyImage& map, const std::string& path);

/// Stages NAME.pgm, NAME.yaml (map_server) and NAME.png in `outputs` and writes them there; they
/// appear with the command's other outputs at `outputs.commit()`.
void writeMapFiles(io::OutputSet& outputs, const std::string& name, const OccupancyImage& map,
                   const std::string& yaml_comment = {});

}  // namespace lidar2d::cli
