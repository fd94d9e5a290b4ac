#include "lidar2d/mapping/occupancy_map.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <bit>
#include <chrono>
#include <cmath>
#include <exception>
#include <numbers>
#include <system_error>
#include <thread>
#include <type_traits>

#include "lidar2d/core/error.hpp"
#include "lidar2d/mapping/ray_trace.hpp"

namespace lidar2d::mapping {
namespace {

double logit(double p) { return std::log(p / (1.0 - p)); }

// Where a beam's walk may start (OccupancyMap::prepare): the share of a cell's width that the wedge
// between its two covering beams may reach (1 is the geometric limit; the rest is a margin).
constexpr double kCoverWidth = 0.9;

Error badOption(const std::string& field, const std::string& msg) {
  return invalidArgument(msg, ErrorLocation("", 0, field));
}

[[gnu::always_inline]] inline CellIndex cellOfCoords(const Eigen::Vector2d& p) {
  return {floorToInt32(p.x()), floorToInt32(p.y())};
}

// A RayWalk over a TiledGrid that keeps the current cell's place in its tile, so that reaching the
// cell is an offset from the tile's first cell rather than a tile lookup per cell. The tile is
// looked up when the walk enters it, and then only when one of its cells is accessed (`ref`): a
// walk restricted to a slab never touches, or allocates, a tile outside the slab.
// The callbacks of the traversals below take a walk, or a `CellAt` for a single cell, and call
// `cell()`, `ref()` and `stepsLeft()` on it.
template <typename Cell>
class GridWalk {
 public:
  using Grid = TiledGrid<Cell>;
  [[gnu::always_inline]] GridWalk(Grid& grid, const RayWalk& walk)
      : walk_(walk),
        grid_(grid),
        index_(indexOf(walk_.cell())),
        step_x_(walk_.stepX()),
        step_y_(walk_.stepY() * Grid::kTileSize),
        edge_x_(walk_.stepX() > 0 ? 0 : Grid::kTileMask),
        edge_y_(walk_.stepY() > 0 ? 0 : Grid::kTileMask) {}
  bool done() const { return walk_.done(); }
  std::int32_t stepsLeft() const { return walk_.stepsLeft(); }
  CellIndex cell() const { return walk_.cell(); }
  std::int32_t x() const { return walk_.x(); }
  std::int32_t y() const { return walk_.y(); }
  // The current cell (allocating its tile on first touch; the grid's `reserve` covers it).
  [[gnu::always_inline]] Cell& ref() {
    if (!tile_) tile_ = &grid_.cellUnchecked(CellIndex{walk_.x() & ~Grid::kTileMask, walk_.y() & ~Grid::kTileMask});
    return tile_[index_];
  }
  [[gnu::always_inline]] void step() {
    // Entering another tile: its first coordinate along the step's axis is the entry edge.
    if (walk_.step()) {
      index_ += step_x_;
      if ((walk_.x() & Grid::kTileMask) == edge_x_) enterTile();
    } else {
      index_ += step_y_;
      if ((walk_.y() & Grid::kTileMask) == edge_y_) enterTile();
    }
  }

  // Calls on_cell(Cell&) for each cell the walk leaves, up to the end cell (which it is left in):
  // the loop of `ref()` and `step()` in fewer instructions per cell (a pointer
  // follows the walk; the tile is looked up at each tile entry instead of testing every step for
  // one). For a walk whose every cell is accessed (no slab): it looks up the tile of each cell it
  // visits, as `ref()`, and no other.
  template <typename F>
  [[gnu::always_inline]] void run(F&& on_cell) {
    const std::int32_t n = walk_.stepsLeft();
    if (n <= 0) return;
    Cell* p = &ref();
    // x (y) steps to the next tile: the first of the next tile along the step's direction.
    const std::int32_t mx = walk_.x() & Grid::kTileMask, my = walk_.y() & Grid::kTileMask;
    const std::int32_t lap_x = step_x_ > 0 ? Grid::kTileSize - mx : mx + 1;
    const std::int32_t lap_y = step_y_ > 0 ? Grid::kTileSize - my : my + 1;
    walk_.run(
        n, lap_x, lap_y, Grid::kTileSize, [&]() __attribute__((always_inline)) { on_cell(*p); },
        [&]() __attribute__((always_inline)) { p += step_x_; }, [&]() __attribute__((always_inline)) { p += step_y_; },
        [&](std::int32_t x, std::int32_t y, bool visited) {
          // (Not inlined: once per tile.) The tile is looked up only when one of its cells is.
          index_ = indexOf(CellIndex{x, y});
          tile_ = nullptr;
          if (visited) {
            tile_ = &grid_.cellUnchecked(CellIndex{x & ~Grid::kTileMask, y & ~Grid::kTileMask});
            p = tile_ + index_;
          }
        });
    if (tile_) index_ = p - tile_;
  }

 private:
  static std::ptrdiff_t indexOf(CellIndex c) {
    return ((c.y & Grid::kTileMask) << Grid::kTileBits) | (c.x & Grid::kTileMask);
  }
  void enterTile() {
    tile_ = nullptr;
    index_ = indexOf(walk_.cell());
  }
  RayWalk walk_;
  Grid& grid_;
  Cell* tile_ = nullptr;  // first cell of the current cell's tile; null until accessed
  std::ptrdiff_t index_;  // the current cell's index in its tile
  const std::ptrdiff_t step_x_, step_y_, edge_x_, edge_y_;
};

// One cell, with the interface of a GridWalk (the end cells of the traversals).
template <typename Cell>
class CellAt {
 public:
  CellAt(TiledGrid<Cell>& grid, CellIndex c) : grid_(grid), c_(c) {}
  std::int32_t stepsLeft() const { return 0; }
  CellIndex cell() const { return c_; }
  Cell& ref() { return grid_.cellUnchecked(c_); }

