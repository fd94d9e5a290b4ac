#pragma once
/// @file
/// Sparse tiled 2D grid: fixed-size square tiles allocated on first touch, so memory grows with the
/// mapped area, never with a fixed canvas.
///
/// Cell convention (used by every grid in lidar2d): the grid's frame is the world frame; cell
/// (x, y) covers world points p with x*r <= p.x < (x+1)*r and y*r <= p.y < (y+1)*r, r = resolution.
/// Cell indices are signed, so negative coordinates need no offset; `cellOf` uses floor().

#include <fmt/format.h>

#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <memory>
#include <string>
#include <vector>

#include "lidar2d/core/error.hpp"

namespace lidar2d::mapping {

/// A cell index. Cell (x, y) has its lower-left corner at world (x * r, y * r).
struct CellIndex {
  std::int32_t x = 0;
  std::int32_t y = 0;
  friend bool operator==(const CellIndex&, const CellIndex&) = default;
};

/// Inclusive cell-index box; empty when max < min.
struct CellBox {
  CellIndex min{0, 0};
  CellIndex max{-1, -1};
  bool empty() const { return max.x < min.x || max.y < min.y; }
  std::int64_t width() const { return empty() ? 0 : std::int64_t{max.x} - min.x + 1; }
  std::int64_t height() const { return empty() ? 0 : std::int64_t{max.y} - min.y + 1; }
  bool contains(CellIndex c) const { return c.x >= min.x && c.x <= max.x && c.y >= min.y && c.y <= max.y; }
};

/// World <-> cell conversions at a fixed resolution.
class GridGeometry {
 public:
  /// Throws `lidar2d::Error` (kInvalidArgument, field "resolution") unless 1e-4 m <= resolution
  /// <= 100 m and finite.
  explicit GridGeometry(double resolution_m);
  double resolution() const { return resolution_; }
  double inverseResolution() const { return inv_resolution_; }
  /// Cell containing world point p (floor). Coordinates beyond +-2^30 cells are the caller's
  /// responsibility (grids check extents against their cell budget before touching cells).
  CellIndex cellOf(const Eigen::Vector2d& p) const {
    return {static_cast<std::int32_t>(std::floor(p.x() * inv_resolution_)),
            static_cast<std::int32_t>(std::floor(p.y() * inv_resolution_))};
  }
  /// World coordinates of the centre of cell c.
  Eigen::Vector2d centerOf(CellIndex c) const {
    return {(c.x + 0.5) * resolution_, (c.y + 0.5) * resolution_};
  }
  /// Continuous cell coordinates (cell (x, y) spans [x, x+1) x [y, y+1)).
  Eigen::Vector2d toCellCoords(const Eigen::Vector2d& p) const { return p * inv_resolution_; }

 private:
  double resolution_;
  double inv_resolution_;
};

/// Sparse grid of `Cell` values in 64 x 64 tiles. Unallocated cells read as the default value
/// given at construction. A cell budget bounds both the allocated cells and the extent the tile
/// table may cover, so absurd coordinates become an `Error` instead of an out-of-memory crash.
///
/// Concurrency: after `reserve`, threads may call `cellUnchecked` at the same time as long as no
/// two threads touch cells of the same tile (each tile is allocated by the one thread touching it,
/// and no grid-wide counter is written on allocation).
template <typename Cell>
class TiledGrid {
 public:
  static constexpr int kTileBits = 6;
  static constexpr int kTileSize = 1 << kTileBits;
  static constexpr int kTileMask = kTileSize - 1;
  static constexpr std::size_t kTileCells = std::size_t{kTileSize} * kTileSize;

  /// `cell_budget`: the most cells the grid may span (extent of the tile table) [cells].
  TiledGrid(Cell default_value, std::size_t cell_budget) : default_(default_value), budget_(cell_budget) {}
  TiledGrid(const TiledGrid&) = delete;
  TiledGrid& operator=(const TiledGrid&) = delete;
  TiledGrid(TiledGrid&&) noexcept = default;
  TiledGrid& operator=(TiledGrid&&) noexcept = default;

