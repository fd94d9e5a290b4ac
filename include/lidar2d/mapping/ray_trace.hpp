#pragma once
/// @file
/// Exact grid traversal of a segment (Amanatides & Woo 1987, "A fast voxel traversal algorithm for
/// ray tracing"): every cell the segment passes through is visited exactly once, in order. It walks
/// as geometry/ray_cast.hpp's `GridRay` (the open ray the localizer casts) does, specialised for map
/// insertion and kept separate for that loop's speed: a step budget per axis makes it end exactly
/// in its end cell, and `run` batches the steps.

#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <limits>

#include "lidar2d/geometry/ray_cast.hpp"
#include "lidar2d/mapping/tiled_grid.hpp"

namespace lidar2d::mapping {

using geometry::floorToInt32;

/// The state of an exact traversal of the segment `start` -> `end`, both in continuous cell
/// coordinates (cell (x, y) spans [x, x+1) x [y, y+1); see `GridGeometry::toCellCoords`). It starts
/// in the start cell; each `step()` moves to the next cell the segment enters; `done()` is true in
/// the end cell. A segment through a cell corner continues into one of the two side cells (the walk
/// stays 4-connected). The number of steps is fixed by the end cell; once one axis has arrived the
/// other is forced, so the walk ends exactly in the end cell despite rounding near corners.
/// Preconditions: finite inputs. Every traversal of mapping uses this one walk, so that all of them
/// visit the same cells in the same order.
class RayWalk {
 public:
  /// An empty walk (done, in cell (0, 0)); assign a real one before use.
  RayWalk() = default;
  // (Forced inline: the walk is the innermost loop of map insertion, and GCC stops inlining it into
  // the large insertion functions otherwise.)
  [[gnu::always_inline]] RayWalk(const Eigen::Vector2d& start, const Eigen::Vector2d& end)
      : x_(floorToInt32(start.x())), y_(floorToInt32(start.y())) {
    const std::int32_t ex = floorToInt32(end.x());
    const std::int32_t ey = floorToInt32(end.y());
    const double dx = end.x() - start.x(), dy = end.y() - start.y();
    constexpr double kInf = std::numeric_limits<double>::infinity();
    step_x_ = dx > 0 ? 1 : -1;
    step_y_ = dy > 0 ? 1 : -1;
    // Parameter t in [0, 1] along the segment at which the next x (y) cell boundary is crossed.
    t_delta_x_ = dx != 0 ? 1.0 / std::abs(dx) : kInf;
    t_delta_y_ = dy != 0 ? 1.0 / std::abs(dy) : kInf;
    t_max_x_ = dx > 0 ? (x_ + 1 - start.x()) * t_delta_x_ : (dx < 0 ? (start.x() - x_) * t_delta_x_ : kInf);
    t_max_y_ = dy > 0 ? (y_ + 1 - start.y()) * t_delta_y_ : (dy < 0 ? (start.y() - y_) * t_delta_y_ : kInf);
    left_x_ = std::abs(ex - x_);
    left_y_ = std::abs(ey - y_);
    // An axis with no step left never steps again: its next crossing is put at infinity, so that
    // `step` needs one comparison. A crossing still to come stays finite (a denormal extent
    // overflows t_delta to infinity; the largest finite value keeps the comparison's outcome).
    constexpr double kMax = std::numeric_limits<double>::max();
    t_max_x_ = left_x_ == 0 ? kInf : std::min(t_max_x_, kMax);
    t_max_y_ = left_y_ == 0 ? kInf : std::min(t_max_y_, kMax);
  }
  bool done() const { return left_x_ + left_y_ == 0; }
  /// Steps left to the end cell.
  std::int32_t stepsLeft() const { return left_x_ + left_y_; }
  std::int32_t x() const { return x_; }
  std::int32_t y() const { return y_; }
  CellIndex cell() const { return CellIndex{x_, y_}; }
  /// Direction of the walk's x and y steps (+1 or -1).
  std::int32_t stepX() const { return step_x_; }
  std::int32_t stepY() const { return step_y_; }
  /// Moves to the next cell; returns true when the step was along x. Precondition: !done().
  [[gnu::always_inline]] bool step() {
    // x when its crossing comes first, or y has arrived (its crossing is at infinity); ties go to
    // y. Once x has arrived (its crossing at infinity) y is forced.
    constexpr double kInf = std::numeric_limits<double>::infinity();
    if (t_max_x_ < t_max_y_) {
      x_ += step_x_;
      t_max_x_ = --left_x_ == 0 ? kInf : t_max_x_ + t_delta_x_;
      return true;
    }
    y_ += step_y_;
    t_max_y_ = --left_y_ == 0 ? kInf : t_max_y_ + t_delta_y_;
    return false;
  }