 private:
  TiledGrid<Cell>& grid_;
  CellIndex c_;
};

// Calls visit(CellAt) for cell c when `slab` holds it (the end cells of the traversals).
// (Templated on the map's protected Slab type, which it cannot name.)
template <typename Cell, typename SlabT, typename F>
[[gnu::always_inline]] inline void visitCell(TiledGrid<Cell>& grid, const SlabT& slab, CellIndex c, F&& visit) {
  if (!slab.contains(c)) return;
  CellAt<Cell> at(grid, c);
  visit(at);
}

// `traceRay` restricted to the cells of `slab`: calls on_pass(walk) for the passed cells (all but
// the end cell) that lie in the slab, in order. It is the same RayWalk, so the cells and their
// order are exactly traceRay's; a segment is monotone along each axis, so it is inside the slab for
// one run of steps: the steps before it are only walked (no cell access), the walk stops at the exit.
// (Jumping straight to the entry would recompute t_max differently from the walk's running sums and
// could pick the other cell at a near-corner crossing.)
template <int kAxis, typename Cell, typename F>
[[gnu::always_inline]] inline void traceInSlabAlong(TiledGrid<Cell>& grid, const RayWalk& ray, std::int32_t lo,
                                                    std::int32_t hi, F&& on_pass) {
  GridWalk<Cell> walk(grid, ray);
  // (kAxis a template parameter: the slab test then reads one coordinate without a branch.)
  auto inside = [&] {
    const std::int32_t v = kAxis == 0 ? walk.x() : walk.y();
    return v >= lo && v < hi;
  };
  while (!walk.done() && !inside()) walk.step();
  for (; !walk.done() && inside(); walk.step()) on_pass(walk);
}

// As above, for any slab (axis -1: all cells). Unless `on_run` is null, the cells of the whole walk
// (no slab) go to on_run(Cell&) instead, by GridWalk::run.
template <typename Cell, typename F, typename Run = std::nullptr_t>
[[gnu::always_inline]] inline void traceInSlab(TiledGrid<Cell>& grid, const RayWalk& ray, int axis, std::int32_t lo,
                                               std::int32_t hi, F&& on_pass, Run&& on_run = nullptr) {
  if (axis < 0) {
    GridWalk<Cell> walk(grid, ray);  // traceRay
    if constexpr (!std::is_null_pointer_v<std::remove_cvref_t<Run>>) walk.run(on_run);
    for (; !walk.done(); walk.step()) on_pass(walk);
  } else if (axis == 0) {
    traceInSlabAlong<0>(grid, ray, lo, hi, on_pass);
  } else {
    traceInSlabAlong<1>(grid, ray, lo, hi, on_pass);
  }
}

// (Near the sensor most cells a beam passes are passed by its neighbours too: a beam's walk starts
// where its covering beams stop passing all its cells, see OccupancyMap::prepare. Clearing row runs
// per beam and skipping the runs already cleared, tried before, cost more per row than the walk
// saved; BENCHMARK.md, mapping.)
// The cells a beam clears (log-odds, count), restricted to `slab`: the cells its walk passes, as
// `traceRay`, and the end cell of a beam with no return (a return's cell is a hit). `on_clear(at)`
// gets a GridWalk or a CellAt (see GridWalk). Without a slab, the passed cells go to
// on_run(Cell&) instead, walked by GridWalk::run: at most `b.walk.stepsLeft()` of them.
// (Templated on the map's protected Beam and Slab types, which it cannot name.)
template <typename Cell, typename BeamT, typename SlabT, typename F, typename Run>
[[gnu::always_inline]] inline void forEachCleared(TiledGrid<Cell>& grid, const BeamT& b, const SlabT& slab,
                                                  F&& on_clear, Run&& on_run) {
  traceInSlab(grid, b.walk, slab.axis, slab.lo, slab.hi, on_clear, on_run);
  if (!b.hit) visitCell(grid, slab, cellOfCoords(b.end), on_clear);
}

// forEachCleared over all beams, for the models that update a cell at most once per scan: the
// cells that go to on_run there are listed in `listed` as they are walked (its first n entries, n
// returned), and mark(cell) marks a cell as updated in this scan and says whether it was not marked
// yet (then the list's end moves past it). The caller updates the listed cells after the walks:
// this way no branch depends on a cell's mark, which the processor mispredicted about once in
// eight cells (freiburg-079, callgrind). The others go to on_clear(at), as in forEachCleared.
template <typename Cell, typename BeamT, typename SlabT, typename F, typename Mark>
[[gnu::always_inline]] inline std::size_t clearAndList(TiledGrid<Cell>& grid, const std::vector<BeamT>& beams,
                                                       const SlabT& slab, std::vector<Cell*>& listed, F&& on_clear,
                                                       Mark&& mark) {
  std::size_t n = 0;
  for (const BeamT& b : beams) {
    // (Room for every cell of the beam, so that listing needs no test.)
    const std::size_t room = n + static_cast<std::size_t>(b.walk.stepsLeft()) + 1;
    if (listed.size() < room) listed.resize(std::max(room, 2 * listed.size()));
    Cell** const list = listed.data();
    forEachCleared(
        grid, b, slab, on_clear, [&](Cell & cell) __attribute__((always_inline)) {
          list[n] = &cell;
          n += mark(cell);
        });
  }
  return n;
}

// The surface guard's cells (InsertOptions::surface_guard_max_m) in `slab`: calls on_cell(Cell&)
// for every cell each segment passes through, its end cells included (a cell may come twice).
template <typename Cell, typename SurfaceT, typename SlabT, typename F>
void forEachSurfaceCell(TiledGrid<Cell>& grid, const std::vector<SurfaceT>& surfaces, const SlabT& slab, F&& on_cell) {
  typename TiledGrid<Cell>::Cursor cursor;
  auto visit = [&](CellIndex c) {
    if (slab.contains(c)) on_cell(grid.cellCached(c, cursor));
  };
  for (const SurfaceT& s : surfaces) visit(traceRay(s.from, s.to, visit));
}

CellBox unite(CellBox a, const CellBox& b) {
  if (a.empty()) return b;
  if (b.empty()) return a;
  a.min.x = std::min(a.min.x, b.min.x);
  a.min.y = std::min(a.min.y, b.min.y);
  a.max.x = std::max(a.max.x, b.max.x);
  a.max.y = std::max(a.max.y, b.max.y);
  return a;
}

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
  // once (sharing a line made two threads 50% slower than one, measured on freiburg-079).
  struct alignas(64) Touched {
    std::vector<HitMiss*> cells;
    std::vector<HitMiss*> listed;  // cells listed by clearAndList (the first `num_listed` of them)
  };
  std::array<Touched, 2> touched_;
};

// Whether the segment p-q meets the box [0, h]^2 (Liang-Barsky clipping).
bool segmentMeetsBox(Eigen::Vector2d p, Eigen::Vector2d q, double h) {
  double t0 = 0.0, t1 = 1.0;
  const Eigen::Vector2d d = q - p;
  for (int k = 0; k < 2; ++k)
    for (const double sign : {-1.0, 1.0}) {
      // Inside: sign * (p + t d)_k <= bound, bound = 0 for the lower side, h for the upper one.
      const double bound = sign < 0 ? 0.0 : h;
      const double num = bound - sign * p[k], den = sign * d[k];
      if (den == 0) {
        if (num < 0) return false;
      } else if (den > 0) {
        t1 = std::min(t1, num / den);
      } else {
        t0 = std::max(t0, num / den);
      }
    }
  return t0 <= t1;
}

// Marching squares on a square of four cell centres, in its own coordinates: a at (0, 0) (the cell
// in question), b at (1, 0), e at (0, 1), f at (1, 1). True when the zero contour passes through
// [0, 0.5]^2, the quarter of the square that belongs to a's cell.
bool contourEntersQuarter(float a, float b, float e, float f) {
  auto neg = [](float x) { return x < 0; };
  std::array<Eigen::Vector2d, 4> cross;  // crossings in order: bottom (a-b), right (b-f), top (e-f), left (a-e)
  std::array<bool, 4> has{};
  auto at = [](float x, float y) { return static_cast<double>(x / (x - y)); };
  if ((has[0] = neg(a) != neg(b))) cross[0] = {at(a, b), 0.0};
  if ((has[1] = neg(b) != neg(f))) cross[1] = {1.0, at(b, f)};
  if ((has[2] = neg(e) != neg(f))) cross[2] = {at(e, f), 1.0};
  if ((has[3] = neg(a) != neg(e))) cross[3] = {0.0, at(a, e)};
  const int count = has[0] + has[1] + has[2] + has[3];
  if (count == 2) {
    std::array<Eigen::Vector2d, 2> ends;
    int k = 0;
    for (int i = 0; i < 4; ++i)
      if (has[static_cast<std::size_t>(i)]) ends[static_cast<std::size_t>(k++)] = cross[static_cast<std::size_t>(i)];
    return segmentMeetsBox(ends[0], ends[1], 0.5);
  }
  if (count == 4) {
    // Saddle, resolved by the centre value: when it has a's sign, a and f are joined and the
    // contour cuts off b (bottom-right) and e (left-top); otherwise it cuts off a and f.
    const bool joined = neg(0.25f * (a + b + e + f)) == neg(a);
    if (joined) return segmentMeetsBox(cross[0], cross[1], 0.5) || segmentMeetsBox(cross[3], cross[2], 0.5);
    return segmentMeetsBox(cross[0], cross[3], 0.5) || segmentMeetsBox(cross[1], cross[2], 0.5);
  }
  return false;
}

// ---------------------------------------------------------------------------------------------
// TSDF: running weighted average of the truncated signed distance along each beam.
struct TsdfCell {
  float sdf = 0.0f;     // [cells], positive in front of the surface
  float weight = 0.0f;  // 0 = never observed
};

class TsdfMap final : public OccupancyMap {
 public:
  explicit TsdfMap(const MapOptions& o)
      : OccupancyMap(o),
        grid_(TsdfCell{}, o.insert.cell_budget),
        trunc_cells_(static_cast<float>(o.tsdf.truncation_m * geometry_.inverseResolution())),
        max_weight_(static_cast<float>(static_cast<std::size_t>(o.tsdf.max_weight))) {
    const auto cap = static_cast<std::size_t>(o.tsdf.max_weight);
    for (std::size_t w = 0; w <= cap; ++w) {
      inv_weight_.push_back(1.0f / static_cast<float>(std::min(w + 1, cap)));
      weight_next_.push_back(static_cast<float>(std::min(w + 1, cap)));
    }
  }
  MapModel model() const override { return MapModel::kTsdf; }