  /// Makes sure the tile table covers `box` (tiles are still allocated lazily). Throws
  /// `lidar2d::Error` (kBadInput, field "extent") when the covered extent would exceed the budget.
  void reserve(const CellBox& box) {
    if (box.empty()) return;
    const std::int64_t tx0 = floorTile(box.min.x), ty0 = floorTile(box.min.y);
    const std::int64_t tx1 = floorTile(box.max.x), ty1 = floorTile(box.max.y);
    if (table_w_ > 0 && tx0 >= tx0_ && ty0 >= ty0_ && tx1 < tx0_ + table_w_ && ty1 < ty0_ + table_h_) return;
    grow(tx0, ty0, tx1, ty1);
  }

  /// Mutable cell, allocating its tile on first touch. Precondition: `reserve` covered c (checked
  /// in debug builds; use `at` when unsure).
  Cell& cellUnchecked(CellIndex c) {
    const std::int64_t tx = (c.x >> kTileBits) - tx0_, ty = (c.y >> kTileBits) - ty0_;
    std::unique_ptr<Cell[]>& tile = table_[static_cast<std::size_t>(ty * table_w_ + tx)];
    if (!tile) allocate(tile);
    return tile[static_cast<std::size_t>(((c.y & kTileMask) << kTileBits) | (c.x & kTileMask))];
  }
  /// The tile `cellCached` used last. Consecutive cells of a ray mostly share a tile, so their
  /// table lookup is skipped. A tile's cells never move, so a cursor stays valid when the table
  /// grows; one cursor per thread.
  struct Cursor {
    std::int32_t tx = std::numeric_limits<std::int32_t>::min(), ty = std::numeric_limits<std::int32_t>::min();
    Cell* tile = nullptr;
  };
  /// `cellUnchecked` through a cursor (same precondition).
  Cell& cellCached(CellIndex c, Cursor& k) {
    const std::int32_t tx = c.x >> kTileBits, ty = c.y >> kTileBits;
    if (tx != k.tx || ty != k.ty) {
      k.tile = &cellUnchecked(CellIndex{tx * kTileSize, ty * kTileSize});  // the tile's first cell
      k.tx = tx;
      k.ty = ty;
    }
    return k.tile[static_cast<std::size_t>(((c.y & kTileMask) << kTileBits) | (c.x & kTileMask))];
  }
  /// Mutable cell; grows the table as needed (may throw as `reserve`).
  Cell& at(CellIndex c) {
    reserve(CellBox{c, c});
    return cellUnchecked(c);
  }
  /// Value of a cell (the default value where nothing was allocated).
  const Cell& get(CellIndex c) const {
    const std::int64_t tx = (c.x >> kTileBits) - tx0_, ty = (c.y >> kTileBits) - ty0_;
    if (tx < 0 || ty < 0 || tx >= table_w_ || ty >= table_h_) return default_;
    const auto& tile = table_[static_cast<std::size_t>(ty * table_w_ + tx)];
    if (!tile) return default_;
    return tile[static_cast<std::size_t>(((c.y & kTileMask) << kTileBits) | (c.x & kTileMask))];
  }
  bool isAllocated(CellIndex c) const {
    const std::int64_t tx = (c.x >> kTileBits) - tx0_, ty = (c.y >> kTileBits) - ty0_;
    if (tx < 0 || ty < 0 || tx >= table_w_ || ty >= table_h_) return false;
    return static_cast<bool>(table_[static_cast<std::size_t>(ty * table_w_ + tx)]);
  }

  /// Number of allocated tiles and cells. Counted over the tile table (one pointer per tile), so
  /// that allocating a tile writes nothing shared between tiles (see the class comment).
  std::size_t numTiles() const {
    return static_cast<std::size_t>(std::count_if(table_.begin(), table_.end(), [](const auto& t) { return t != nullptr; }));
  }
  std::size_t numAllocatedCells() const { return numTiles() * kTileCells; }
  std::size_t cellBudget() const { return budget_; }
  const Cell& defaultValue() const { return default_; }

