#pragma once
/// @file
/// Exact grid traversal (Amanatides & Woo 1987, "A fast voxel traversal algorithm for ray tracing")
/// of a ray in a grid of unit cells: cell (x, y) spans [x, x+1) x [y, y+1) in continuous cell
/// coordinates. mapping/ray_trace.hpp's `RayWalk` has the same setup and step rule (with dir =
/// end - start) but stays separate: it walks a segment to a fixed end cell (a step budget per axis,
/// so that it ends exactly there despite rounding) in a loop tuned for map insertion, where
/// `GridRay` walks an open ray and knows the ray parameter at which it entered each cell.

#include <Eigen/Core>
#include <cmath>
#include <cstdint>
#include <limits>
#include <span>
#include <vector>

namespace lidar2d::geometry {

/// floor(v) as an integer, for finite v within the int32 range (as the cast of std::floor, which
/// on the baseline x86-64 target, without SSE4.1's rounding instruction, is a sequence of about 14
/// instructions and a branch). Exact: truncation toward zero, less one when that rounded up.
[[gnu::always_inline]] inline std::int32_t floorToInt32(double v) {
  const auto i = static_cast<std::int32_t>(v);
  return i - static_cast<std::int32_t>(v < static_cast<double>(i));
}

/// The cells of the ray p(t) = start + t dir, t >= 0 (continuous cell coordinates), in order: it
/// starts in the cell of `start` at t = 0; each `step()` moves to the next cell the ray enters, and
/// `t()` is then the parameter at which it entered. Where the ray crosses a cell corner it continues
/// into one of the two side cells (a tie steps in y), so the walk stays 4-connected. With a unit
/// `dir`, t is the distance travelled [cells]. Preconditions: finite inputs, dir != 0, start within
/// the int32 range; a walk that steps on forever leaves that range (the caller bounds it).
class GridRay {
 public:
  GridRay(const Eigen::Vector2d& start, const Eigen::Vector2d& dir)
      : x_(floorToInt32(start.x())), y_(floorToInt32(start.y())) {
    constexpr double kInf = std::numeric_limits<double>::infinity();
    step_x_ = dir.x() > 0 ? 1 : -1;
    step_y_ = dir.y() > 0 ? 1 : -1;
    // t between two crossings of x (y) cell boundaries, and t of the next crossing.
    t_delta_x_ = dir.x() != 0 ? 1.0 / std::abs(dir.x()) : kInf;
    t_delta_y_ = dir.y() != 0 ? 1.0 / std::abs(dir.y()) : kInf;
    t_next_x_ = dir.x() > 0 ? (x_ + 1 - start.x()) * t_delta_x_ : (dir.x() < 0 ? (start.x() - x_) * t_delta_x_ : kInf);
    t_next_y_ = dir.y() > 0 ? (y_ + 1 - start.y()) * t_delta_y_ : (dir.y() < 0 ? (start.y() - y_) * t_delta_y_ : kInf);
  }

  std::int32_t x() const { return x_; }
  std::int32_t y() const { return y_; }
  /// Ray parameter at which the ray entered the current cell (0 in the start cell).
  double t() const { return t_; }

  /// Moves to the next cell.
  void step() {
    if (t_next_x_ < t_next_y_) {
      t_ = t_next_x_;
      t_next_x_ += t_delta_x_;
      x_ += step_x_;
    } else {
      t_ = t_next_y_;
      t_next_y_ += t_delta_y_;
      y_ += step_y_;
    }
  }

 private:
  std::int32_t x_, y_;
  std::int32_t step_x_, step_y_;
  double t_delta_x_, t_delta_y_, t_next_x_, t_next_y_;
  double t_ = 0.0;
};

/// Casts the ray p(t) = start + t dir (see `GridRay`) through the grid of cells [0, width) x
/// [0, height) and returns the entry parameter t of the first cell along the ray for which
/// `hit(x, y)` is true (0 when it is the start cell); +inf when the ray leaves the grid first or
/// enters no such cell at t <= max_t. `hit` is called only for cells inside the grid.
template <typename Hit>
double castRay(const Eigen::Vector2d& start, const Eigen::Vector2d& dir, double max_t, std::int32_t width,
               std::int32_t height, Hit&& hit) {
  for (GridRay ray(start, dir); ray.t() <= max_t; ray.step()) {
    if (ray.x() < 0 || ray.y() < 0 || ray.x() >= width || ray.y() >= height) break;
    if (hit(ray.x(), ray.y())) return ray.t();
  }
  return std::numeric_limits<double>::infinity();
}

/// A grid of cells [0, width) x [0, height) that knows, for every cell, how much open space
/// surrounds it: `at(x, y)` is 0 on an obstacle cell, else 1 + floor(g) (at most 255), where g is
/// the Euclidean distance between the cell's square and the nearest obstacle cell's square (0 for
/// a neighbour of an obstacle). One byte per cell.
class ClearanceGrid {
 public:
  /// `obstacle[y * width + x]` != 0 marks an obstacle cell (the vector holds width x height
  /// values); width, height >= 0. Computed by `threads` threads (at least one; same result).
  ClearanceGrid(const std::vector<std::uint8_t>& obstacle, std::int32_t width, std::int32_t height,
                unsigned threads = 1);
  /// The same grid with the obstacle cells those of an occupancy grid's `values` (row-major,
  /// width x height of them) at least `occupied_min`, without a copy of the mask.
  ClearanceGrid(std::span<const std::int8_t> values, int occupied_min, std::int32_t width, std::int32_t height,
                unsigned threads = 1);
  std::int32_t width() const { return width_; }
  std::int32_t height() const { return height_; }
  /// Precondition: the cell is inside the grid (not checked).
  std::uint8_t at(std::int32_t x, std::int32_t y) const {
    return cells_[static_cast<std::size_t>(y) * static_cast<std::size_t>(width_) + static_cast<std::size_t>(x)];
  }

