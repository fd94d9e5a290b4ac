#pragma once
/// @file
/// Exact grid traversal of a segment (Amanatides & Woo 1987, "A fast voxel traversal algorithm for
/// ray tracing"): every cell the segment passes through is visited exactly once, in order.

#include <Eigen/Core>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <limits>

#include "lidar2d/mapping/tiled_grid.hpp"

namespace lidar2d::mapping {

/// Visits the cells crossed by the segment from `start` to `end`, both in continuous cell
/// coordinates (cell (x, y) spans [x, x+1) x [y, y+1); see `GridGeometry::toCellCoords`).
/// `on_pass(CellIndex)` is called for each cell before the end cell, in order from the start; the
/// end cell is returned (not passed to `on_pass`). A segment through a cell corner continues into
/// one of the two side cells (the traversal stays 4-connected). Preconditions: finite inputs.
template <typename F>
CellIndex traceRay(const Eigen::Vector2d& start, const Eigen::Vector2d& end, F&& on_pass) {
  std::int32_t x = static_cast<std::int32_t>(std::floor(start.x()));
  std::int32_t y = static_cast<std::int32_t>(std::floor(start.y()));
  const auto ex = static_cast<std::int32_t>(std::floor(end.x()));
  const auto ey = static_cast<std::int32_t>(std::floor(end.y()));
  const double dx = end.x() - start.x(), dy = end.y() - start.y();
  constexpr double kInf = std::numeric_limits<double>::infinity();
  const std::int32_t step_x = dx > 0 ? 1 : -1, step_y = dy > 0 ? 1 : -1;
  // Parameter t in [0, 1] along the segment at which the next x (y) cell boundary is crossed.
  const double t_delta_x = dx != 0 ? 1.0 / std::abs(dx) : kInf;
  const double t_delta_y = dy != 0 ? 1.0 / std::abs(dy) : kInf;
  double t_max_x = dx > 0 ? (x + 1 - start.x()) * t_delta_x : (dx < 0 ? (start.x() - x) * t_delta_x : kInf);
  double t_max_y = dy > 0 ? (y + 1 - start.y()) * t_delta_y : (dy < 0 ? (start.y() - y) * t_delta_y : kInf);
  // The number of steps is fixed by the end cell; forcing the remaining axis once the other one has
  // arrived makes the walk end exactly at the end cell despite rounding near corners.
  std::int32_t left_x = std::abs(ex - x), left_y = std::abs(ey - y);
  while (left_x + left_y > 0) {
    on_pass(CellIndex{x, y});
    if (left_y == 0 || (left_x > 0 && t_max_x < t_max_y)) {
      x += step_x;
      t_max_x += t_delta_x;
      --left_x;
    } else {
      y += step_y;
      t_max_y += t_delta_y;
      --left_y;
    }
  }
  return CellIndex{x, y};
}

}  // namespace lidar2d::mapping
