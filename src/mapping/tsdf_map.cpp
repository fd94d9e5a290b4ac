// The 2D TSDF model (MapModel::kTsdf) and its sub-cell surface (tsdfSurface).

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <vector>

#include "lidar2d/core/error.hpp"
#include "src/mapping/internal/models.hpp"
#include "src/mapping/internal/traversal.hpp"

namespace lidar2d::mapping {
namespace {

using internal::cellOfCoords;
using internal::traceInSlab;
using internal::visitCell;

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

std::unique_ptr<OccupancyMap> internal::makeTsdfMap(const MapOptions& options) {
  return std::make_unique<TsdfMap>(options);
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

}  // namespace lidar2d::mapping
