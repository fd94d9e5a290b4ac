// The hit/miss counting model (MapModel::kCount).

#include <array>
#include <cstdint>
#include <vector>

#include "src/mapping/internal/models.hpp"
#include "src/mapping/internal/traversal.hpp"

namespace lidar2d::mapping {
namespace {

using internal::cellOfCoords;
using internal::clearAndList;
using internal::forEachSurfaceCell;

// ---------------------------------------------------------------------------------------------
// Counting: hits and misses per cell.
struct HitMiss {
  std::uint32_t hits = 0;
  std::uint32_t misses = 0;
};

class CountMap final : public OccupancyMap {
 public:
  explicit CountMap(const MapOptions& o) : OccupancyMap(o), grid_(HitMiss{}, o.insert.cell_budget) {}
  MapModel model() const override { return MapModel::kCount; }

  std::optional<double> probability(CellIndex c) const override {
    const HitMiss& h = grid_.get(c);
    const std::uint64_t n = std::uint64_t{h.hits} + h.misses;
    if (n == 0) return std::nullopt;
    return static_cast<double>(h.hits) / static_cast<double>(n);
  }
  CellState state(CellIndex c) const override {
    const auto p = probability(c);
    if (!p) return CellState::kUnknown;
    return *p >= options_.count.occupied_threshold ? CellState::kOccupied : CellState::kFree;
  }
  std::size_t memoryBytes() const override { return grid_.numAllocatedCells() * sizeof(HitMiss); }

 protected:
  void beginScan(const CellBox& box) override { grid_.reserve(box); }
  std::uint64_t insertBeams(const Eigen::Vector2d& /*origin*/, const std::vector<Beam>& beams, const Slab& slab,
                            int part) override {
    // At most one update per cell per scan, hits first, as for log-odds; the top bit of `misses`
    // marks the cells updated in this scan. Counts saturate below that bit. Each part clears the
    // markers of its own cells (no other part touches them).
    std::vector<HitMiss*>& touched = touched_[static_cast<std::size_t>(part)].cells;
    TiledGrid<HitMiss>::Cursor cursor;
    touched.clear();
    auto update = [&touched](HitMiss& h, bool hit) __attribute__((always_inline)) {
      if (h.misses & kMarker) return;
      std::uint32_t& v = hit ? h.hits : h.misses;
      v += (v < kMarker - 1) ? 1u : 0u;
      h.misses |= kMarker;
      touched.push_back(&h);
    };
    for (const Beam& b : beams)
      if (b.hit && slab.contains(cellOfCoords(b.end))) update(grid_.cellCached(cellOfCoords(b.end), cursor), true);
    // The surface guard's cells are marked, so that no beam clears them, but not counted.
    const std::size_t num_counted = touched.size();
    forEachSurfaceCell(grid_, surfaces_, slab, [&touched](HitMiss& h) {
      if (h.misses & kMarker) return;
      h.misses |= kMarker;
      touched.push_back(&h);
    });
    const std::size_t num_guarded = touched.size() - num_counted;
    // Without a slab, the cleared cells are marked as they are walked and counted after the walks
    // (clearAndList).
    std::vector<HitMiss*>& listed = touched_[static_cast<std::size_t>(part)].listed;
    const std::size_t num_listed = clearAndList(
        grid_, beams, slab, listed, [&](auto& at) __attribute__((always_inline)) { update(at.ref(), false); },
        [](HitMiss & h) __attribute__((always_inline)) {
          const bool fresh = (h.misses & kMarker) == 0;
          h.misses |= kMarker;
          return fresh;
        });
    for (HitMiss* h : touched) h->misses &= ~kMarker;
    for (std::size_t i = 0; i < num_listed; ++i) {
      HitMiss& h = *listed[i];
      const std::uint32_t v = h.misses & ~kMarker;
      h.misses = v + (v < kMarker - 1 ? 1u : 0u);
    }
    return touched.size() - num_guarded + num_listed;
  }

 private:
  static constexpr std::uint32_t kMarker = 0x80000000u;
  TiledGrid<HitMiss> grid_;
  // Cells updated in the current scan, per part; a cache line each, as both parts push_back at
  // once (sharing a line would make the two threads contend for it).
  struct alignas(64) Touched {
    std::vector<HitMiss*> cells;
    std::vector<HitMiss*> listed;  // cells listed by clearAndList (the first `num_listed` of them)
  };
  std::array<Touched, 2> touched_;
};

}  // namespace

std::unique_ptr<OccupancyMap> internal::makeCountMap(const MapOptions& options) {
  return std::make_unique<CountMap>(options);
}

}  // namespace lidar2d::mapping
