// Branch and bound over candidate regions and over the whole map (the cascade's verification
// stages after the descriptors; see internal/region_search.hpp and docs/localization.md).
// Hand-written rather than registration::matchCorrelative per region: one discretisation of the
// scan serves every region and the whole-map search, and the search must stop at a deadline.

#include "src/localization/internal/region_search.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>

namespace lidar2d::localization::internal {

using Clock = std::chrono::steady_clock;

DiscretisedScan::DiscretisedScan(const registration::CorrelativeGrid& grid, const Points2& points_robot)
    : grid_(&grid) {
  if (grid.empty()) return;
  const double res = grid.resolution();
  double d_max = res;
  std::size_t n = 0;
  for (const auto& p : points_robot)
    if (p.allFinite()) {
      d_max = std::max(d_max, p.norm());
      ++n;
    }
  points_ = n;
  if (n == 0) return;
  // Hess 2016 eq. 7: the farthest point moves by at most one cell per heading step.
  step_ = std::acos(1.0 - res * res / (2.0 * d_max * d_max));
  const auto headings = static_cast<std::size_t>(std::ceil(2.0 * std::numbers::pi / step_));
  step_ = 2.0 * std::numbers::pi / static_cast<double>(headings);
  cells_.resize(headings);
  for (std::size_t k = 0; k < headings; ++k) {
    const double th = -std::numbers::pi + static_cast<double>(k) * step_;
    const double c = std::cos(th) / res, s = std::sin(th) / res;
    auto& out = cells_[k];
    out.reserve(n);
    for (const auto& p : points_robot)
      if (p.allFinite())
        out.emplace_back(static_cast<int>(std::floor(c * p.x() - s * p.y())),
                         static_cast<int>(std::floor(s * p.x() + c * p.y())));
  }
  for (const auto& cells : cells_) {
    const auto [lo, hi] = registration::CorrelativeGrid::boxOf(cells);
    lo_.push_back(lo);
    hi_.push_back(hi);
  }
}

double DiscretisedScan::scoreAt(int k, int ix, int iy, int h) const {
  const auto kk = static_cast<std::size_t>(k);
  return grid_->sumMaxValues(h, cells_[kk], ix, iy, lo_[kk], hi_[kk]) / static_cast<double>(points_);
}

GridPose DiscretisedScan::search(std::vector<Node> roots, int h, const Eigen::Vector2i& lo, const Eigen::Vector2i& hi,
                                 Clock::time_point deadline) const {
  GridPose out;
  Node best{0, 0, 0, -1.0f};
  std::size_t visited = 0;
  bool stopped = false;
  // Depth-first, best child first (Hess 2016, algorithm 3): a good leaf early prunes most nodes.
  auto recurse = [&](auto&& self, std::vector<Node>& nodes, int height) -> void {
    std::sort(nodes.begin(), nodes.end(), [](const Node& a, const Node& b) { return a.score > b.score; });
    for (const Node& c : nodes) {
      if (stopped || c.score <= best.score) return;  // sorted: nothing later can win either
      if (height == 0) {
        best = c;
        return;
      }
      if (++visited % 256 == 0 && Clock::now() > deadline) {
        stopped = true;
        return;
      }
      const int s = 1 << (height - 1);
      std::vector<Node> children;
      children.reserve(4);
      for (int dx : {0, s}) {
        if (c.ix + dx > hi.x()) continue;
        for (int dy : {0, s}) {
          if (c.iy + dy > hi.y()) continue;
          children.push_back({c.k, c.ix + dx, c.iy + dy, static_cast<float>(scoreAt(c.k, c.ix + dx, c.iy + dy, height - 1))});
        }
      }
      self(self, children, height - 1);
    }
  };
  (void)lo;
  recurse(recurse, roots, h);
  if (best.score < 0) {
    out.complete = !stopped;
    return out;
  }
  const double res = grid_->resolution();
  // The cell of a point is floor(R p / res) + (ix, iy): the translation is origin + (ix, iy) res.
  out.T_world_robot = SE2(grid_->origin().x() + best.ix * res, grid_->origin().y() + best.iy * res,
                          -std::numbers::pi + best.k * step_);
  out.score = best.score;
  out.complete = !stopped;
  return out;
}

GridPose DiscretisedScan::searchWindow(const Eigen::Vector2d& centre, double half_window_m,
                                       Clock::time_point deadline) const {
  if (empty()) return {};
  const double res = grid_->resolution();
  const int n = std::max(0, static_cast<int>(std::ceil(half_window_m / res - 1e-9)));
  const Eigen::Vector2i c(static_cast<int>(std::lround((centre.x() - grid_->origin().x()) / res)),
                          static_cast<int>(std::lround((centre.y() - grid_->origin().y()) / res)));
  const Eigen::Vector2i lo = c.array() - n, hi = c.array() + n;
  // Roots: the lowest height whose cells cover the window, so one root per heading (or a few).
  int h = 0;
  while (h + 1 < grid_->depth() && (1 << h) < 2 * n + 1) ++h;
  std::vector<Node> roots;
  for (int k = 0; k < static_cast<int>(cells_.size()); ++k)
    for (int ix = lo.x(); ix <= hi.x(); ix += 1 << h)
      for (int iy = lo.y(); iy <= hi.y(); iy += 1 << h) roots.push_back({k, ix, iy, static_cast<float>(scoreAt(k, ix, iy, h))});
  return search(std::move(roots), h, lo, hi, deadline);
}

GridPose DiscretisedScan::searchAll(Clock::time_point deadline) const {
  if (empty()) return {};
  // Every translation that puts the scan's origin on the grid.
  const Eigen::Vector2i lo(0, 0), hi(grid_->width() - 1, grid_->height() - 1);
  const int h = grid_->depth() - 1;
  std::vector<Node> roots;
  for (int k = 0; k < static_cast<int>(cells_.size()); ++k) {
    if (k % 64 == 0 && Clock::now() > deadline) {
      GridPose out;
      out.complete = false;
      return out;
    }
    for (int ix = lo.x(); ix <= hi.x(); ix += 1 << h)
      for (int iy = lo.y(); iy <= hi.y(); iy += 1 << h) roots.push_back({k, ix, iy, static_cast<float>(scoreAt(k, ix, iy, h))});
  }
  return search(std::move(roots), h, lo, hi, deadline);
}

}  // namespace lidar2d::localization::internal
