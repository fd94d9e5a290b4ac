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

#include "lidar2d/core/se2.hpp"

namespace lidar2d::io {

/// An occupancy grid as map_server publishes it (nav_msgs/OccupancyGrid).
///
/// Cells are stored row by row, `cells[row * width + col]`, with **row 0 the bottom row** (smallest
/// map-frame y) and column 0 the leftmost (smallest x): the same order as OccupancyGrid.data, i.e.
/// the image flipped vertically. Cell (col, row) covers the square
/// [col * res, (col + 1) * res) x [row * res, (row + 1) * res) in the map frame, whose pose in the
/// world is `origin` (`p_world = origin * p_map`; the yaw is usually 0).
/// Values: -1 unknown, 0 (free) .. 100 (occupied).
///
/// Invariants (checked by `create`): width, height >= 1, width * height <= 10^9, resolution in
/// [kMinResolution, kMaxResolution] (the range `lidar2d map` accepts), finite origin with |x|, |y| <=
/// kMaxOriginAbs, cells.size() == width * height, every value in {-1, 0..100}. (The bounds keep
/// every derived extent and cell index finite and in range: a YAML saying `resolution: 1e308`
/// is an error, not an endless loop.)
class OccupancyImage {
 public:
  static constexpr std::int8_t kUnknown = -1;
  static constexpr std::int8_t kFree = 0;
  static constexpr std::int8_t kOccupied = 100;
  static constexpr std::uint64_t kMaxCells = 1000000000ULL;
  static constexpr double kMinResolution = 1e-4;  ///< [m]
  static constexpr double kMaxResolution = 100.0;  ///< [m]
  static constexpr double kMaxOriginAbs = 1e9;     ///< [m]

  OccupancyImage() = default;
  /// Checks the invariants above; throws `lidar2d::Error` (kInvalidArgument) naming the field.
  static OccupancyImage create(int width, int height, double resolution_m, const SE2& origin,
                               std::vector<std::int8_t> cells);
  /// A map of `width` x `height` cells all set to `value`.
  static OccupancyImage filled(int width, int height, double resolution_m, const SE2& origin,
                               std::int8_t value = kUnknown);

  int width() const { return width_; }
  int height() const { return height_; }
  double resolution() const { return resolution_; }  ///< cell side [m]
  const SE2& origin() const { return origin_; }      ///< T_world_map: pose of cell (0, 0)'s lower-left corner
  const std::vector<std::int8_t>& cells() const { return cells_; }

  /// Value of cell (col, row); precondition: inside the map (debug-checked).
  std::int8_t at(int col, int row) const;
  void set(int col, int row, std::int8_t value);
  bool contains(int col, int row) const { return col >= 0 && row >= 0 && col < width_ && row < height_; }

  /// Centre of cell (col, row) in the world frame [m].
  Eigen::Vector2d cellCenter(int col, int row) const;
  /// The cell containing world point `p_world`, or std::nullopt when it is outside the map.
  std::optional<Eigen::Vector2i> worldToCell(const Eigen::Vector2d& p_world) const;

 private:
  int width_ = 0;
  int height_ = 0;
  double resolution_ = 0.0;
  SE2 origin_;
  std::vector<std::int8_t> cells_;
};

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

/// Writes `map` as a trinary map_server map: the PGM at `image_path` (default: the YAML path with
/// its extension replaced by ".pgm") and the YAML at `yaml_path`, whose `image` is the PGM's path
/// relative to the YAML's folder. Cells 0..`free_max` become 254 (free), `occupied_min`..100 become
/// 0 (occupied), everything else 205 (unknown). Both files are written atomically; throws
/// `lidar2d::Error` (kIo) when they cannot be written. `comment` (may hold several lines) is written
/// at the top of the YAML as `#` lines, which map_server and rviz ignore.
void writeMap(const std::string& yaml_path, const OccupancyImage& map, const std::string& image_path = {},
              int free_max = 25, int occupied_min = 65, const std::string& comment = {});

}  // namespace lidar2d::io
