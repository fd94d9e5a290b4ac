// The log-odds model (MapModel::kLogOdds).

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <utility>
#include <vector>

#include "src/mapping/internal/models.hpp"
#include "src/mapping/internal/traversal.hpp"

namespace lidar2d::mapping {
namespace {

using internal::cellOfCoords;
using internal::clearAndList;
using internal::forEachSurfaceCell;

double logit(double p) { return std::log(p / (1.0 - p)); }

// ---------------------------------------------------------------------------------------------
// Log-odds: one float per cell holding the (clamped) log-odds, or the classic integer score.
// A cell never observed holds the start value (so that an update needs no test for it) and stamp 0.
struct LogOddsCell {
  float value = 0.0f;
  std::uint32_t stamp = 0;  // last scan that updated the cell; 0: never observed
};

class LogOddsMap final : public OccupancyMap {
 public:
  explicit LogOddsMap(const MapOptions& o)
      : OccupancyMap(o), grid_(LogOddsCell{o.logodds.classic_integer ? 50.0f : 0.0f, 0}, o.insert.cell_budget) {
    const auto& l = o.logodds;
    if (l.classic_integer) {
      hit_ = 2.0f;
      miss_ = -1.0f;
      lo_ = 1.0f;
      hi_ = 100.0f;
    } else {
      hit_ = static_cast<float>(logit(l.hit_probability));
      miss_ = static_cast<float>(logit(l.miss_probability));
      lo_ = static_cast<float>(logit(l.min_probability));
      hi_ = static_cast<float>(logit(l.max_probability));
    }
  }
  MapModel model() const override { return MapModel::kLogOdds; }

  std::optional<double> probability(CellIndex c) const override {
    const LogOddsCell& cell = grid_.get(c);
    if (cell.stamp == 0) return std::nullopt;
    const float v = cell.value;
    if (options_.logodds.classic_integer) return v / 100.0;
    return 1.0 / (1.0 + std::exp(-static_cast<double>(v)));
  }
  CellState state(CellIndex c) const override {
    const auto p = probability(c);
    if (!p) return CellState::kUnknown;
    if (*p > options_.logodds.occupied_threshold) return CellState::kOccupied;
    if (*p < options_.logodds.free_threshold) return CellState::kFree;
    return CellState::kUnknown;
  }
  std::size_t memoryBytes() const override { return grid_.numAllocatedCells() * sizeof(LogOddsCell); }

 protected:
  void beginScan(const CellBox& box) override {
    grid_.reserve(box);
    if (++scan_ == 0) scan_ = 1;  // (stamp 0 means never observed)
  }
  std::uint64_t insertBeams(const Eigen::Vector2d& /*origin*/, const std::vector<Beam>& beams, const Slab& slab,
                            int part) override {
    // Each cell is updated at most once per scan, hits first (as Cartographer's update marker,
    // Hess et al. 2016, section IV-B): a wall cell hit by one beam is not cleared by another beam of
    // the same scan that grazes it, and cells near the sensor crossed by many beams get one miss,
    // not dozens. A per-cell scan stamp says whether the cell was updated in this scan.
    std::uint64_t updates = 0;
    TiledGrid<LogOddsCell>::Cursor cursor;
    // (Copies of the members: as far as the compiler knows, a cell's stamp and value may alias them,
    // which would reload them after every cell written.)
    const std::uint32_t scan = scan_;
    const float lo = lo_, hi = hi_, hit = hit_, miss = miss_;
    auto update = [scan, lo, hi, &updates](LogOddsCell& cell, float delta) __attribute__((always_inline)) {
      if (cell.stamp == scan) return;
      cell.stamp = scan;
      cell.value = std::clamp(cell.value + delta, lo, hi);
      ++updates;
    };
    for (const Beam& b : beams)
      if (b.hit && slab.contains(cellOfCoords(b.end))) update(grid_.cellCached(cellOfCoords(b.end), cursor), hit);
    // The surface guard's cells get this scan's stamp, so that no beam clears them, and their own
    // stamp back after the walks (they are not updated).
    std::vector<std::pair<LogOddsCell*, std::uint32_t>>& guarded = listed_[static_cast<std::size_t>(part)].guarded;
    guarded.clear();
    forEachSurfaceCell(grid_, surfaces_, slab, [&](LogOddsCell& cell) {
      if (cell.stamp == scan) return;
      guarded.emplace_back(&cell, cell.stamp);
      cell.stamp = scan;
    });
    // Without a slab, the cleared cells are stamped as they are walked and updated after the walks
    // (clearAndList).
    std::vector<LogOddsCell*>& listed = listed_[static_cast<std::size_t>(part)].cells;
    const std::size_t num_listed = clearAndList(
        grid_, beams, slab, listed, [&](auto& at) __attribute__((always_inline)) { update(at.ref(), miss); },
        [scan](LogOddsCell & cell) __attribute__((always_inline)) {
          const bool fresh = cell.stamp != scan;
          cell.stamp = scan;
          return fresh;
        });
    for (std::size_t i = 0; i < num_listed; ++i) {
      LogOddsCell& cell = *listed[i];
      cell.value = std::clamp(cell.value + miss, lo, hi);
    }
    for (const auto& [cell, stamp] : guarded) cell->stamp = stamp;
    return updates + num_listed;
  }

 private:
  TiledGrid<LogOddsCell> grid_;
  // Cells of this scan listed for their update, per part (a cache line each, as for CountMap).
  struct alignas(64) Listed {
    std::vector<LogOddsCell*> cells;
    std::vector<std::pair<LogOddsCell*, std::uint32_t>> guarded;  // the surface guard's cells, their stamps
  };
  std::array<Listed, 2> listed_;
  std::uint32_t scan_ = 0;  // number of the scan being inserted (stamps start at 0 = none)
  float hit_, miss_, lo_, hi_;
};

}  // namespace

std::unique_ptr<OccupancyMap> internal::makeLogOddsMap(const MapOptions& options) {
  return std::make_unique<LogOddsMap>(options);
}

}  // namespace lidar2d::mapping