  std::optional<double> probability(CellIndex c) const override {
    switch (state(c)) {
      case CellState::kOccupied:
        return 1.0;
      case CellState::kFree:
        return 0.0;
      case CellState::kUnknown:
        break;
    }
    return grid_.get(c).weight > 0 ? std::optional<double>(0.5) : std::nullopt;
  }

  /// Occupied: the zero contour of the field passes through the cell's square. The contour is the
  /// marching-squares one: linear between the crossings on the edges joining cell centres, per
  /// square of four centres (the cell's square is covered by four such squares, a quarter each).
  /// A crossing on an edge with an unobserved end's square missing still counts: the cell is the one
  /// nearer the crossing. Free: observed, positive, no contour. Cells behind the surface stay unknown.
  CellState state(CellIndex c) const override {
    const TsdfCell& v = grid_.get(c);
    if (v.weight <= 0) return CellState::kUnknown;
    // The 3 x 3 block around the cell: nb[dy + 1][dx + 1].
    std::array<std::array<const TsdfCell*, 3>, 3> nb{};
    bool any_crossing = false;
    for (int dy = -1; dy <= 1; ++dy)
      for (int dx = -1; dx <= 1; ++dx) {
        const TsdfCell& n = dx == 0 && dy == 0 ? v : grid_.get(CellIndex{c.x + dx, c.y + dy});
        nb[static_cast<std::size_t>(dy + 1)][static_cast<std::size_t>(dx + 1)] = &n;
        any_crossing |= n.weight > 0 && (n.sdf >= 0) != (v.sdf >= 0);
      }
    if (!any_crossing) return v.sdf > 0 ? CellState::kFree : CellState::kUnknown;
    auto at = [&nb](int dx, int dy) { return nb[static_cast<std::size_t>(dy + 1)][static_cast<std::size_t>(dx + 1)]; };
    // A crossing on an edge to a 4-neighbour, in this cell's half of the edge.
    static constexpr std::array<std::array<int, 2>, 4> kN{{{1, 0}, {-1, 0}, {0, 1}, {0, -1}}};
    for (const auto& d : kN) {
      const TsdfCell& n = *at(d[0], d[1]);
      if (n.weight > 0 && (v.sdf >= 0) != (n.sdf >= 0) && std::abs(v.sdf) <= std::abs(n.sdf)) return CellState::kOccupied;
    }
    // The contour crossing a corner of the cell's square without crossing its edges' halves.
    for (const int dy : {-1, 1})
      for (const int dx : {-1, 1}) {
        const TsdfCell &b = *at(dx, 0), &e = *at(0, dy), &f = *at(dx, dy);
        if (b.weight <= 0 || e.weight <= 0 || f.weight <= 0) continue;
        if (contourEntersQuarter(v.sdf, b.sdf, e.sdf, f.sdf)) return CellState::kOccupied;
      }
    return v.sdf > 0 ? CellState::kFree : CellState::kUnknown;
  }
  std::size_t memoryBytes() const override { return grid_.numAllocatedCells() * sizeof(TsdfCell); }

