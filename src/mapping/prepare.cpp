// OccupancyMap::prepare: a scan's beams in cell coordinates, where each beam's walk starts, and
// the surface guard's segments.

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>
#include <numbers>
#include <vector>

#include "lidar2d/core/error.hpp"
#include "lidar2d/mapping/occupancy_map.hpp"
#include "src/mapping/internal/traversal.hpp"

namespace lidar2d::mapping {
namespace {

// Where a beam's walk may start (OccupancyMap::prepare): the share of a cell's width that the wedge
// between its two covering beams may reach (1 is the geometric limit; the rest is a margin).
constexpr double kCoverWidth = 0.9;

}  // namespace

using internal::cellOfCoords;
using internal::unite;

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
  out.surfaces_.clear();
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
  // Beam directions in the laser frame, and how far each level of covering beams reaches per unit
  // of a cell's width (see below).
  // (The directions depend only on the scan's angles, which a laser keeps from scan to scan: they
  // are computed again only when those change.)
  if (out.units_.size() != n || out.units_angle_min_ != scan.angleMin() ||
      out.units_angle_increment_ != scan.angleIncrement()) {
    out.units_.resize(n);
    for (std::size_t i = 0; i < n; ++i) {
      const double a = scan.angle(i);
      out.units_[i] = Eigen::Vector2d(std::cos(a), std::sin(a));
    }
    // kCoverWidth / (2 sin(h inc)) for h = 2^z, while the wedge (2 h inc) is well under a half turn.
    // (inc is finite and non-zero: LaserScan checks it.)
    const double inc = std::abs(scan.angleIncrement());
    out.reach_per_width_.clear();
    for (int z = 0; z < 63 && std::ldexp(inc, z) < 1.5; ++z)
      out.reach_per_width_.push_back(kCoverWidth / (2.0 * std::sin(std::ldexp(inc, z))));
    out.units_angle_min_ = scan.angleMin();
    out.units_angle_increment_ = scan.angleIncrement();
  }
  out.hits_.assign(n, 0);
  for (std::size_t i = 0; i < n; ++i) out.hits_[i] = scan.isValid(i) && scan.ranges()[i] <= max_range;
  out.reserve_ = CellBox{};                            // (empty)
  auto toWorldCells = [&](const Eigen::Vector2d& p) {  // a point in the laser frame [m] -> [cells]
    return Eigen::Vector2d(origin + inv_res * Eigen::Vector2d(c0 * p.x() - s0 * p.y(), s0 * p.x() + c0 * p.y()));
  };
  if (guard_max > 0) {
    // The surface guard's segments (InsertOptions::surface_guard_max_m), in the laser frame first.
    out.points_.resize(n);
    for (std::size_t i = 0; i < n; ++i)
      if (out.hits_[i]) out.points_[i] = scan.ranges()[i] * out.units_[i];
    // Each return's nearer neighbouring return, if within reach.
    const double reach = std::min(options_.insert.surface_neighbor_max_m, guard_max);
    out.neighbors_.assign(n, n);
    for (std::size_t i = 0; i < n; ++i) {
      if (!out.hits_[i]) continue;
      double best = reach * reach;
      for (const std::size_t j : {i - 1, i + 1}) {
        if (j >= n || !out.hits_[j]) continue;  // (i - 1 wraps to a huge index for i = 0)
        const double sq = (out.points_[j] - out.points_[i]).squaredNorm();
        if (sq > 0 && sq <= best) {
          best = sq;
          out.neighbors_[i] = j;
        }
      }
    }
    auto joined = [&](std::size_t a, std::size_t b) { return out.neighbors_[a] == b || out.neighbors_[b] == a; };
    auto cross = [](const Eigen::Vector2d& a, const Eigen::Vector2d& b) { return a.x() * b.y() - a.y() * b.x(); };
    const double edge_max = 2 * std::numbers::sqrt2 * geometry_.resolution();  // 2 sqrt(2) cells [m]
    for (std::size_t i = 0; i < n; ++i) {
      if (!out.hits_[i]) continue;
      const Eigen::Vector2d& p = out.points_[i];
      const Eigen::Vector2d from = toWorldCells(p);
      // The surface between this return and the next, when they are one surface.
      if (i + 1 < n && out.hits_[i + 1] && joined(i, i + 1))
        out.surfaces_.push_back({from, toWorldCells(out.points_[i + 1])});
      // Past an occluding edge towards each side: where the neighbour on that side is not on this
      // surface and lies farther (by more than edge_max) or has no return, the surface continues
      // (away from its other neighbour, or across the beam) to where that neighbour's beam passes
      // it, at most edge_max.
      for (const int side : {-1, 1}) {
        const std::size_t m = side < 0 ? i - 1 : i + 1;
        if (m >= n) continue;  // (wraps below 0)
        if (out.hits_[m] && (joined(i, m) || !(scan.ranges()[m] > scan.ranges()[i] + edge_max))) continue;
        const std::size_t k = out.neighbors_[i];
        const Eigen::Vector2d along = k < n ? Eigen::Vector2d((p - out.points_[k]).normalized())
                                            : Eigen::Vector2d(-out.units_[i].y() * side, out.units_[i].x() * side);
        // p + l along meets beam m where cross(u_m, p + l along) = 0.
        const double den = cross(out.units_[m], along);
        const double l = den != 0 ? -cross(out.units_[m], p) / den : edge_max;
        const Eigen::Vector2d to = toWorldCells(p + (l > 0 ? std::min(l, edge_max) : edge_max) * along);
        const CellIndex c = cellOfCoords(to);
        out.reserve_ = unite(out.reserve_, CellBox{c, c});
        out.surfaces_.push_back({from, to});
      }
    }
  }
  // Each beam's length [cells]; 0: no beam.
  out.lengths_.resize(n);
  for (std::size_t i = 0; i < n; ++i) {
    const double r = scan.ranges()[i];
    double len = 0;
    if (!std::isnan(r) && r > scan.rangeMin())
      len = out.hits_[i] ? r + beyond : std::min(clear, std::isfinite(r) ? r : clear);
    out.lengths_[i] = len > 0 ? len * inv_res : 0.0;
  }
  // Where each beam's walk starts. Log-odds and count update a cell at most once per scan, so only
  // the set of cells that the scan's beams pass matters, not which beam passes them. Near the laser
  // the beams are closer together than a cell and most cells a beam passes are passed by its
  // neighbours too. Beam i's covering beams are i - h and i + h, h the largest power of two
  // dividing i (beam 0 has none). A cell that beam i passes and that neither covering beam passes
  // through lies inside the wedge between them; within
  // distance rho of the laser that wedge is 2 rho sin(h inc) wide across beam i, and the cell is at
  // least |cos| + |sin| of the beam's direction wide in that direction (a unit square). So while
  // the wedge is narrower than the cell, and both covering beams pass more than 1.5 cells beyond
  // rho (the cell is not their end cell), every cell that beam i passes wholly within rho is passed
  // by a covering beam: by its walk, or, where that walk starts later, by the covering beams of a
  // coarser level still (the induction ends at beams that start at the laser). Beam i's walk starts
  // at distance rho - 1.5 (the cells before lie wholly within rho). The maps are the same cell for
  // cell as with every walk starting at the laser (Insertion.WalksStartingAwayFromTheLaserUpdateTheSameCells
  // in test_occupancy_map). The TSDF updates each cell once per beam and walks every beam from the laser.
  const bool cover = model() != MapModel::kTsdf;
  const std::vector<double>& reach_per_width = out.reach_per_width_;
  const std::size_t levels = reach_per_width.size();
  for (std::size_t i = 0; i < n; ++i) {
    const double len = out.lengths_[i];
    if (len <= 0) continue;
    const double ca = out.units_[i].x(), sa = out.units_[i].y();
    const Eigen::Vector2d dir(c0 * ca - s0 * sa, s0 * ca + c0 * sa);
    const Eigen::Vector2d end = origin + dir * len;
    grow(end);
    double start = 0;  // [cells]
    const auto z = static_cast<std::size_t>(std::countr_zero(i));
    if (cover && i > 0 && z < levels) {
      const std::size_t a = i - (std::size_t{1} << z), b = i + (std::size_t{1} << z);
      if (b < n && out.lengths_[a] > 0 && out.lengths_[b] > 0) {
        const double rho = std::min((std::abs(dir.x()) + std::abs(dir.y())) * reach_per_width[z],
                                    std::min(out.lengths_[a], out.lengths_[b]) - 1.5);
        start = std::clamp(rho - 1.5, 0.0, len);
      }
    }
    out.beams_.push_back(Beam{end, RayWalk(start > 0 ? Eigen::Vector2d(origin + dir * start) : origin, end),
                              scan.ranges()[i] * inv_res, out.hits_[i] != 0});
  }
  out.ready_ = true;
}

}  // namespace lidar2d::mapping
