#include "lidar2d/mapping/occupancy_map.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <utility>

#include "lidar2d/core/error.hpp"
#include "src/mapping/internal/models.hpp"
#include "src/mapping/internal/traversal.hpp"

namespace lidar2d::mapping {
namespace {

Error badOption(const std::string& field, const std::string& msg) {
  return invalidArgument(msg, ErrorLocation("", 0, field));
}

}  // namespace

using internal::unite;

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

void OccupancyMap::insert(const LaserScan& scan, const SE2& T_world_laser) {
  if (!prepared_) prepared_ = std::make_unique<PreparedScan>();
  prepare(scan, T_world_laser, *prepared_);
  insert(*prepared_);
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
      return internal::makeLogOddsMap(o);
    case MapModel::kCount:
      return internal::makeCountMap(o);
    case MapModel::kTsdf:
      return internal::makeTsdfMap(o);
  }
  throw badOption("model", "unknown map model");
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