  const TiledGrid<TsdfCell>& grid() const { return grid_; }

 protected:
  void beginScan(const CellBox& box) override { grid_.reserve(box); }
  std::uint64_t insertBeams(const Eigen::Vector2d& origin, const std::vector<Beam>& beams, const Slab& slab,
                            int /*part*/) override {
    // One update per beam and cell, in beam order; a cell's updates all come from the part whose
    // slab holds it, in that order, so a split scan averages exactly as an unsplit one.
    std::uint64_t updates = 0;
    const float t = trunc_cells_;
    for (const Beam& b : beams) {
      const Eigen::Vector2d d = b.end - origin;
      const double len = d.norm();
      if (len <= 0) continue;
      // Signed distance of a cell = range - (projection of its centre on the beam), in cells;
      // the projection is affine in the cell index, so it costs two multiply-adds per cell.
      const float dir_x = static_cast<float>(d.x() / len), dir_y = static_cast<float>(d.y() / len);
      const float offset = static_cast<float>(b.range_cells - ((0.5 - origin.x()) * d.x() + (0.5 - origin.y()) * d.y()) / len);
      auto update = [&](auto& at) __attribute__((always_inline)) {
        const CellIndex c = at.cell();
        const float sdf =
            b.hit ? std::clamp(offset - (dir_x * static_cast<float>(c.x) + dir_y * static_cast<float>(c.y)), -t, t) : t;
        TsdfCell& v = at.ref();
        // Free-space carving (sdf at the truncation) leaves cells near a surface (|sdf| < t) alone:
        // beams grazing a wall clip the corners of the cells the wall passes through, and averaging
        // +t into them would move the zero crossing off the wall.
        if (sdf >= t) {
          if (v.weight > 0 && v.sdf < t) return;
          // Averaging the truncation into a cell holding it (carving leaves others alone) changes
          // only the weight; at the cap, nothing: skip the writes (it still counts as an update).
          if (v.weight >= max_weight_) {
            ++updates;
            return;
          }
        }
        // Weights are whole numbers up to the cap, so 1 / (w + 1) comes from a table.
        const auto w = static_cast<std::size_t>(v.weight);
        v.sdf += (sdf - v.sdf) * inv_weight_[w];
        v.weight = weight_next_[w];
        ++updates;
      };
      // For a return, b.end already lies `truncation` behind the surface (see insert()).
      traceInSlab(grid_, b.walk, slab.axis, slab.lo, slab.hi, update);
      visitCell(grid_, slab, cellOfCoords(b.end), update);
    }
    return updates;
  }

 private:
  TiledGrid<TsdfCell> grid_;
  const float trunc_cells_;
  const float max_weight_;  // the weight cap, a whole number
  std::vector<float> inv_weight_;   // 1 / (new weight) for each current whole weight
  std::vector<float> weight_next_;  // new weight after one more observation (capped)
};

}  // namespace

const char* toString(MapModel m) {
  switch (m) {
    case MapModel::kLogOdds:
      return "logodds";
    case MapModel::kCount:
      return "count";
    case MapModel::kTsdf:
      return "tsdf";
  }
  return "unknown";
}

// ---------------------------------------------------------------------------------------------
// Two-thread insertion. The scan's cells are split by a line on a tile border (so each tile, and
// each cell, belongs to one thread and lazy tile allocation cannot race); each thread runs the
// model's insertion restricted to its side. A cell's updates thus happen on one thread and in the
// single-threaded order (hits phase, then beams in order), so the map is bit-identical.

namespace {

void cpuRelax() {
#if defined(__x86_64__) || defined(__i386__)
  __builtin_ia32_pause();
#endif
}

// Waits until `a` differs from `old`: busy for up to `spin` first (the other side is normally only
// microseconds away) - pausing for the first microseconds, then yielding the core so that a thread
// it is shared with (the other half of the scan, the log reader) runs - and then sleeps in the
// kernel (futex), so an idle worker costs no CPU.
std::uint32_t waitChange(const std::atomic<std::uint32_t>& a, std::uint32_t old, std::chrono::microseconds spin) {
  const auto t0 = std::chrono::steady_clock::now();
  for (int i = 0;; ++i) {
    const std::uint32_t v = a.load(std::memory_order_acquire);
    if (v != old) return v;
    if ((i & 15) == 15) {
      const auto waited = std::chrono::steady_clock::now() - t0;
      if (waited > spin) break;
      if (waited > std::chrono::microseconds(2)) std::this_thread::yield();
    }
    cpuRelax();
  }
  for (;;) {
    a.wait(old, std::memory_order_acquire);
    const std::uint32_t v = a.load(std::memory_order_acquire);
    if (v != old) return v;
  }
}

// Handshake spin times, measured on freiburg-079 (2 cores, reader thread running): long enough to
// cover the gap between consecutive scans when the reader keeps up, short enough not to starve it.
constexpr std::chrono::microseconds kWorkerSpin{50};
constexpr std::chrono::microseconds kCallerSpin{200};

}  // namespace

