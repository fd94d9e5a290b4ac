#pragma once
// A map given on the command line: a map_server YAML, or a bare PGM/PNG image (a map drawn or
// exported by hand) whose resolution, origin and row order the command line states. Shared by every
// command that reads a map (localize-index, localize, track, simulate --map, map --prior); and what
// localize and track say when the scans and the map are mirror images of each other.

#include <CLI/CLI.hpp>
#include <cstddef>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>

#include "lidar2d/core/se2.hpp"
#include "lidar2d/io/map_file.hpp"
#include "lidar2d/localization/mirror_check.hpp"

namespace lidar2d::cli {

/// The command-line stand-ins for a bare image's YAML, and the names of their options.
struct BareMapOptions {
  std::string resolution_flag = "--resolution";
  std::string origin_flag = "--origin";
  std::string rows_up_flag = "--image-rows-up";
  std::optional<double> resolution;  ///< [m/cell]
  std::optional<SE2> origin;         ///< lower-left pixel's corner in the world [m, m, rad]
  /// The image's first row is its lowest y (an array written as it is indexed, row = y), where a
  /// map_server image's first row is its top: read it upside down.
  bool rows_up = false;
  /// Whether any of the options was given.
  bool given() const { return resolution || origin || rows_up; }
};

/// Adds `bare.resolution_flag`, `bare.origin_flag` and `bare.rows_up_flag` to `sub`; `what` names the map in their help
/// ("MAP", "--prior"). `bare` must outlive parsing.
void addBareMapOptions(CLI::App* sub, BareMapOptions& bare, const std::string& what);

/// The map at `path`: a map_server YAML, or, when the file starts like an image, a bare image read
/// with `bare`'s resolution and origin (default 0,0,0) as a YAML with map_server's defaults would
/// read it (with `rows_up`, the image's rows in reverse order: its first row the bottom one). A bare image without the
/// resolution, or the options with a YAML, is a usage error (CLI::ValidationError, exit 2); bad content is
/// lidar2d::Error naming the file and field.
io::MapFile readMapChecked(const std::string& path, const BareMapOptions& bare);

/// What `localize` and `track` say of their localization::MirrorCheck: nothing (null) when it did
/// not run; else its `mirror_check` JSON object ({tried, placed, mirrored}), and, when the scans and
/// the map are mirror images of each other, a warning on stderr naming `map` (`unplaced` of `scans`
/// were not placed) and how to tell which is mirrored.
nlohmann::json reportMirrorCheck(const std::optional<localization::MirrorCheckResult>& check, const std::string& map,
                                 std::size_t unplaced, std::size_t scans);

}  // namespace lidar2d::cli
