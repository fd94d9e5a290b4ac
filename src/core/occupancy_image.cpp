#include "lidar2d/core/occupancy_image.hpp"

#include <fmt/format.h>

#include <cassert>
#include <cmath>

#include "lidar2d/core/error.hpp"

namespace lidar2d {

OccupancyImage OccupancyImage::create(int width, int height, double resolution_m, const SE2& origin,
                                      std::vector<std::int8_t> cells) {
  const ErrorLocation where({}, 0, "occupancy image");
  if (width < 1 || height < 1) throw invalidArgument(fmt::format("width and height must be >= 1, got {} x {}", width, height), where);
  if (static_cast<std::uint64_t>(width) * static_cast<std::uint64_t>(height) > kMaxCells)
    throw invalidArgument(fmt::format("{} x {} cells exceed the limit of 10^9", width, height), where);
  if (!(resolution_m >= kMinResolution && resolution_m <= kMaxResolution))
    throw invalidArgument(fmt::format("resolution must be between {} and {} m, got {}", kMinResolution, kMaxResolution,
                                      resolution_m),
                          where);
  if (!origin.isFinite() || std::abs(origin.x()) > kMaxOriginAbs || std::abs(origin.y()) > kMaxOriginAbs)
    throw invalidArgument(fmt::format("origin must be finite with |x|, |y| <= {:g} m", kMaxOriginAbs), where);
  if (cells.size() != static_cast<std::size_t>(width) * static_cast<std::size_t>(height))
    throw invalidArgument(fmt::format("{} cells given for {} x {}", cells.size(), width, height), where);
  for (std::size_t i = 0; i < cells.size(); ++i)
    if (cells[i] < -1 || cells[i] > 100)
      throw invalidArgument(fmt::format("cell {} has value {}, expected -1 or 0..100", i, static_cast<int>(cells[i])), where);
  OccupancyImage m;
  m.width_ = width;
  m.height_ = height;
  m.resolution_ = resolution_m;
  m.origin_ = origin;
  m.cells_ = std::move(cells);
  return m;
}

OccupancyImage OccupancyImage::filled(int width, int height, double resolution_m, const SE2& origin,
                                      std::int8_t value) {
  if (width < 1 || height < 1 || static_cast<std::uint64_t>(width) * static_cast<std::uint64_t>(height) > kMaxCells)
    return create(width, height, resolution_m, origin, {});  // throws with the right message
  return create(width, height, resolution_m, origin,
                std::vector<std::int8_t>(static_cast<std::size_t>(width) * static_cast<std::size_t>(height), value));
}

std::int8_t OccupancyImage::at(int col, int row) const {
  assert(contains(col, row));
  return cells_[static_cast<std::size_t>(row) * static_cast<std::size_t>(width_) + static_cast<std::size_t>(col)];
}

void OccupancyImage::set(int col, int row, std::int8_t value) {
  assert(contains(col, row) && value >= -1 && value <= 100);
  cells_[static_cast<std::size_t>(row) * static_cast<std::size_t>(width_) + static_cast<std::size_t>(col)] = value;
}

Eigen::Vector2d OccupancyImage::cellCenter(int col, int row) const {
  return origin_ * Eigen::Vector2d((col + 0.5) * resolution_, (row + 0.5) * resolution_);
}

std::optional<Eigen::Vector2i> OccupancyImage::worldToCell(const Eigen::Vector2d& p_world) const {
  const Eigen::Vector2d p = origin_.inverse() * p_world;
  const double cx = std::floor(p.x() / resolution_), cy = std::floor(p.y() / resolution_);
  if (!(cx >= 0 && cy >= 0 && cx < width_ && cy < height_)) return std::nullopt;
  return Eigen::Vector2i(static_cast<int>(cx), static_cast<int>(cy));
}

}  // namespace lidar2d