struct OccupancyMap::Worker {
  explicit Worker(OccupancyMap* map) : thread([this, map] { run(map); }) {}
  ~Worker() {
    stop = true;
    job.fetch_add(1, std::memory_order_release);
    job.notify_one();
    thread.join();
  }
  Worker(const Worker&) = delete;
  Worker& operator=(const Worker&) = delete;

  void run(OccupancyMap* map) {
    std::uint32_t seen = 0;
    for (;;) {
      seen = waitChange(job, seen, kWorkerSpin);
      if (stop) return;
      try {
        updates = map->insertBeams(*origin, map->beams_, slab, 1);
      } catch (...) {
        error = std::current_exception();
      }
      done.store(seen, std::memory_order_release);
      done.notify_one();
    }
  }
  // Runs the worker's part of a scan; returns the job number to pass to `wait`.
  std::uint32_t start(const Eigen::Vector2d& o, const Slab& s) {
    origin = &o;
    slab = s;
    updates = 0;
    error = nullptr;
    const std::uint32_t n = job.fetch_add(1, std::memory_order_release) + 1;
    job.notify_one();
    return n;
  }
  void wait(std::uint32_t n) {
    std::uint32_t d = done.load(std::memory_order_acquire);
    while (d != n) d = waitChange(done, d, kCallerSpin);
  }

  // The job, written by the caller before `job` is bumped, read by the worker after.
  const Eigen::Vector2d* origin = nullptr;
  Slab slab;
  bool stop = false;
  // The result, written by the worker before `done` is set.
  std::uint64_t updates = 0;
  std::exception_ptr error;
  alignas(64) std::atomic<std::uint32_t> job{0};  // number of the last job posted (own cache line:
  alignas(64) std::atomic<std::uint32_t> done{0};  // number of the last job finished  each side spins on one)
  std::thread thread;                  // last member: starts once the others exist
};

OccupancyMap::OccupancyMap(const MapOptions& options) : options_(options), geometry_(options.resolution_m) {}

OccupancyMap::~OccupancyMap() = default;

std::optional<std::pair<OccupancyMap::Slab, OccupancyMap::Slab>> OccupancyMap::chooseSplit(const Eigen::Vector2d& origin,
                                                                                             const CellBox& box) {
  // The work is estimated as if every walk started at the laser (log-odds and count start most of
  // them farther out, see `prepare`: the near part's share is overestimated).
  // Below this much work (cells traversed) the handshake (a few microseconds) does not pay.
  constexpr double kMinWork = 3000;
  // Walking a far part's cells before the split line without touching them costs about this
  // fraction of visiting a cell (measured with bench_mapping).
  constexpr double kSkipCost = 0.25;
  // Split only when the smaller part has at least this share of the work.
  constexpr double kMinShare = 0.2;
  constexpr int kBits = TiledGrid<int>::kTileBits;
  double total = 0;
  for (const Beam& b : beams_) total += std::abs(b.end.x() - origin.x()) + std::abs(b.end.y() - origin.y());
  if (total < kMinWork) return std::nullopt;
  // For a line at coordinate X on axis a, a beam ending beyond it has the share |end - X| / |end -
  // origin| of its cells beyond. Per tile column (row) of the beam ends, sums of w/|d| and
  // w/|d| * end give the far work at every tile border in one sweep.
  double best_cost = total;
  Slab best_near, best_far;
  for (int axis = 0; axis < 2; ++axis) {
    const double o = origin[axis];
    const std::int32_t lo_tile = (axis == 0 ? box.min.x : box.min.y) >> kBits;
    const std::int32_t hi_tile = (axis == 0 ? box.max.x : box.max.y) >> kBits;
    const std::int32_t o_tile = floorToInt32(o) >> kBits;
    const auto n = static_cast<std::size_t>(hi_tile - lo_tile + 1);
    split_sums_.assign(2 * n, 0.0);
    for (const Beam& b : beams_) {
      const double d = std::abs(b.end[axis] - o);
      if (d == 0) continue;
      const double a = (std::abs(b.end.x() - origin.x()) + std::abs(b.end.y() - origin.y())) / d;
      const auto k = static_cast<std::size_t>((floorToInt32(b.end[axis]) >> kBits) - lo_tile);
      split_sums_[2 * k] += a;
      split_sums_[2 * k + 1] += a * b.end[axis];
    }
    auto consider = [&](std::int32_t tile, double s0, double s1, bool upper) {
      const double X = static_cast<double>(tile) * (1 << kBits);
      const double far = (upper ? s1 - X * s0 : X * s0 - s1) + kSkipCost * std::abs(X - o) * s0;
      const double cost = std::max(far, total - far);
      if (cost >= best_cost) return;
      best_cost = cost;
      const std::int32_t line = tile * (1 << kBits);
      constexpr std::int32_t kMin = std::numeric_limits<std::int32_t>::min(), kMax = std::numeric_limits<std::int32_t>::max();
      best_far = upper ? Slab{axis, line, kMax} : Slab{axis, kMin, line};
      best_near = upper ? Slab{axis, kMin, line} : Slab{axis, line, kMax};
    };
    // Lines above the origin's cell: the far side is tiles >= t.
    double s0 = 0, s1 = 0;
    for (std::int32_t t = hi_tile; t > o_tile; --t) {
      s0 += split_sums_[2 * static_cast<std::size_t>(t - lo_tile)];
      s1 += split_sums_[2 * static_cast<std::size_t>(t - lo_tile) + 1];
      consider(t, s0, s1, true);
    }
    // Lines at or below the origin's cell: the far side is tiles < t.
    s0 = s1 = 0;
    for (std::int32_t t = lo_tile + 1; t <= o_tile; ++t) {
      s0 += split_sums_[2 * static_cast<std::size_t>(t - 1 - lo_tile)];
      s1 += split_sums_[2 * static_cast<std::size_t>(t - 1 - lo_tile) + 1];
      consider(t, s0, s1, false);
    }
  }
  if (best_cost > (1 - kMinShare) * total) return std::nullopt;
  return std::make_pair(best_near, best_far);
}

