#include "lidar2d/mapping/occupancy_map.hpp"

#include <algorithm>
#include <array>
#include <cmath>

#include "lidar2d/core/error.hpp"
#include "lidar2d/mapping/ray_trace.hpp"

namespace lidar2d::mapping {
namespace {

double logit(double p) { return std::log(p / (1.0 - p)); }

Error badOption(const std::string& field, const std::string& msg) {
  return invalidArgument(msg, ErrorLocation("", 0, field));
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
struct LogOddsCell {
  float value = std::numeric_limits<float>::quiet_NaN();  // NaN: never observed
  std::uint32_t stamp = 0;                                 // last scan that updated the cell
};

class LogOddsMap final : public OccupancyMap {
 public:
  explicit LogOddsMap(const MapOptions& o) : OccupancyMap(o), grid_(LogOddsCell{}, o.insert.cell_budget) {
    const auto& l = o.logodds;
    if (l.classic_integer) {
      hit_ = 2.0f;
      miss_ = -1.0f;
      lo_ = 1.0f;
      hi_ = 100.0f;
      start_ = 50.0f;
    } else {
      hit_ = static_cast<float>(logit(l.hit_probability));
      miss_ = static_cast<float>(logit(l.miss_probability));
      lo_ = static_cast<float>(logit(l.min_probability));
      hi_ = static_cast<float>(logit(l.max_probability));
      start_ = 0.0f;
    }
  }
  MapModel model() const override { return MapModel::kLogOdds; }

  std::optional<double> probability(CellIndex c) const override {
    const float v = grid_.get(c).value;
    if (std::isnan(v)) return std::nullopt;
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
  std::uint64_t insertBeams(const Eigen::Vector2d& origin, const std::vector<Beam>& beams,
                            const CellBox& box) override {
    grid_.reserve(box);
    // Each cell is updated at most once per scan, hits first (as Cartographer's update marker,
    // Hess et al. 2016, section IV-B): a wall cell hit by one beam is not cleared by another beam of
    // the same scan that grazes it, and cells near the sensor crossed by many beams get one miss,
    // not dozens. A per-cell scan stamp says whether the cell was updated in this scan.
    ++scan_;
    std::uint64_t updates = 0;
    auto update = [this, &updates](LogOddsCell& cell, float delta) {
      if (cell.stamp == scan_) return;
      cell.stamp = scan_;
      const float base = std::isnan(cell.value) ? start_ : cell.value;  // NaN = never observed
      cell.value = std::clamp(base + delta, lo_, hi_);
      ++updates;
    };
    for (const Beam& b : beams)
      if (b.hit) update(grid_.cellUnchecked(CellIndex{static_cast<std::int32_t>(std::floor(b.end.x())),
                                                       static_cast<std::int32_t>(std::floor(b.end.y()))}),
                        hit_);
    for (const Beam& b : beams) {
      const CellIndex end = traceRay(origin, b.end, [&](CellIndex c) { update(grid_.cellUnchecked(c), miss_); });
      if (!b.hit) update(grid_.cellUnchecked(end), miss_);
    }
    return updates;
  }

 private:
  TiledGrid<LogOddsCell> grid_;
  std::uint32_t scan_ = 0;  // number of the scan being inserted (stamps start at 0 = none)
  float hit_, miss_, lo_, hi_, start_;
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
  std::uint64_t insertBeams(const Eigen::Vector2d& origin, const std::vector<Beam>& beams,
                            const CellBox& box) override {
    grid_.reserve(box);
    // At most one update per cell per scan, hits first, as for log-odds; the top bit of `misses`
    // marks the cells updated in this scan. Counts saturate below that bit.
    touched_.clear();
    auto update = [this](HitMiss& h, bool hit) {
      if (h.misses & kMarker) return;
      std::uint32_t& v = hit ? h.hits : h.misses;
      v += (v < kMarker - 1) ? 1u : 0u;
      h.misses |= kMarker;
      touched_.push_back(&h);
    };
    for (const Beam& b : beams)
      if (b.hit) update(grid_.cellUnchecked(CellIndex{static_cast<std::int32_t>(std::floor(b.end.x())),
                                                       static_cast<std::int32_t>(std::floor(b.end.y()))}),
                        true);
    for (const Beam& b : beams) {
      const CellIndex end = traceRay(origin, b.end, [&](CellIndex c) { update(grid_.cellUnchecked(c), false); });
      if (!b.hit) update(grid_.cellUnchecked(end), false);
    }
    for (HitMiss* h : touched_) h->misses &= ~kMarker;
    return touched_.size();
  }

 private:
  static constexpr std::uint32_t kMarker = 0x80000000u;
  TiledGrid<HitMiss> grid_;
  std::vector<HitMiss*> touched_;  // cells updated in the current scan
};

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
        trunc_cells_(static_cast<float>(o.tsdf.truncation_m * geometry_.inverseResolution())) {
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

  /// Occupied: the cell holds a zero crossing, i.e. a 4-neighbour has the opposite sign and the
  /// cell is the one nearer the surface (|sdf| not larger than the neighbour's). Free: observed,
  /// positive, no crossing. Cells behind the surface stay unknown.
  CellState state(CellIndex c) const override {
    const TsdfCell& v = grid_.get(c);
    if (v.weight <= 0) return CellState::kUnknown;
    static constexpr std::array<std::array<int, 2>, 4> kN{{{1, 0}, {-1, 0}, {0, 1}, {0, -1}}};
    for (const auto& d : kN) {
      const TsdfCell& n = grid_.get(CellIndex{c.x + d[0], c.y + d[1]});
      if (n.weight <= 0) continue;
      if ((v.sdf >= 0) != (n.sdf >= 0) && std::abs(v.sdf) <= std::abs(n.sdf)) return CellState::kOccupied;
    }
    return v.sdf > 0 ? CellState::kFree : CellState::kUnknown;
  }
  std::size_t memoryBytes() const override { return grid_.numAllocatedCells() * sizeof(TsdfCell); }

  const TiledGrid<TsdfCell>& grid() const { return grid_; }

 protected:
  std::uint64_t insertBeams(const Eigen::Vector2d& origin, const std::vector<Beam>& beams,
                            const CellBox& box) override {
    grid_.reserve(box);
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
      auto update = [&](CellIndex c) {
        const float sdf =
            b.hit ? std::clamp(offset - (dir_x * static_cast<float>(c.x) + dir_y * static_cast<float>(c.y)), -t, t) : t;
        TsdfCell& v = grid_.cellUnchecked(c);
        // Free-space carving (sdf at the truncation) leaves cells near a surface (|sdf| < t) alone:
        // beams grazing a wall clip the corners of the cells the wall passes through, and averaging
        // +t into them would move the zero crossing off the wall.
        if (sdf >= t && v.weight > 0 && v.sdf < t) return;
        // Weights are whole numbers up to the cap, so 1 / (w + 1) comes from a table.
        const auto w = static_cast<std::size_t>(v.weight);
        v.sdf += (sdf - v.sdf) * inv_weight_[w];
        v.weight = weight_next_[w];
        ++updates;
      };
      // For a return, b.end already lies `truncation` behind the surface (see insert()).
      const CellIndex end = traceRay(origin, b.end, update);
      update(end);
    }
    return updates;
  }

 private:
  TiledGrid<TsdfCell> grid_;
  const float trunc_cells_;
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

OccupancyMap::OccupancyMap(const MapOptions& options) : options_(options), geometry_(options.resolution_m) {}

void OccupancyMap::insert(const LaserScan& scan, const SE2& T_world_laser) {
  if (!T_world_laser.isFinite()) throw badInput("laser pose is not finite", ErrorLocation("", 0, "pose"));
  const double inv_res = geometry_.inverseResolution();
  // Cell coordinates must stay far inside int32 for the traversal; ranges are capped by the options
  // (<= 10 km), so bounding the pose bounds every endpoint. The cell budget catches the rest.
  if (std::abs(T_world_laser.x()) * inv_res > 1e9 || std::abs(T_world_laser.y()) * inv_res > 1e9)
    throw badInput("laser pose is absurdly far from the map origin", ErrorLocation("", 0, "pose"));
  const Eigen::Vector2d origin = geometry_.toCellCoords(T_world_laser.translation());
  const double max_range = options_.insert.max_range_m;
  const double clear = options_.insert.no_return_clear_m;
  // The TSDF traces past each return so that the cells just behind the surface get their negative
  // distance - but only a short way (behind_surface_m): walls are thinner than the truncation
  // distance, and a long negative band would reach into the room on the other side of the wall and
  // cancel its zero crossing when the two are averaged.
  const double beyond =
      model() == MapModel::kTsdf ? std::min(options_.tsdf.truncation_m, options_.tsdf.behind_surface_m) : 0.0;
  beams_.clear();
  CellBox box{geometry_.cellOf(T_world_laser.translation()), geometry_.cellOf(T_world_laser.translation())};
  auto grow = [&box](const Eigen::Vector2d& p) {
    const auto x = static_cast<std::int32_t>(std::floor(p.x())), y = static_cast<std::int32_t>(std::floor(p.y()));
    box.min.x = std::min(box.min.x, x);
    box.min.y = std::min(box.min.y, y);
    box.max.x = std::max(box.max.x, x);
    box.max.y = std::max(box.max.y, y);
  };
  const double c0 = std::cos(T_world_laser.theta()), s0 = std::sin(T_world_laser.theta());
  for (std::size_t i = 0; i < scan.size(); ++i) {
    const double r = scan.ranges()[i];
    if (std::isnan(r) || r <= scan.rangeMin()) continue;
    const bool hit = scan.isValid(i) && r <= max_range;
    const double len = hit ? r + beyond : std::min(clear, std::isfinite(r) ? r : clear);
    if (len <= 0) continue;
    const double a = scan.angle(i);
    const double ca = std::cos(a), sa = std::sin(a);
    const Eigen::Vector2d dir(c0 * ca - s0 * sa, s0 * ca + c0 * sa);
    const Eigen::Vector2d end = origin + dir * (len * inv_res);
    grow(end);
    beams_.push_back(Beam{end, r * inv_res, hit});
  }
  if (beams_.empty()) return;
  cell_updates_ += insertBeams(origin, beams_, box);
  const auto ox = static_cast<std::int64_t>(std::floor(origin.x())), oy = static_cast<std::int64_t>(std::floor(origin.y()));
  for (const Beam& b : beams_)
    cell_visits_ += static_cast<std::uint64_t>(std::abs(static_cast<std::int64_t>(std::floor(b.end.x())) - ox) +
                                               std::abs(static_cast<std::int64_t>(std::floor(b.end.y())) - oy) + 1);
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
  if (!(o.tsdf.max_weight >= 1 && o.tsdf.max_weight <= 1e6)) throw badOption("max_weight", "must be in [1, 1e6]");
  if (!(o.insert.max_range_m > 0 && o.insert.max_range_m <= 1e4))
    throw badOption("max_range_m", "must be in (0, 10000] m");
  if (!(o.insert.no_return_clear_m >= 0 && o.insert.no_return_clear_m <= 1e4))
    throw badOption("no_return_clear_m", "must be in [0, 10000] m");
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