  /// Takes `n` steps (0 <= n <= stepsLeft()), calling visit() in each cell before leaving it: the
  /// loop of `step()` for a traversal that visits every cell it leaves, in fewer instructions per
  /// step. The same cells in the same order, by the same running sums. The cell's coordinates are
  /// not kept from step to step: the caller follows the walk by `on_x()` and `on_y()`, called after
  /// each x and y step, and by laps: every `lap`-th x step (the first after `first_lap_x` x steps)
  /// is followed, after its on_x(), by `on_lap(x, y, visited)` with the new cell's coordinates and
  /// whether it will be visited (false: the run ends in it); the same for y.
  /// (One counter per axis counts the steps to the next lap or to the axis' last step, whichever
  /// comes first, so that a step makes one test besides the choice of its axis. That choice stays a
  /// branch: a branch-free choice costs more instructions than the mispredictions it saves.)
  template <typename Visit, typename OnX, typename OnY, typename OnLap>
  [[gnu::always_inline]] void run(std::int32_t n, std::int32_t first_lap_x, std::int32_t first_lap_y, std::int32_t lap,
                                  Visit&& visit, OnX&& on_x, OnY&& on_y, OnLap&& on_lap) {
    constexpr double kInf = std::numeric_limits<double>::infinity();
    constexpr std::int32_t kNever = std::numeric_limits<std::int32_t>::max();
    std::int32_t x = x_, y = y_, left_x = left_x_, left_y = left_y_;
    std::int32_t lap_x = first_lap_x, lap_y = first_lap_y;
    double t_max_x = t_max_x_, t_max_y = t_max_y_;
    const double t_delta_x = t_delta_x_, t_delta_y = t_delta_y_;
    // Steps to the next event on each axis, counted down from `full_x` (`full_y`); kNever when
    // the axis has arrived (its crossing is at infinity, so it takes no more steps).
    std::int32_t full_x = left_x == 0 ? kNever : std::min(left_x, lap_x);
    std::int32_t full_y = left_y == 0 ? kNever : std::min(left_y, lap_y);
    std::int32_t count_x = full_x, count_y = full_y;
    for (; n > 0; --n) {
      visit();
      if (t_max_x < t_max_y) {
        t_max_x += t_delta_x;
        on_x();
        if (--count_x == 0) {
          x += step_x_ * full_x;
          left_x -= full_x;
          lap_x -= full_x;
          if (left_x == 0) t_max_x = kInf;
          if (lap_x == 0) {
            lap_x = lap;
            on_lap(x, y + step_y_ * (full_y == kNever ? 0 : full_y - count_y), n > 1);
          }
          count_x = full_x = left_x == 0 ? kNever : std::min(left_x, lap_x);
        }
      } else {
        t_max_y += t_delta_y;
        on_y();
        if (--count_y == 0) {
          y += step_y_ * full_y;
          left_y -= full_y;
          lap_y -= full_y;
          if (left_y == 0) t_max_y = kInf;
          if (lap_y == 0) {
            lap_y = lap;
            on_lap(x + step_x_ * (full_x == kNever ? 0 : full_x - count_x), y, n > 1);
          }
          count_y = full_y = left_y == 0 ? kNever : std::min(left_y, lap_y);
        }
      }
    }
    if (full_x != kNever) {
      x += step_x_ * (full_x - count_x);
      left_x -= full_x - count_x;
    }
    if (full_y != kNever) {
      y += step_y_ * (full_y - count_y);
      left_y -= full_y - count_y;
    }
    x_ = x;
    y_ = y;
    left_x_ = left_x;
    left_y_ = left_y;
    t_max_x_ = t_max_x;
    t_max_y_ = t_max_y;
  }

 private:
  std::int32_t x_ = 0, y_ = 0;
  std::int32_t step_x_ = 1, step_y_ = 1;
  double t_delta_x_ = 0.0, t_delta_y_ = 0.0, t_max_x_ = 0.0, t_max_y_ = 0.0;
  std::int32_t left_x_ = 0, left_y_ = 0;
};

/// Visits the cells crossed by the segment from `start` to `end` (see `RayWalk`): `on_pass(CellIndex)`
/// is called for each cell before the end cell, in order from the start; the end cell is returned
/// (not passed to `on_pass`).
template <typename F>
[[gnu::always_inline]] inline CellIndex traceRay(const Eigen::Vector2d& start, const Eigen::Vector2d& end, F&& on_pass) {
  RayWalk walk(start, end);
  while (!walk.done()) {
    on_pass(walk.cell());
    walk.step();
  }
  return walk.cell();
}

}  // namespace lidar2d::mapping
