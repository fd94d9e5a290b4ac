#pragma once
// The branch-and-bound stages of the localizer's cascade (private to the localization module):
// the scan discretised once at every heading, searched over translation windows around candidate
// regions and, as the last resort, over the whole map, against the max-grids of a
// registration::CorrelativeGrid (Hess et al. 2016, section V: the score of a node at height h
// bounds every pose below it, so whole subtrees are skipped).

#include <Eigen/Core>
#include <chrono>
#include <cstddef>
#include <vector>

#include "lidar2d/core/laser_scan.hpp"
#include "lidar2d/core/se2.hpp"
#include "lidar2d/registration/correlative.hpp"

namespace lidar2d::localization::internal {

/// The best pose of one search: its grid score (mean max-grid value of the points, in [0, 1]);
/// score < 0 when the window held no pose.
struct GridPose {
  SE2 T_world_robot;
  double score = -1.0;
  bool complete = true;  ///< false: the deadline stopped the search (the best pose found so far)
};

/// The scan (robot frame) rotated by every heading of the circle and cut into the grid's cells,
/// once per query. Headings are spaced so that the farthest point moves by at most one cell (Hess
/// 2016, eq. 7).
class DiscretisedScan {
 public:
  DiscretisedScan(const registration::CorrelativeGrid& grid, const Points2& points_robot);
  std::size_t headings() const { return cells_.size(); }
  bool empty() const { return cells_.empty() || points_ == 0; }

  /// Best pose with its translation within `half_window_m` (a square) of `centre` (world frame),
  /// at any heading. Stops at `deadline` (then complete = false).
  GridPose searchWindow(const Eigen::Vector2d& centre, double half_window_m,
                        std::chrono::steady_clock::time_point deadline) const;
  /// Best pose over the whole grid and every heading; stops at `deadline`.
  GridPose searchAll(std::chrono::steady_clock::time_point deadline) const;

 private:
  struct Node {
    int k, ix, iy;
    float score;
  };
  double scoreAt(int k, int ix, int iy, int h) const;
  // Depth-first branch and bound from `roots` (all of height h), translations within [lo, hi].
  GridPose search(std::vector<Node> roots, int h, const Eigen::Vector2i& lo, const Eigen::Vector2i& hi,
                  std::chrono::steady_clock::time_point deadline) const;

  const registration::CorrelativeGrid* grid_;
  std::size_t points_ = 0;
  double step_ = 0;
  std::vector<std::vector<Eigen::Vector2i>> cells_;  // per heading k (theta = -pi + k step), per point
  std::vector<Eigen::Vector2i> lo_, hi_;             // per heading, the box of its cells
};

}  // namespace lidar2d::localization::internal
