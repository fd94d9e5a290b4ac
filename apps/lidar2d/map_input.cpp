#include "map_input.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <charconv>
#include <cmath>
#include <iostream>
#include <system_error>
#include <vector>

#include "commands.hpp"

namespace lidar2d::cli {

io::MapFile readMapChecked(const std::string& path, const BareMapOptions& bare) {
  if (!io::isMapImage(path)) {
    if (bare.given())
      throw CLI::ValidationError(bare.resolution_flag + "/" + bare.origin_flag + "/" + bare.rows_up_flag,
                                 "apply to a bare map image; " + path + " states its own in its YAML");
    return io::readMap(path);
  }
  if (!bare.resolution)
    throw CLI::ValidationError(bare.resolution_flag, path + " is a bare image: give its cell size, " +
                                                         bare.resolution_flag + " M (and " + bare.origin_flag +
                                                         " X,Y,YAW)");
  io::MapYaml y;
  y.resolution = *bare.resolution;
  y.origin = bare.origin.value_or(SE2());
  y.rows_up = bare.rows_up;
  return io::readMapImage(path, y);
}

nlohmann::json reportMirrorCheck(const std::optional<localization::MirrorCheckResult>& check, const std::string& map,
                                 std::size_t unplaced, std::size_t scans) {
  if (!check) return nullptr;
  if (check->mirrored())
    std::cerr << fmt::format(
        "lidar2d: warning: {}: {} of {} scans could not be placed, but {} of {} tried as their mirror image were: "
        "the scans and the map are mirror images of each other. Either the laser is mounted the other way up from "
        "how it is read (an upside-down laser: --laser-mount X,Y,THETA,flipped; docs/file-formats.md, laser "
        "mounting) or the map image is mirrored (a bare image whose first row is its lowest y: --image-rows-up)\n",
        map, unplaced, scans, check->placed, check->tried);
  return {{"tried", check->tried}, {"placed", check->placed}, {"mirrored", check->mirrored()}};
}

void addBareMapOptions(CLI::App* sub, BareMapOptions& bare, const std::string& what) {
  sub->add_option_function<double>(
         bare.resolution_flag, [&bare](double r) { bare.resolution = r; },
         what + " as a bare PGM/PNG image (no YAML): its cell size [m] (required then; a YAML states its own)")
      ->check(positiveNumber());
  const std::string flag = bare.origin_flag;
  sub->add_option_function<std::string>(
         flag,
         [&bare, flag](const std::string& v) {
           // Three comma-separated finite numbers, as the YAML's origin: x, y [m], yaw [rad].
           std::vector<double> xs;
           std::size_t start = 0;
           while (start <= v.size()) {
             const std::size_t end = std::min(v.find(',', start), v.size());
             const std::string field = v.substr(start, end - start);
             double x = 0.0;
             const auto [ptr, ec] = std::from_chars(field.data(), field.data() + field.size(), x);
             if (field.empty() || ec != std::errc() || ptr != field.data() + field.size() || !std::isfinite(x))
               throw CLI::ValidationError(flag, "'" + field + "' is not a finite number (expected X,Y,YAW)");
             xs.push_back(x);
             start = end + 1;
           }
           if (xs.size() != 3)
             throw CLI::ValidationError(flag, "expected 3 comma-separated values X,Y,YAW, got " + std::to_string(xs.size()));
           bare.origin = SE2(xs[0], xs[1], xs[2]);
         },
         what + " as a bare image: world pose of its lower-left pixel's corner, x,y [m],yaw [rad], as a map_server "
                "YAML's origin (default 0,0,0)")
      ->type_name("X,Y,YAW");
  sub->add_flag(bare.rows_up_flag, bare.rows_up,
                what +
                    " as a bare image stored with its first row at the lowest y (an array written as it is "
                    "indexed, row = y); a map_server image's first row is its top");
}

}  // namespace lidar2d::cli
