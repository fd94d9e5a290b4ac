#pragma once
// The data behind IcpTarget: the finite target points, their nearest-neighbour structure and line
// fits (built in icp_target.cpp). The correspondence search (icp_problem.cpp) reads it directly so
// that its nearest-neighbour queries inline.

#include <Eigen/Core>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <memory>
#include <vector>

#include "lidar2d/registration/icp.hpp"
#include "src/geometry/kdtree2.hpp"
#include "src/registration/internal/bearing_index.hpp"

namespace lidar2d::registration {

namespace internal {

// The finite points of `in`, in their order.
Points2 finitePoints(const Points2& in);
// True when `pts` is not empty and all its points lie within 1e-9 m of each other.
bool allSame(const Points2& pts);

}  // namespace internal

struct IcpTarget::Impl {
  Points2 points;
  Points2 normals;
  bool identical = false;
  std::unique_ptr<geometry::KdTree2> tree;          // NeighborSearch::kKdTree
  std::unique_ptr<internal::BearingIndex> bearing;  // NeighborSearch::kBearingWalk
  // Point-to-line's two-point lines (IcpOptions::two_point_lines): for each point whose
  // neighbourhood fits no line, the line through it and each of its fitted neighbours (those
  // within normal_max_radius_m; the nearest kMaxCornerLines at most), nearest first:
  // corner_count[i] entries from corner_slots * i.
  static constexpr std::size_t kMaxCornerLines = 8;
  struct CornerLine {
    std::uint32_t neighbor;  // index of the neighbour
    Eigen::Vector2d normal;  // unit normal of the line through the point and the neighbour
  };
  std::size_t corner_slots = 0;
  std::vector<std::uint8_t> corner_count;
  std::vector<CornerLine> corner_lines;

  // Keeps `pts` (finite), builds the search structure of `o.neighbor_search` and fits the lines.
  Impl(Points2 pts, const IcpOptions& o);

  [[gnu::always_inline]] std::size_t nearestWithin(const Eigen::Vector2d& p, double max_dist_sq, double* dist_sq,
                                                   std::uint32_t* hint) const {
    if (!p.allFinite()) {
      *dist_sq = std::numeric_limits<double>::infinity();
      return points.size();
    }
    if (bearing) return bearing->nearest(p, max_dist_sq, dist_sq, hint);
    const std::size_t j = tree->nearest(p, dist_sq);
    if (*dist_sq <= max_dist_sq) return j;
    *dist_sq = std::numeric_limits<double>::infinity();
    return points.size();
  }

  // Local line fit per target point (the "local line fit" variant of Censi 2008, section III: the
  // line through the nearest target points, here a total-least-squares fit over up to k of them,
  // which is less sensitive to range noise than the line through exactly two points).
  void computeNormals(const IcpOptions& o);
};

}  // namespace lidar2d::registration
