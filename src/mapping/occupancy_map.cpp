#include "lidar2d/mapping/occupancy_map.hpp"

#include <algorithm>
#include <array>
#include <atomic>
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

Error badOption(const std::string& field, const std::string& msg) {
  return invalidArgument(msg, ErrorLocation("", 0, field));
}

// Most beams on each side of an occluding edge that the surface guard spares (InsertOptions).
constexpr std::size_t kGuardNeighbors = 8;

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
  // Whether the current cell's tile has been looked up (`ref()` looks it up when not).
  bool hasTile() const { return tile_ != nullptr; }
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

  // Calls on_cell(Cell&) for each cell the walk leaves until `stop_at` steps are left (stop_at <=
  // stepsLeft()): the loop of `ref()` and `step()` in fewer instructions per cell (a pointer
  // follows the walk; the tile is looked up at each tile entry instead of testing every step for
  // one). For a walk whose every cell is accessed (no slab): it looks up the tile of each cell it
  // visits, as `ref()`, and no other.
  template <typename F>
  [[gnu::always_inline]] void run(std::int32_t stop_at, F&& on_cell) {
    const std::int32_t n = walk_.stepsLeft() - stop_at;
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
template <int kAxis, typename Cell, typename Far, typename Near>
[[gnu::always_inline]] inline void traceInSlabAlong(TiledGrid<Cell>& grid, const RayWalk& ray, std::int32_t lo,
                                                    std::int32_t hi, std::int32_t near_steps, Far&& on_far, Near&& on_near) {
  GridWalk<Cell> walk(grid, ray);
  // (kAxis a template parameter: the slab test then reads one coordinate without a branch.)
  auto inside = [&] {
    const std::int32_t v = kAxis == 0 ? walk.x() : walk.y();
    return v >= lo && v < hi;
  };
  while (!walk.done() && !inside()) walk.step();
  while (!walk.done() && inside()) {
    if (walk.stepsLeft() > near_steps)
      on_far(walk);
    else
      on_near(walk);
    walk.step();
  }
}

// As above; the cells at most `near_steps` (>= 0) steps before the end cell go to on_near, the
// others to on_far (so that a test only the last cells need is not made for every cell).
// Unless `on_run` is null, the far cells of the whole walk (no slab) go to on_run(Cell&) instead,
// by GridWalk::run.
template <typename Cell, typename Far, typename Near, typename Run = std::nullptr_t>
[[gnu::always_inline]] inline void traceInSlab(TiledGrid<Cell>& grid, const RayWalk& ray, int axis, std::int32_t lo,
                                               std::int32_t hi, std::int32_t near_steps, Far&& on_far, Near&& on_near,
                                               Run&& on_run = nullptr) {
  if (axis < 0) {
    GridWalk<Cell> walk(grid, ray);  // traceRay
    if constexpr (!std::is_null_pointer_v<std::remove_cvref_t<Run>>) walk.run(near_steps, on_run);
    while (walk.stepsLeft() > near_steps) {  // (near_steps >= 0: not done)
      on_far(walk);
      walk.step();
    }
    while (!walk.done()) {
      on_near(walk);
      walk.step();
    }
  } else if (axis == 0) {
    traceInSlabAlong<0>(grid, ray, lo, hi, near_steps, on_far, on_near);
  } else {
    traceInSlabAlong<1>(grid, ray, lo, hi, near_steps, on_far, on_near);
  }
}

template <typename Cell, typename F>
[[gnu::always_inline]] inline void traceInSlab(TiledGrid<Cell>& grid, const RayWalk& ray, int axis, std::int32_t lo,
                                               std::int32_t hi, F&& on_pass) {
  traceInSlab(grid, ray, axis, lo, hi, 0, on_pass, on_pass);
}

// (Beams are walked cell by cell although near the sensor most cells a beam passes were already
// cleared by a neighbouring beam: clearing row runs per beam and skipping the runs already cleared
// removed those visits but cost more per row than the walk saves; BENCHMARK.md, mapping.)
// The cells a beam clears (log-odds, count), restricted to `slab`: each clearing stretch's cells
// from its start to its end cell inclusive (the stretch ends lie sqrt(2) cells from any guarded
// surface, so their cells hold none). A beam clearing up to its return (guard off) passes the cells
// before the return's cell, as `traceRay` does; the return's cell is a hit. `on_clear(at)` gets a
// GridWalk or a CellAt (see GridWalk). Without a slab, the passed cells go to on_run(cell, take)
// instead (all but the end cell of a beam clearing up to its return, and a stretch's last cell):
// take is false for a cell its guard spares (whose tile may then be left unallocated, as on_clear
// leaves it); at most `b.walk.stepsLeft()` of them per beam. The unguarded runs are walked by
// GridWalk::run, the guarded cells with the guard's test computed without a branch.
// (Templated on the map's protected Beam and Slab types, which it cannot name.)
template <typename Cell, typename BeamT, typename StretchT, typename SlabT, typename F, typename Run>
[[gnu::always_inline]] inline void forEachCleared(TiledGrid<Cell>& grid, const BeamT& b,
                                                  const std::vector<StretchT>& stretches, const SlabT& slab,
                                                  F&& on_clear, Run&& on_run) {
  constexpr double kMargin = 1e-6;  // see below
  auto run_all = [&on_run](Cell & cell) __attribute__((always_inline)) { on_run(cell, true); };
  // (`&`, not `&&`: one value, no branch on either comparison, which the processor mispredicted
  // often near returns and edges.)
  auto crosses = [](const auto& g, CellIndex c) __attribute__((always_inline))->bool {
    const double v = g.nx * c.x + g.ny * c.y + g.offset;
    return (v + g.corner_min < -kMargin) & (v + g.corner_max > kMargin);
  };
  // A guarded cell of a whole walk goes to on_run with whether the guard spares it; a spared
  // cell's tile is not looked up, as on_clear's callers do not look it up (rarely not yet).
  auto runGuarded = [&on_run](GridWalk<Cell> & walk, bool spared) __attribute__((always_inline)) {
    if (spared & !walk.hasTile()) return;
    on_run(walk.ref(), !spared);
  };
  if (b.clear_to_end) {
    if (b.own_guard) {
      // One walk: a beam meets its own surface line only at its return, so the cells of the beam
      // that the line passes through all lie near the return; `guard_reach_sq` caps how near.
      // Only the last `guard_steps` cells of the walk can be near the return.
      auto ownSpares = [&b, &crosses ](CellIndex c) __attribute__((always_inline))->bool {
        const double dx = c.x + 0.5 - b.guard_return.x(), dy = c.y + 0.5 - b.guard_return.y();
        return crosses(b.guards[0], c) & (dx * dx + dy * dy <= b.guard_reach_sq);
      };
      auto guarded = [&](auto& at) __attribute__((always_inline)) {
        if (!ownSpares(at.cell())) on_clear(at);
      };
      if (slab.axis < 0) {
        // The whole walk: the last cells too go to on_run (runGuarded).
        GridWalk<Cell> walk(grid, b.walk);
        walk.run(b.guard_steps, run_all);
        for (; !walk.done(); walk.step()) runGuarded(walk, ownSpares(walk.cell()));
      } else {
        traceInSlab(grid, b.walk, slab.axis, slab.lo, slab.hi, b.guard_steps, on_clear, guarded);
      }
    } else {
      traceInSlab(grid, b.walk, slab.axis, slab.lo, slab.hi, 0, on_clear, on_clear, run_all);
    }
    visitCell(grid, slab, cellOfCoords(b.end), on_clear);  // a hit's cell keeps its hit (stamp)
    return;
  }
  // A guarded stretch spares the cells whose open square one of its surface lines passes through:
  // the cell's corners lie on both sides of the line (n . (corner - p) takes both signs). The
  // margin keeps a line along a cell border (a wall at a multiple of the cell size) from catching
  // the cells on both sides through rounding [cells].
  // The stretches are runs of one walk over the beam (ClearStretch), so the beam is walked once.
  // (`lines` is the stretch's, so the branches on its bits are predicted.)
  auto spares = [&b, &crosses ](std::uint8_t lines, CellIndex c) __attribute__((always_inline))->bool {
    if (lines == 1) return crosses(b.guards[0], c);  // the common case: only the beam's own surface
    bool spared = false;
    for (std::size_t l = 0; l < 3; ++l)
      if (lines & (1u << l)) spared |= crosses(b.guards[l], c);
    return spared;
  };
  const StretchT* const st = stretches.data() + b.first_clear;
  const std::size_t n = b.num_clear;
  if (n == 0) return;  // (prepare gives every beam with clear_len > 0 a stretch; kept safe regardless)
  // inside(walk): the walk's cell is in the slab; past(walk): the walk has left it for good.
  auto walkStretches = [&](auto inside, auto past, auto whole) __attribute__((always_inline)) {
    constexpr bool kWhole = decltype(whole)::value;  // no slab: GridWalk::run for the unguarded runs
    GridWalk<Cell> walk(grid, b.walk);
    std::size_t k = 0;
    while (true) {
      // The cells of stretch k before its last one.
      const std::int32_t until = st[k].until;
      const std::uint8_t lines = st[k].lines;
      if (lines == 0) {
        if constexpr (kWhole) walk.run(until, run_all);
        while (walk.stepsLeft() > until) {
          if (past(walk)) return;
          if (inside(walk)) on_clear(walk);
          walk.step();
        }
      } else {
        if constexpr (kWhole)
          for (; walk.stepsLeft() > until; walk.step()) runGuarded(walk, spares(lines, walk.cell()));
        while (walk.stepsLeft() > until) {
          if (past(walk)) return;
          if (inside(walk) && !spares(lines, walk.cell())) on_clear(walk);
          walk.step();
        }
      }
      // Its last cell, which the next stretch starts from (and the ones after it that end there).
      const bool in = inside(walk);
      bool spared = in && lines != 0 && spares(lines, walk.cell());
      std::size_t j = k + 1;
      for (; j < n; ++j) {
        if (spared) spared = st[j].lines != 0 && spares(st[j].lines, walk.cell());
        if (st[j].until < until) break;
      }
      if (in && !spared) on_clear(walk);
      if (j == n || walk.done()) return;
      walk.step();
      k = j;
    }
  };
  if (slab.axis < 0) {
    walkStretches(
        [](const auto&) __attribute__((always_inline)) { return true; },
        [](const auto&) __attribute__((always_inline)) { return false; }, std::true_type{});
  } else {
    // Only the slab's cells are accessed; the walk is monotone along each axis, so once beyond the
    // slab's far side it stays outside.
    const int axis = slab.axis;
    const std::int32_t lo = slab.lo, hi = slab.hi;
    const bool ascending = (axis == 0 ? b.walk.stepX() : b.walk.stepY()) > 0;
    walkStretches(
        [ axis, lo, hi ](const auto& w) __attribute__((always_inline)) {
          const std::int32_t v = axis == 0 ? w.x() : w.y();
          return v >= lo && v < hi;
        },
        [ axis, lo, hi, ascending ](const auto& w) __attribute__((always_inline)) {
          const std::int32_t v = axis == 0 ? w.x() : w.y();
          return ascending ? v >= hi : v < lo;
        },
        std::false_type{});
  }
}

// forEachCleared over all beams, for the models that update a cell at most once per scan: the
// cells that go to on_run there are listed in `listed` as they are walked (its first n entries, n
// returned), and mark(cell, take) marks a taken cell as updated in this scan and says whether it
// is taken and was not marked yet (then the list's end moves past it). The caller updates the
// listed cells after the walks: this way no branch depends on a cell's mark, which the processor
// mispredicted about once in eight cells (freiburg-079, callgrind). The others go to
// on_clear(at), as in forEachCleared.
template <typename Cell, typename BeamT, typename StretchT, typename SlabT, typename F, typename Mark>
[[gnu::always_inline]] inline std::size_t clearAndList(TiledGrid<Cell>& grid, const std::vector<BeamT>& beams,
                                                       const std::vector<StretchT>& stretches, const SlabT& slab,
                                                       std::vector<Cell*>& listed, F&& on_clear, Mark&& mark) {
  std::size_t n = 0;
  for (const BeamT& b : beams) {
    // (Room for every cell of the beam, so that listing needs no test.)
    const std::size_t room = n + static_cast<std::size_t>(b.walk.stepsLeft()) + 1;
    if (listed.size() < room) listed.resize(std::max(room, 2 * listed.size()));
    Cell** const list = listed.data();
    forEachCleared(
        grid, b, stretches, slab, on_clear, [&](Cell & cell, bool take) __attribute__((always_inline)) {
          list[n] = &cell;
          n += mark(cell, take);
        });
  }
  return n;
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
    // Without a slab, the cleared cells are stamped as they are walked and updated after the walks
    // (clearAndList).
    std::vector<LogOddsCell*>& listed = listed_[static_cast<std::size_t>(part)].cells;
    const std::size_t num_listed = clearAndList(
        grid_, beams, clear_stretches_, slab,
        listed, [&](auto& at) __attribute__((always_inline)) { update(at.ref(), miss); },
        [scan](LogOddsCell & cell, bool take) __attribute__((always_inline)) {
          const bool fresh = cell.stamp != scan;
          cell.stamp = take ? scan : cell.stamp;
          return fresh & take;
        });
    for (std::size_t i = 0; i < num_listed; ++i) {
      LogOddsCell& cell = *listed[i];
      cell.value = std::clamp(cell.value + miss, lo, hi);
    }
    return updates + num_listed;
  }

 private:
  TiledGrid<LogOddsCell> grid_;
  // Cells of this scan listed for their update, per part (a cache line each, as for CountMap).
  struct alignas(64) Listed {
    std::vector<LogOddsCell*> cells;
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
    // Without a slab, the cleared cells are marked as they are walked and counted after the walks
    // (clearAndList).
    std::vector<HitMiss*>& listed = touched_[static_cast<std::size_t>(part)].listed;
    const std::size_t num_listed = clearAndList(
        grid_, beams, clear_stretches_, slab,
        listed, [&](auto& at) __attribute__((always_inline)) { update(at.ref(), false); },
        [](HitMiss & h, bool take) __attribute__((always_inline)) {
          const bool fresh = (h.misses & kMarker) == 0;
          h.misses |= take ? kMarker : 0u;
          return fresh & take;
        });
    for (HitMiss* h : touched) h->misses &= ~kMarker;
    for (std::size_t i = 0; i < num_listed; ++i) {
      HitMiss& h = *listed[i];
      const std::uint32_t v = h.misses & ~kMarker;
      h.misses = v + (v < kMarker - 1 ? 1u : 0u);
    }
    return touched.size() + num_listed;
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
  out.clear_stretches_.clear();
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
  // Beam directions in the laser frame, and for the surface guard (see InsertOptions::
  // surface_guard_max_m) each return's point and the unit direction of its surface: towards the
  // nearer neighbouring return within surface_neighbor_max_m (the farther one is more likely across
  // a depth jump), or else facing the beam.
  // (The directions depend only on the scan's angles, which a laser keeps from scan to scan: they
  // are computed again only when those change - the sines and cosines were 2% of `lidar2d map`.)
  if (out.units_.size() != n || out.units_angle_min_ != scan.angleMin() ||
      out.units_angle_increment_ != scan.angleIncrement()) {
    out.units_.resize(n);
    for (std::size_t i = 0; i < n; ++i) {
      const double a = scan.angle(i);
      out.units_[i] = Eigen::Vector2d(std::cos(a), std::sin(a));
    }
    out.units_angle_min_ = scan.angleMin();
    out.units_angle_increment_ = scan.angleIncrement();
  }
  out.hits_.assign(n, 0);
  for (std::size_t i = 0; i < n; ++i) out.hits_[i] = scan.isValid(i) && scan.ranges()[i] <= max_range;
  if (guard_max > 0) {
    out.points_.resize(n);
    out.tangents_.resize(n);
    for (std::size_t i = 0; i < n; ++i)
      if (out.hits_[i]) out.points_[i] = scan.ranges()[i] * out.units_[i];
    const double neighbor_max_sq = options_.insert.surface_neighbor_max_m * options_.insert.surface_neighbor_max_m;
    for (std::size_t i = 0; i < n; ++i) {
      if (!out.hits_[i]) continue;
      double best = neighbor_max_sq;
      out.tangents_[i] = Eigen::Vector2d(-out.units_[i].y(), out.units_[i].x());  // facing the beam
      for (const std::size_t j : {i - 1, i + 1}) {
        if (j >= n || !out.hits_[j]) continue;  // (i - 1 wraps to a huge index for i = 0)
        const Eigen::Vector2d t = out.points_[j] - out.points_[i];
        const double sq = t.squaredNorm();
        if (sq > 0 && sq <= best) {
          best = sq;
          out.tangents_[i] = t / std::sqrt(sq);
        }
      }
    }
  }
  auto cross = [](const Eigen::Vector2d& a, const Eigen::Vector2d& b) { return a.x() * b.y() - a.y() * b.x(); };
  // A cell holding two lines lies within sqrt(2) cells of each; two lines meeting at angle a are
  // within d of each other for d / sin(a) either side of their crossing.
  const double d = std::numbers::sqrt2 * geometry_.resolution();
  // How far either side of the crossing a beam meeting a line at sin_angle stays within d of it.
  auto halfWidth = [&](double sin_angle) { return sin_angle * guard_max > d ? d / sin_angle : guard_max; };
  // Edges of occluding surfaces: a return nearer than its neighbour on one side (by more than
  // 2 d, or that neighbour has no return) is the edge of a surface that the beams on that side
  // pass. Those beams, as far as they pass within 2 d of the edge, get a guarded stretch for the
  // edge's surface line (its own beam's surface): where they come within d of it. A beam keeps the
  // nearest edge on each side. Along a continuous surface nothing is needed: a beam's own guarded
  // stretch covers its neighbours' surface.
  if (guard_max > 0) {
    out.side_guards_.assign(2 * n, PreparedScan::SideGuard{});  // [2 i + slot]; none when to < from
    for (std::size_t j = 0; j < n; ++j) {
      if (!out.hits_[j]) continue;
      const double rj = scan.ranges()[j];
      const Eigen::Vector2d& p = out.points_[j];
      const Eigen::Vector2d& t = out.tangents_[j];
      for (const int side : {-1, 1}) {
        const std::size_t m = side < 0 ? j - 1 : j + 1;
        if (m >= n) continue;  // (wraps below 0)
        const double rm = scan.ranges()[m];
        if (out.hits_[m] && !(rm > rj + 2 * d)) continue;  // not an edge towards this side
        for (std::size_t k = 1; k <= kGuardNeighbors; ++k) {
          const std::size_t i = side < 0 ? j - k : j + k;
          if (i >= n) break;
          const double ri = scan.ranges()[i];
          if (std::isnan(ri) || ri <= scan.rangeMin()) continue;
          const Eigen::Vector2d& u = out.units_[i];
          const double along = p.dot(u), lateral = std::abs(cross(u, p));
          if (lateral >= 2 * d) break;  // farther beams pass farther from the edge
          if (out.hits_[i] && ri <= along) continue;  // ends before it passes the edge
          const double sin_angle = std::abs(cross(u, t));
          double centre = along;
          if (sin_angle * guard_max > d) {
            centre = cross(p, t) / cross(u, t);  // where the beam crosses the edge's surface line
            if (std::abs(centre - along) > guard_max) continue;
          } else if (lateral >= d) {
            continue;  // (nearly) parallel to it and never within d
          }
          const double h = halfWidth(sin_angle);
          PreparedScan::SideGuard& g = out.side_guards_[2 * i + (side > 0 ? 0 : 1)];  // seen from beam i, the edge is on the other side
          if (g.to < g.from || k < g.beams_away) g = PreparedScan::SideGuard{centre - h, centre + h, j, k};
        }
      }
    }
  }
  for (std::size_t i = 0; i < n; ++i) {
    const double r = scan.ranges()[i];
    if (std::isnan(r) || r <= scan.rangeMin()) continue;
    const bool hit = out.hits_[i];
    const double len = hit ? r + beyond : std::min(clear, std::isfinite(r) ? r : clear);
    if (len <= 0) continue;
    const double ca = out.units_[i].x(), sa = out.units_[i].y();
    const Eigen::Vector2d dir(c0 * ca - s0 * sa, s0 * ca + c0 * sa);
    const Eigen::Vector2d end = origin + dir * (len * inv_res);
    grow(end);
    Beam beam{end, RayWalk(origin, end), 0, 0, true, false, 0.0, 0, Eigen::Vector2d::Zero(), {}, r * inv_res, hit};
    if (guard_max > 0) {
      const Eigen::Vector2d u(ca, sa);
      const double clear_len = hit ? r : len;
      // Up to three guarded intervals [from, to] (metres from the laser), each with its surface
      // line: the beam's own surface (from where the beam comes within d of it to the return) and
      // the nearest occluding edge on each side (see above).
      std::array<std::array<double, 2>, 3> spans{};
      std::uint8_t lines = 0;
      auto setLine = [&](int k, std::size_t j, double from, double to) {
        const Eigen::Vector2d& t = out.tangents_[j];  // laser frame
        const Eigen::Vector2d point =
            origin + inv_res * Eigen::Vector2d(c0 * out.points_[j].x() - s0 * out.points_[j].y(), s0 * out.points_[j].x() + c0 * out.points_[j].y());
        const Eigen::Vector2d normal(-(s0 * t.x() + c0 * t.y()), c0 * t.x() - s0 * t.y());  // world, unit
        beam.guards[static_cast<std::size_t>(k)] =
            GuardLine{normal.x(), normal.y(), -normal.dot(point), std::min(normal.x(), 0.0) + std::min(normal.y(), 0.0),
                      std::max(normal.x(), 0.0) + std::max(normal.y(), 0.0)};
        spans[static_cast<std::size_t>(k)] = {std::max(from, 0.0), std::min(to, clear_len)};
        if (spans[static_cast<std::size_t>(k)][1] > spans[static_cast<std::size_t>(k)][0]) lines |= std::uint8_t(1u << k);
      };
      if (hit) {
        const double sin_incidence = std::abs(cross(out.tangents_[i], u));
        setLine(0, i, r - halfWidth(sin_incidence), r);
      }
      for (int k = 0; k < 2; ++k) {
        const PreparedScan::SideGuard& g = out.side_guards_[2 * i + static_cast<std::size_t>(k)];
        if (g.from <= g.to) setLine(1 + k, g.edge, g.from, g.to);
      }
      if (lines == 1) {  // only its own surface (no edge nearby): one walk, see forEachCleared
        beam.own_guard = true;
        beam.guard_return = origin + dir * (r * inv_res);
        const double reach = (r - spans[0][0]) * inv_res + 1.0;  // (+1: the cell centre may lie ahead of the walk)
        beam.guard_reach_sq = reach * reach;
        // A walk over a distance L takes at most |L dx| + |L dy| + 2 steps.
        beam.guard_steps = static_cast<std::int32_t>(std::ceil(reach * (std::abs(dir.x()) + std::abs(dir.y())))) + 2;
      } else if (lines != 0) {
        // Stretches between consecutive interval ends, each guarded by the lines covering it.
        std::array<double, 8> cuts{};
        std::size_t num_cuts = 0;
        cuts[num_cuts++] = 0.0;
        cuts[num_cuts++] = clear_len;
        for (std::size_t k = 0; k < 3; ++k)
          if (lines & (1u << k)) {
            cuts[num_cuts++] = spans[k][0];
            cuts[num_cuts++] = spans[k][1];
          }
        std::sort(cuts.begin(), cuts.begin() + static_cast<std::ptrdiff_t>(num_cuts));
        beam.clear_to_end = false;
        // Where a stretch ending `to` metres out ends on the beam's walk, as steps left (at most
        // `at_most`, the previous stretch's): the walk is monotone along each axis, so it reaches a
        // cell after as many steps as the cell lies from its first one, |dx| + |dy|.
        const CellIndex first = beam.walk.cell();
        const std::int32_t total = beam.walk.stepsLeft();
        auto untilAt = [&](double to, std::int32_t at_most) {
          const CellIndex c = cellOfCoords(origin + dir * (to * inv_res));
          const std::int64_t steps = std::abs(std::int64_t{c.x} - first.x) + std::abs(std::int64_t{c.y} - first.y);
          return static_cast<std::int32_t>(std::clamp<std::int64_t>(total - steps, 0, at_most));
        };
        for (std::size_t c = 0; c + 1 < num_cuts; ++c) {
          const double from = cuts[c], to = cuts[c + 1];
          if (!(to > from)) continue;
          const double mid = 0.5 * (from + to);
          std::uint8_t mask = 0;
          for (std::size_t k = 0; k < 3; ++k)
            if ((lines & (1u << k)) && spans[k][0] <= mid && mid <= spans[k][1]) mask |= std::uint8_t(1u << k);
          if (beam.num_clear > 0 && out.clear_stretches_.back().lines == mask) {  // continues the previous stretch
            const std::int32_t at_most =
                beam.num_clear > 1 ? out.clear_stretches_[out.clear_stretches_.size() - 2].until : total;
            out.clear_stretches_.back().until = untilAt(to, at_most);
            continue;
          }
          const std::int32_t at_most = beam.num_clear > 0 ? out.clear_stretches_.back().until : total;
          if (beam.num_clear++ == 0) beam.first_clear = static_cast<std::uint32_t>(out.clear_stretches_.size());
          out.clear_stretches_.push_back({untilAt(to, at_most), mask});
        }
      }
    }
    out.beams_.push_back(beam);
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
  std::swap(clear_stretches_, prepared.clear_stretches_);
  const Eigen::Vector2d origin = prepared.origin_;
  const CellBox box = prepared.box_;
  if (beams_.empty()) return;
  beginScan(box);
  std::optional<std::pair<Slab, Slab>> split;
  if (options_.insert.threads >= 2) {
    if (single_left_ > 0)
      --single_left_;
    else
      split = chooseSplit(origin, box);
  }
  cell_updates_ += split ? insertParallel(origin, split->first, split->second) : insertBeams(origin, beams_, Slab{}, 0);
  const std::int64_t ox = floorToInt32(origin.x()), oy = floorToInt32(origin.y());
  for (const Beam& b : beams_)
    cell_visits_ += static_cast<std::uint64_t>(std::abs(std::int64_t{floorToInt32(b.end.x())} - ox) +
                                               std::abs(std::int64_t{floorToInt32(b.end.y())} - oy) + 1);
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
    throw invalidArgument("must be between 0.0001 and 100 m (got " + std::to_string(resolution_m) + ")",
                          ErrorLocation("", 0, "resolution"));
}

}  // namespace lidar2d::mapping
