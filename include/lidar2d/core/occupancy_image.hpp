#pragma once
/// @file
/// The occupancy grid image every module exchanges (maps read from disk, maps exported by mapping,
/// the grids of registration, localization and the simulator): a plain value type with no file
/// format attached (io/map_file.hpp reads and writes it as a map_server map).

#include <cstdint>
#include <optional>
#include <vector>

#include <Eigen/Core>

#include "lidar2d/core/se2.hpp"

namespace lidar2d {

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

}  // namespace lidar2d
