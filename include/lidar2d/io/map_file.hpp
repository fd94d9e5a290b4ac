#pragma once
/// @file
/// ROS map_server maps: a YAML file (`image`, `resolution`, `origin: [x, y, yaw]`, `negate`,
/// `occupied_thresh`, `free_thresh`, `mode`) next to an 8-bit grey image (PGM P5 or P2; PNG and other
/// formats through OpenCV). The reader interprets pixels exactly as ROS1 map_server's image_loader
/// does; the writer writes what map_saver writes (trinary PGM: 254 free, 0 occupied, 205 unknown,
/// `free_thresh: 0.196` so that 205 reads back as unknown), so nav2 and rviz load our maps unchanged.

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "lidar2d/core/occupancy_image.hpp"
#include "lidar2d/core/se2.hpp"

namespace lidar2d::io {

/// How map_server turns pixels into occupancy.
enum class MapMode {
  kTrinary,  ///< occupied (100), free (0) or unknown (-1)
  kScale,    ///< like trinary, but values between the thresholds become 1..99
  kRaw,      ///< the pixel value itself (values above 100 read as unknown)
};

/// The YAML fields of a map file.
struct MapYaml {
  std::string image;               ///< image path as written in the YAML (relative to the YAML's folder)
  double resolution = 0.0;         ///< [m/cell]
  SE2 origin;                      ///< [x, y, yaw] of the lower-left pixel [m, m, rad]
  bool negate = false;             ///< true: white is occupied
  double occupied_thresh = 0.65;   ///< p > occupied_thresh -> occupied
  double free_thresh = 0.196;      ///< p < free_thresh -> free
  MapMode mode = MapMode::kTrinary;
  /// Not a map_server key (readMap leaves it false; readMapImage takes it): the image's first row
  /// is its lowest y, as an array written as it is indexed (row = y) is stored. map_server's first
  /// row is the top. Read the other way, such a map is the room's mirror image.
  bool rows_up = false;
};

/// A map read from disk.
struct MapFile {
  OccupancyImage map;
  MapYaml yaml;
  std::string image_path;  ///< resolved image path that was read
};

/// Reads a map_server YAML and its image. Missing `negate`, `occupied_thresh`, `free_thresh`, `mode`
/// take the defaults of `MapYaml`; `image`, `resolution` and `origin` are required. Pixel p of
/// grey value v (the mean of the colour channels) has occupancy probability (255 - v) / 255
/// (v / 255 with negate); it is occupied when p > occupied_thresh, free when p < free_thresh, and
/// otherwise unknown (trinary) or scaled (scale mode). Throws `lidar2d::Error` naming the file and
/// field: missing or malformed keys, resolution <= 0, thresholds outside 0 <= free < occupied <= 1,
/// missing image, wrong magic, truncated data, more than 10^9 pixels, more than 8 bits per pixel.
MapFile readMap(const std::string& yaml_path);

/// Whether the file at `path` starts like an image (PNG signature, or a PGM's "P5"/"P2") rather
/// than a YAML. False for a file that cannot be read (readMap then reports it).
bool isMapImage(const std::string& path);

/// Reads a bare map image (PGM or PNG, no YAML: a map drawn or exported by hand) as readMap reads
/// the image of a YAML holding `yaml`'s fields (its `image` is ignored), its rows in the order
/// `yaml.rows_up` says. The resolution and origin
/// are checked as readMap checks them, with the error naming `image_path` and the field
/// ("resolution", "origin"). Throws `lidar2d::Error` as readMap does.
MapFile readMapImage(const std::string& image_path, const MapYaml& yaml);

/// Writes `map` as a trinary map_server map: the PGM at `image_path` (default: the YAML path with
/// its extension replaced by ".pgm") and the YAML at `yaml_path`, whose `image` is the PGM's path
/// relative to the YAML's folder. Cells 0..`free_max` become 254 (free), `occupied_min`..100 become
/// 0 (occupied), everything else 205 (unknown). Both files are written atomically; throws
/// `lidar2d::Error` (kIo) when they cannot be written. `comment` (may hold several lines) is written
/// at the top of the YAML as `#` lines, which map_server and rviz ignore.
void writeMap(const std::string& yaml_path, const OccupancyImage& map, const std::string& image_path = {},
              int free_max = 25, int occupied_min = 65, const std::string& comment = {});

}  // namespace lidar2d::io