std::uint64_t OccupancyMap::insertParallel(const Eigen::Vector2d& origin, const Slab& mine, const Slab& theirs) {
  if (!worker_) {
    try {
      worker_ = std::make_unique<Worker>(this);
    } catch (const std::system_error&) {  // no thread to be had: stay single-threaded
      return insertBeams(origin, beams_, Slab{}, 0);
    }
  }
  ++parallel_scans_;
  const auto t0 = std::chrono::steady_clock::now();
  const std::uint32_t job = worker_->start(origin, theirs);
  std::uint64_t updates = 0;
  std::exception_ptr error;
  try {
    updates = insertBeams(origin, beams_, mine, 0);
  } catch (...) {
    error = std::current_exception();
  }
  const auto t1 = std::chrono::steady_clock::now();
  worker_->wait(job);  // always: the worker reads beams_
  // When the cores are busy with other work the worker may get its time slice late and the scan
  // takes longer than on one thread (waiting longer than the own part took). Then insert the next
  // scans on one thread, doubling the pause while it keeps happening.
  if (options_.insert.adaptive_threads && std::chrono::steady_clock::now() - t1 > t1 - t0) {
    backoff_ = std::min<std::uint32_t>(std::max<std::uint32_t>(2 * backoff_, 8), 1024);
    single_left_ = backoff_;
  } else {
    backoff_ /= 2;
  }
  if (error) std::rethrow_exception(error);
  if (worker_->error) std::rethrow_exception(std::exchange(worker_->error, nullptr));
  return updates + worker_->updates;
}

void OccupancyMap::insert(const LaserScan& scan, const SE2& T_world_laser) {
  if (!prepared_) prepared_ = std::make_unique<PreparedScan>();
  prepare(scan, T_world_laser, *prepared_);
  insert(*prepared_);
}

