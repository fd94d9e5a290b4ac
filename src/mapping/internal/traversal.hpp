#pragma once
// Cell traversals of map insertion over a TiledGrid: a RayWalk that follows the cell's place in its
// tile (GridWalk), the walks restricted to one thread's slab of the grid, the cells a beam clears,
// and the surface guard's cells. Private to the mapping module.

#include <Eigen/Core>
#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <type_traits>
#include <vector>

#include "lidar2d/mapping/ray_trace.hpp"
#include "lidar2d/mapping/tiled_grid.hpp"

namespace lidar2d::mapping::internal {

// The cell holding `p`, a point in continuous cell coordinates.
[[gnu::always_inline]] inline CellIndex cellOfCoords(const Eigen::Vector2d& p) {
  return {floorToInt32(p.x()), floorToInt32(p.y())};
}

// The smallest box holding both boxes (an empty box adds nothing).
inline CellBox unite(CellBox a, const CellBox& b) {
  if (a.empty()) return b;
  if (b.empty()) return a;
  a.min.x = std::min(a.min.x, b.min.x);
  a.min.y = std::min(a.min.y, b.min.y);
  a.max.x = std::max(a.max.x, b.max.x);
  a.max.y = std::max(a.max.y, b.max.y);
  return a;
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
// where its covering beams stop passing all its cells, see OccupancyMap::prepare.)
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
// this way no branch depends on a cell's mark, which the processor predicts poorly. The others go
// to on_clear(at), as in forEachCleared.
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

}  // namespace lidar2d::mapping::internal
