#pragma once
// Rasterisation helpers shared by the likelihood field and the correlative matcher: a scan's points
// joined into wall segments, and visiting the grid nodes near a segment or a point.

#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <vector>

#include "lidar2d/core/laser_scan.hpp"

namespace lidar2d::registration::internal {

struct Segment {
  Eigen::Vector2d a, b;
};

/// A scan's points as wall segments (consecutive points closer than `max_gap`) plus the points
/// that belong to no segment. Non-finite points are dropped (and break the polyline).
struct Polyline {
  std::vector<Segment> segments;
  std::vector<Eigen::Vector2d> isolated;
};

inline Polyline makePolyline(const Points2& pts, double max_gap) {
  Polyline out;
  const std::size_t n = pts.size();
  std::vector<char> used(n, 0);
  for (std::size_t i = 0; i + 1 < n; ++i) {
    const auto& a = pts[i];
    const auto& b = pts[i + 1];
    if (!a.allFinite() || !b.allFinite()) continue;
    const double d = (b - a).norm();
    if (d <= max_gap && d > 1e-9) {
      out.segments.push_back({a, b});
      used[i] = used[i + 1] = 1;
    }
  }
  for (std::size_t i = 0; i < n; ++i)
    if (!used[i] && pts[i].allFinite()) out.isolated.push_back(pts[i]);
  return out;
}

/// A grid of nodes: node (i, j) at origin + (i, j) * res, i in [0, w), j in [0, h).
struct NodeGrid {
  Eigen::Vector2d origin;
  double res;
  int w, h;
};

/// Calls f(i, j, q) for every node q of `g` inside the box [lo, hi].
template <class F>
void forEachNodeInBox(const NodeGrid& g, const Eigen::Vector2d& lo, const Eigen::Vector2d& hi, F&& f) {
  const int i0 = std::max(0, static_cast<int>(std::ceil((lo.x() - g.origin.x()) / g.res)));
  const int i1 = std::min(g.w - 1, static_cast<int>(std::floor((hi.x() - g.origin.x()) / g.res)));
  const int j0 = std::max(0, static_cast<int>(std::ceil((lo.y() - g.origin.y()) / g.res)));
  const int j1 = std::min(g.h - 1, static_cast<int>(std::floor((hi.y() - g.origin.y()) / g.res)));
  for (int j = j0; j <= j1; ++j)
    for (int i = i0; i <= i1; ++i) f(i, j, Eigen::Vector2d(g.origin.x() + i * g.res, g.origin.y() + j * g.res));
}

/// Bounding box of points (finite ones); returns false when there are none.
inline bool boundingBox(const Points2& pts, Eigen::Vector2d& lo, Eigen::Vector2d& hi) {
  bool any = false;
  for (const auto& p : pts) {
    if (!p.allFinite()) continue;
    if (!any) {
      lo = hi = p;
      any = true;
    } else {
      lo = lo.cwiseMin(p);
      hi = hi.cwiseMax(p);
    }
  }
  return any;
}

/// Unsigned distance of q to the segment.
inline double segmentDistance(const Segment& s, const Eigen::Vector2d& q) {
  const Eigen::Vector2d ab = s.b - s.a;
  const double t = std::clamp((q - s.a).dot(ab) / ab.squaredNorm(), 0.0, 1.0);
  return (q - (s.a + t * ab)).norm();
}

}  // namespace lidar2d::registration::internal