void OccupancyMap::prepare(const LaserScan& scan, const SE2& T_world_laser, PreparedScan& out) const {
  out.ready_ = false;
  out.model_ = this;
  if (!T_world_laser.isFinite()) throw badInput("laser pose is not finite", ErrorLocation("", 0, "pose"));
  const double inv_res = geometry_.inverseResolution();
  // Cell coordinates must stay far inside int32 for the traversal; ranges are capped by the options
  // (<= 10 km), so bounding the pose bounds every endpoint. The cell budget catches the rest.
  if (std::abs(T_world_laser.x()) * inv_res > 1e9 || std::abs(T_world_laser.y()) * inv_res > 1e9)
    throw badInput("laser pose is absurdly far from the map origin", ErrorLocation("", 0, "pose"));
  const Eigen::Vector2d origin = geometry_.toCellCoords(T_world_laser.translation());
  out.origin_ = origin;
  const double max_range = options_.insert.max_range_m;
  const double clear = options_.insert.no_return_clear_m;
  // The TSDF traces past each return so that the cells just behind the surface get their negative
  // distance - but only a short way (behind_surface_m): walls are thinner than the truncation
  // distance, and a long negative band would reach into the room on the other side of the wall and
  // cancel its zero crossing when the two are averaged.
  const double beyond =
      model() == MapModel::kTsdf ? std::min(options_.tsdf.truncation_m, options_.tsdf.behind_surface_m) : 0.0;
  out.beams_.clear();
  out.surfaces_.clear();
  CellBox& box = out.box_;
  box = CellBox{geometry_.cellOf(T_world_laser.translation()), geometry_.cellOf(T_world_laser.translation())};
  auto grow = [&box](const Eigen::Vector2d& p) {
    const std::int32_t x = floorToInt32(p.x()), y = floorToInt32(p.y());
    box.min.x = std::min(box.min.x, x);
    box.min.y = std::min(box.min.y, y);
    box.max.x = std::max(box.max.x, x);
    box.max.y = std::max(box.max.y, y);
  };
  const double c0 = std::cos(T_world_laser.theta()), s0 = std::sin(T_world_laser.theta());
  const double guard_max = model() == MapModel::kTsdf ? 0.0 : options_.insert.surface_guard_max_m;
  const std::size_t n = scan.size();
  // Beam directions in the laser frame, and how far each level of covering beams reaches per unit
  // of a cell's width (see below).
  // (The directions depend only on the scan's angles, which a laser keeps from scan to scan: they
  // are computed again only when those change - the sines and cosines were 2% of `lidar2d map`.)
  if (out.units_.size() != n || out.units_angle_min_ != scan.angleMin() ||
      out.units_angle_increment_ != scan.angleIncrement()) {
    out.units_.resize(n);
    for (std::size_t i = 0; i < n; ++i) {
      const double a = scan.angle(i);
      out.units_[i] = Eigen::Vector2d(std::cos(a), std::sin(a));
    }
    // kCoverWidth / (2 sin(h inc)) for h = 2^z, while the wedge (2 h inc) is well under a half turn.
    // (inc is finite and non-zero: LaserScan checks it.)
    const double inc = std::abs(scan.angleIncrement());
    out.reach_per_width_.clear();
    for (int z = 0; z < 63 && std::ldexp(inc, z) < 1.5; ++z)
      out.reach_per_width_.push_back(kCoverWidth / (2.0 * std::sin(std::ldexp(inc, z))));
    out.units_angle_min_ = scan.angleMin();
    out.units_angle_increment_ = scan.angleIncrement();
  }
  out.hits_.assign(n, 0);
  for (std::size_t i = 0; i < n; ++i) out.hits_[i] = scan.isValid(i) && scan.ranges()[i] <= max_range;
  out.reserve_ = CellBox{};                            // (empty)
  auto toWorldCells = [&](const Eigen::Vector2d& p) {  // a point in the laser frame [m] -> [cells]
    return Eigen::Vector2d(origin + inv_res * Eigen::Vector2d(c0 * p.x() - s0 * p.y(), s0 * p.x() + c0 * p.y()));
  };
  if (guard_max > 0) {
    // The surface guard's segments (InsertOptions::surface_guard_max_m), in the laser frame first.
    out.points_.resize(n);
    for (std::size_t i = 0; i < n; ++i)
      if (out.hits_[i]) out.points_[i] = scan.ranges()[i] * out.units_[i];
    // Each return's nearer neighbouring return, if within reach.
    const double reach = std::min(options_.insert.surface_neighbor_max_m, guard_max);
    out.neighbors_.assign(n, n);
    for (std::size_t i = 0; i < n; ++i) {
      if (!out.hits_[i]) continue;
      double best = reach * reach;
      for (const std::size_t j : {i - 1, i + 1}) {
        if (j >= n || !out.hits_[j]) continue;  // (i - 1 wraps to a huge index for i = 0)
        const double sq = (out.points_[j] - out.points_[i]).squaredNorm();
        if (sq > 0 && sq <= best) {
          best = sq;
          out.neighbors_[i] = j;
        }
      }
    }
    auto joined = [&](std::size_t a, std::size_t b) { return out.neighbors_[a] == b || out.neighbors_[b] == a; };
    auto cross = [](const Eigen::Vector2d& a, const Eigen::Vector2d& b) { return a.x() * b.y() - a.y() * b.x(); };
    const double edge_max = 2 * std::numbers::sqrt2 * geometry_.resolution();  // 2 sqrt(2) cells [m]
    for (std::size_t i = 0; i < n; ++i) {
      if (!out.hits_[i]) continue;
      const Eigen::Vector2d& p = out.points_[i];
      const Eigen::Vector2d from = toWorldCells(p);
      // The surface between this return and the next, when they are one surface.
      if (i + 1 < n && out.hits_[i + 1] && joined(i, i + 1))
        out.surfaces_.push_back({from, toWorldCells(out.points_[i + 1])});
      // Past an occluding edge towards each side: where the neighbour on that side is not on this
      // surface and lies farther (by more than edge_max) or has no return, the surface continues
      // (away from its other neighbour, or across the beam) to where that neighbour's beam passes
      // it, at most edge_max.
      for (const int side : {-1, 1}) {
        const std::size_t m = side < 0 ? i - 1 : i + 1;
        if (m >= n) continue;  // (wraps below 0)
        if (out.hits_[m] && (joined(i, m) || !(scan.ranges()[m] > scan.ranges()[i] + edge_max))) continue;
        const std::size_t k = out.neighbors_[i];
        const Eigen::Vector2d along = k < n ? Eigen::Vector2d((p - out.points_[k]).normalized())
                                            : Eigen::Vector2d(-out.units_[i].y() * side, out.units_[i].x() * side);
        // p + l along meets beam m where cross(u_m, p + l along) = 0.
        const double den = cross(out.units_[m], along);
        const double l = den != 0 ? -cross(out.units_[m], p) / den : edge_max;
        const Eigen::Vector2d to = toWorldCells(p + (l > 0 ? std::min(l, edge_max) : edge_max) * along);
        const CellIndex c = cellOfCoords(to);
        out.reserve_ = unite(out.reserve_, CellBox{c, c});
        out.surfaces_.push_back({from, to});
      }
    }
  }
  // Each beam's length [cells]; 0: no beam.
  out.lengths_.resize(n);
  for (std::size_t i = 0; i < n; ++i) {
    const double r = scan.ranges()[i];
    double len = 0;
    if (!std::isnan(r) && r > scan.rangeMin())
      len = out.hits_[i] ? r + beyond : std::min(clear, std::isfinite(r) ? r : clear);
    out.lengths_[i] = len > 0 ? len * inv_res : 0.0;
  }
  // Where each beam's walk starts. Log-odds and count update a cell at most once per scan, so only
  // the set of cells that the scan's beams pass matters, not which beam passes them. Near the laser
  // the beams are closer together than a cell and most cells a beam passes are passed by its
  // neighbours too (freiburg-079: 24 k steps per scan for 7.5 k cells). Beam i's covering beams are
  // i - h and i + h, h the largest power of two dividing i (beam 0 has none). A cell that beam i
  // passes and that neither covering beam passes through lies inside the wedge between them; within
  // distance rho of the laser that wedge is 2 rho sin(h inc) wide across beam i, and the cell is at
  // least |cos| + |sin| of the beam's direction wide in that direction (a unit square). So while
  // the wedge is narrower than the cell, and both covering beams pass more than 1.5 cells beyond
  // rho (the cell is not their end cell), every cell that beam i passes wholly within rho is passed
  // by a covering beam: by its walk, or, where that walk starts later, by the covering beams of a
  // coarser level still (the induction ends at beams that start at the laser). Beam i's walk starts
  // at distance rho - 1.5 (the cells before lie wholly within rho). The maps are the same cell for
  // cell as with every walk starting at the laser (tests; BENCHMARK.md, mapping). The TSDF updates
  // each cell once per beam and walks every beam from the laser.
  const bool cover = model() != MapModel::kTsdf;
  const std::vector<double>& reach_per_width = out.reach_per_width_;
  const std::size_t levels = reach_per_width.size();
  for (std::size_t i = 0; i < n; ++i) {
    const double len = out.lengths_[i];
    if (len <= 0) continue;
    const double ca = out.units_[i].x(), sa = out.units_[i].y();
    const Eigen::Vector2d dir(c0 * ca - s0 * sa, s0 * ca + c0 * sa);
    const Eigen::Vector2d end = origin + dir * len;
    grow(end);
    double start = 0;  // [cells]
    const auto z = static_cast<std::size_t>(std::countr_zero(i));
    if (cover && i > 0 && z < levels) {
      const std::size_t a = i - (std::size_t{1} << z), b = i + (std::size_t{1} << z);
      if (b < n && out.lengths_[a] > 0 && out.lengths_[b] > 0) {
        const double rho = std::min((std::abs(dir.x()) + std::abs(dir.y())) * reach_per_width[z],
                                    std::min(out.lengths_[a], out.lengths_[b]) - 1.5);
        start = std::clamp(rho - 1.5, 0.0, len);
      }
    }
    out.beams_.push_back(Beam{end, RayWalk(start > 0 ? Eigen::Vector2d(origin + dir * start) : origin, end),
                              scan.ranges()[i] * inv_res, out.hits_[i] != 0});
  }
  out.ready_ = true;
}