  /// Bounding box of the allocated tiles, in cells (empty when nothing is allocated).
  CellBox allocatedBox() const {
    CellBox box{{std::numeric_limits<std::int32_t>::max(), std::numeric_limits<std::int32_t>::max()},
                {std::numeric_limits<std::int32_t>::min(), std::numeric_limits<std::int32_t>::min()}};
    bool any = false;
    for (std::int64_t ty = 0; ty < table_h_; ++ty)
      for (std::int64_t tx = 0; tx < table_w_; ++tx) {
        if (!table_[static_cast<std::size_t>(ty * table_w_ + tx)]) continue;
        any = true;
        const auto x0 = static_cast<std::int32_t>((tx + tx0_) * kTileSize);
        const auto y0 = static_cast<std::int32_t>((ty + ty0_) * kTileSize);
        box.min.x = std::min(box.min.x, x0);
        box.min.y = std::min(box.min.y, y0);
        box.max.x = std::max(box.max.x, x0 + kTileSize - 1);
        box.max.y = std::max(box.max.y, y0 + kTileSize - 1);
      }
    return any ? box : CellBox{};
  }

  /// Calls f(CellIndex origin, const Cell* cells) for every allocated tile; cells are row-major
  /// (index (y << kTileBits) | x within the tile).
  template <typename F>
  void forEachTile(F&& f) const {
    for (std::int64_t ty = 0; ty < table_h_; ++ty)
      for (std::int64_t tx = 0; tx < table_w_; ++tx) {
        const auto& tile = table_[static_cast<std::size_t>(ty * table_w_ + tx)];
        if (tile)
          f(CellIndex{static_cast<std::int32_t>((tx + tx0_) * kTileSize),
                      static_cast<std::int32_t>((ty + ty0_) * kTileSize)},
            tile.get());
      }
  }

 private:
  static std::int64_t floorTile(std::int64_t c) { return c >> kTileBits; }

  void allocate(std::unique_ptr<Cell[]>& tile) {
    tile = std::make_unique<Cell[]>(kTileCells);
    std::fill(tile.get(), tile.get() + kTileCells, default_);
  }

  void grow(std::int64_t tx0, std::int64_t ty0, std::int64_t tx1, std::int64_t ty1) {
    if (table_w_ > 0) {
      tx0 = std::min(tx0, tx0_);
      ty0 = std::min(ty0, ty0_);
      tx1 = std::max(tx1, tx0_ + table_w_ - 1);
      ty1 = std::max(ty1, ty0_ + table_h_ - 1);
    }
    const double extent_cells = static_cast<double>(tx1 - tx0 + 1) * static_cast<double>(ty1 - ty0 + 1) *
                                static_cast<double>(kTileCells);
    if (extent_cells > static_cast<double>(budget_))
      throw badInput(
          fmt::format("the map would span {:.0f} cells, more than the cell budget of {} (absurd coordinates or ranges? "
                      "raise the budget for a genuinely huge map)",
                      extent_cells, budget_),
          ErrorLocation("", 0, "extent"));
    // Grow with a margin so that a robot moving steadily does not re-grow on every scan; the
    // margin is not charged to the budget (the table holds one pointer per tile).
    const std::int64_t margin = 4;
    tx0 -= margin;
    ty0 -= margin;
    tx1 += margin;
    ty1 += margin;
    const std::int64_t w = tx1 - tx0 + 1, h = ty1 - ty0 + 1;
    std::vector<std::unique_ptr<Cell[]>> table(static_cast<std::size_t>(w * h));
    for (std::int64_t y = 0; y < table_h_; ++y)
      for (std::int64_t x = 0; x < table_w_; ++x)
        table[static_cast<std::size_t>((y + ty0_ - ty0) * w + (x + tx0_ - tx0))] =
            std::move(table_[static_cast<std::size_t>(y * table_w_ + x)]);
    table_ = std::move(table);
    tx0_ = tx0;
    ty0_ = ty0;
    table_w_ = w;
    table_h_ = h;
  }

  Cell default_;
  std::size_t budget_;
  std::vector<std::unique_ptr<Cell[]>> table_;  // dense table of tile pointers, row-major
  std::int64_t tx0_ = 0, ty0_ = 0;              // tile index of table_[0]
  std::int64_t table_w_ = 0, table_h_ = 0;      // table size in tiles
};

}  // namespace lidar2d::mapping
