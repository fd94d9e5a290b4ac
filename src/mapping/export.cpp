#include "lidar2d/mapping/export.hpp"

#include <fmt/format.h>

#include <cmath>

#include "lidar2d/core/error.hpp"

namespace lidar2d::mapping {

OccupancyImage toOccupancyImage(const OccupancyMap& map, int pad_cells) {
  const ClassifiedGrid g = classify(map, pad_cells);
  if (g.box.empty()) throw badInput("the map is empty: no scan was inserted", ErrorLocation("", 0, "map"));
  std::vector<std::int8_t> cells(g.cells.size());
  for (std::size_t i = 0; i < cells.size(); ++i) cells[i] = static_cast<std::int8_t>(g.cells[i]);
  const double r = g.resolution_m;
  return OccupancyImage::create(static_cast<int>(g.width()), static_cast<int>(g.height()), r,
                                    SE2(g.box.min.x * r, g.box.min.y * r, 0.0), std::move(cells));
}

std::size_t applyPrior(OccupancyImage& map, const OccupancyImage& prior) {
  if (std::abs(prior.resolution() - map.resolution()) > 1e-9 * map.resolution())
    throw badInput(fmt::format("prior has resolution {:g} m, the map {:g} m", prior.resolution(), map.resolution()),
                   ErrorLocation("", 0, "resolution"));
  std::size_t n = 0;
  for (int row = 0; row < map.height(); ++row)
    for (int col = 0; col < map.width(); ++col) {
      const auto c = prior.worldToCell(map.cellCenter(col, row));
      if (!c) continue;
      const std::int8_t v = prior.at(c->x(), c->y());
      if (v == OccupancyImage::kOccupied || v == OccupancyImage::kFree) {
        n += map.at(col, row) != v;
        map.set(col, row, v);
      }
    }
  return n;
}

std::size_t applyPriorSameSize(OccupancyImage& map, const std::vector<std::int8_t>& prior, int width, int height) {
  if (width != map.width() || height != map.height())
    throw badInput("prior is " + std::to_string(width) + " x " + std::to_string(height) + " pixels but the map is " +
                       std::to_string(map.width()) + " x " + std::to_string(map.height()),
                   ErrorLocation("", 0, "size"));
  std::size_t n = 0;
  for (int row = 0; row < height; ++row)
    for (int col = 0; col < width; ++col) {
      const std::int8_t v = prior[static_cast<std::size_t>(row) * static_cast<std::size_t>(width) + static_cast<std::size_t>(col)];
      if (v == OccupancyImage::kOccupied || v == OccupancyImage::kFree) {
        n += map.at(col, row) != v;
        map.set(col, row, v);
      }
    }
  return n;
}

}  // namespace lidar2d::mapping