void OccupancyMap::insert(PreparedScan& prepared) {
  if (!prepared.ready_ || prepared.model_ != this)
    throw invalidArgument("scan not prepared by this map", ErrorLocation("", 0, "prepared"));
  prepared.ready_ = false;
  // The prepared beams become the current scan's (swapped, not copied: the caller gets the old
  // buffers back to prepare the next scan into).
  std::swap(beams_, prepared.beams_);
  std::swap(surfaces_, prepared.surfaces_);
  const Eigen::Vector2d origin = prepared.origin_;
  const CellBox box = prepared.box_;
  if (beams_.empty()) return;
  beginScan(unite(prepared.reserve_, box));
  std::optional<std::pair<Slab, Slab>> split;
  if (options_.insert.threads >= 2) {
    if (single_left_ > 0)
      --single_left_;
    else
      split = chooseSplit(origin, box);
  }
  cell_updates_ += split ? insertParallel(origin, split->first, split->second) : insertBeams(origin, beams_, Slab{}, 0);
  for (const Beam& b : beams_) cell_visits_ += static_cast<std::uint64_t>(b.walk.stepsLeft()) + 1;
  bounds_ = unite(bounds_, box);
}

std::unique_ptr<OccupancyMap> makeMap(MapModel model, const MapOptions& o) {
  const auto& l = o.logodds;
  auto prob = [](double p) { return std::isfinite(p) && p > 0.0 && p < 1.0; };
  if (!prob(l.hit_probability)) throw badOption("hit_probability", "must be in (0, 1)");
  if (!prob(l.miss_probability)) throw badOption("miss_probability", "must be in (0, 1)");
  if (!prob(l.min_probability) || !prob(l.max_probability) || l.min_probability >= l.max_probability)
    throw badOption("min_probability", "clamp bounds must satisfy 0 < min < max < 1");
  if (!(o.tsdf.truncation_m > 0) || !std::isfinite(o.tsdf.truncation_m))
    throw badOption("truncation_m", "must be positive");
  if (o.insert.threads < 1) throw badOption("threads", "must be at least 1");
  if (!(o.tsdf.max_weight >= 1 && o.tsdf.max_weight <= 1e6)) throw badOption("max_weight", "must be in [1, 1e6]");
  if (!(o.insert.max_range_m > 0 && o.insert.max_range_m <= 1e4))
    throw badOption("max_range_m", "must be in (0, 10000] m");
  if (!(o.insert.no_return_clear_m >= 0 && o.insert.no_return_clear_m <= 1e4))
    throw badOption("no_return_clear_m", "must be in [0, 10000] m");
  if (!(o.insert.surface_guard_max_m >= 0 && o.insert.surface_guard_max_m <= 100))
    throw badOption("surface_guard_max_m", "must be in [0, 100] m");
  if (!(o.insert.surface_neighbor_max_m > 0 && o.insert.surface_neighbor_max_m <= 100))
    throw badOption("surface_neighbor_max_m", "must be in (0, 100] m");
  switch (model) {
    case MapModel::kLogOdds:
      return std::make_unique<LogOddsMap>(o);
    case MapModel::kCount:
      return std::make_unique<CountMap>(o);
    case MapModel::kTsdf:
      return std::make_unique<TsdfMap>(o);
  }
  throw badOption("model", "unknown map model");
}

std::vector<SurfacePoint> tsdfSurface(const OccupancyMap& map) {
  const auto* tsdf = dynamic_cast<const TsdfMap*>(&map);
  if (!tsdf) throw invalidArgument("tsdfSurface needs a TSDF map");
  std::vector<SurfacePoint> out;
  const auto& grid = tsdf->grid();
  const double res = map.geometry().resolution();
  grid.forEachTile([&](CellIndex origin, const TsdfCell* cells) {
    for (int y = 0; y < TiledGrid<TsdfCell>::kTileSize; ++y)
      for (int x = 0; x < TiledGrid<TsdfCell>::kTileSize; ++x) {
        const TsdfCell& a = cells[(y << TiledGrid<TsdfCell>::kTileBits) | x];
        if (a.weight <= 0) continue;
        const CellIndex ca{origin.x + x, origin.y + y};
        for (const auto& d : {CellIndex{1, 0}, CellIndex{0, 1}}) {
          const TsdfCell& b = grid.get(CellIndex{ca.x + d.x, ca.y + d.y});
          if (b.weight <= 0 || (a.sdf >= 0) == (b.sdf >= 0)) continue;
          // Linear interpolation of the zero crossing between the two cell centres.
          const double f = a.sdf / (a.sdf - b.sdf);
          const Eigen::Vector2d pa((ca.x + 0.5) * res, (ca.y + 0.5) * res);
          out.push_back({pa + f * res * Eigen::Vector2d(d.x, d.y), std::min(a.weight, b.weight)});
        }
      }
  });
  return out;
}

ClassifiedGrid classify(const OccupancyMap& map, int pad_cells) {
  ClassifiedGrid g;
  g.resolution_m = map.geometry().resolution();
  g.box = map.bounds();
  if (g.box.empty()) return g;
  g.box.min.x -= pad_cells;
  g.box.min.y -= pad_cells;
  g.box.max.x += pad_cells;
  g.box.max.y += pad_cells;
  g.cells.resize(static_cast<std::size_t>(g.width() * g.height()));
  for (std::int32_t y = g.box.min.y; y <= g.box.max.y; ++y)
    for (std::int32_t x = g.box.min.x; x <= g.box.max.x; ++x)
      g.cells[static_cast<std::size_t>((y - g.box.min.y) * g.width() + (x - g.box.min.x))] = map.state({x, y});
  return g;
}

GridGeometry::GridGeometry(double resolution_m) : resolution_(resolution_m), inv_resolution_(1.0 / resolution_m) {
  if (!std::isfinite(resolution_m) || resolution_m < 1e-4 || resolution_m > 100.0)
    throw invalidArgument(fmt::format("must be between 0.0001 and 100 m (got {:g})", resolution_m),
                          ErrorLocation("", 0, "resolution"));
}

}  // namespace lidar2d::mapping