 private:
  template <class Obstacle>
  void build(Obstacle&& obstacle, unsigned threads);
  void columns(std::size_t x0, std::size_t x1);
  template <class Obstacle>
  void rows(const Obstacle& obstacle, std::size_t y0, std::size_t y1);
  std::int32_t width_, height_;
  std::vector<std::uint8_t> cells_;
};

namespace internal {

/// One stage of castRayInClearance for the ray at parameter *t: a leap, or a walk up to the next
/// leap. Returns true when the ray is done (its answer in *result), else advances *t.
[[gnu::always_inline]] inline bool advanceInClearance(const Eigen::Vector2d& start, const Eigen::Vector2d& dir,
                                                      double max_t, const ClearanceGrid& grid, double* t,
                                                      double* result) {
  constexpr double kInf = std::numeric_limits<double>::infinity();
  // A leap stops this short of the bound, for the rounding of the point it lands on.
  constexpr double kMargin = 1e-6;
  // Leaps of fewer cells than this are left to the walk (a leap costs more than a step).
  constexpr int kMinLeap = 2;
  const std::int32_t width = grid.width(), height = grid.height();
  if (*t > max_t) {
    *result = kInf;
    return true;
  }
  const Eigen::Vector2d p = start + *t * dir;
  const std::int32_t x = floorToInt32(p.x()), y = floorToInt32(p.y());
  if (x < 0 || y < 0 || x >= width || y >= height) {
    *result = kInf;
    return true;
  }
  const int v = grid.at(x, y);
  if (v == 0) {  // only where the ray starts: a leap never lands on an obstacle
    *result = *t;
    return true;
  }
  if (v - 1 >= kMinLeap) {
    *t += (v - 1) - kMargin;
    return false;
  }
  // Walk from p until an obstacle, or a cell with room to leap again.
  for (GridRay ray(p, dir);; ray.step()) {
    const double tc = *t + ray.t();
    if (tc > max_t || ray.x() < 0 || ray.y() < 0 || ray.x() >= width || ray.y() >= height) {
      *result = kInf;
      return true;
    }
    const int c = grid.at(ray.x(), ray.y());
    if (c == 0) {
      *result = tc;
      return true;
    }
    if (c - 1 >= kMinLeap) {
      *t = tc + (c - 1) - kMargin;  // the entry point lies on the closed square of this cell
      return false;
    }
  }
}

}  // namespace internal

/// `castRay` with `hit(x, y)` = "obstacle cell of `grid`", the same answer (the entry parameter of
/// the first obstacle cell, +inf when the ray leaves the grid or passes max_t first) up to rounding
/// (~1e-12 cells), but it leaps over open space instead of visiting every cell: from any point of a
/// cell whose square is g away from every obstacle square, the ray meets no obstacle cell before
/// it has gone g, so it resumes that far ahead; it walks cell by cell (GridRay) only near
/// obstacles. Preconditions: `dir` of unit length (t is then the distance in cells), finite
/// `start` within the int32 range.
inline double castRayInClearance(const Eigen::Vector2d& start, const Eigen::Vector2d& dir, double max_t,
                                 const ClearanceGrid& grid) {
  double t = 0.0, result = 0.0;
  while (!internal::advanceInClearance(start, dir, max_t, grid, &t, &result)) {
  }
  return result;
}

/// castRayInClearance of `n` rays from one start: out[i] is the answer for dirs[i], exactly as
/// castRayInClearance gives it. The rays advance in turns, so that the memory accesses of one
/// overlap those of the others (a single ray waits on each cell it reads).
void castRaysInClearance(const Eigen::Vector2d& start, const Eigen::Vector2d* dirs, std::size_t n, double max_t,
                         const ClearanceGrid& grid, double* out);

}  // namespace lidar2d::geometry
