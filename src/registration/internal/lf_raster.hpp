#pragma once
// Rasterisation helpers shared by the likelihood field and the correlative matcher: a scan's points
// joined into wall segments, and visiting the grid nodes near a segment or a point.

#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <limits>
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

/// The index range [i0, i1] x [j0, j1] of the nodes of `g` inside the box [lo, hi] (empty when
/// i0 > i1 or j0 > j1).
struct NodeRange {
  int i0, i1, j0, j1;
};
inline NodeRange nodesInBox(const NodeGrid& g, const Eigen::Vector2d& lo, const Eigen::Vector2d& hi) {
  return {std::max(0, static_cast<int>(std::ceil((lo.x() - g.origin.x()) / g.res))),
          std::min(g.w - 1, static_cast<int>(std::floor((hi.x() - g.origin.x()) / g.res))),
          std::max(0, static_cast<int>(std::ceil((lo.y() - g.origin.y()) / g.res))),
          std::min(g.h - 1, static_cast<int>(std::floor((hi.y() - g.origin.y()) / g.res)))};
}

/// Calls f(i, j, q) for every node q of `g` inside the box [lo, hi].
template <class F>
void forEachNodeInBox(const NodeGrid& g, const Eigen::Vector2d& lo, const Eigen::Vector2d& hi, F&& f) {
  const auto [i0, i1, j0, j1] = nodesInBox(g, lo, hi);
  for (int j = j0; j <= j1; ++j)
    for (int i = i0; i <= i1; ++i) f(i, j, Eigen::Vector2d(g.origin.x() + i * g.res, g.origin.y() + j * g.res));
}

/// Calls f(i, j, q) for the nodes q of `g` that may lie in the rectangle
/// {a + t u + d n : t0 <= t <= t1, |d| <= r} (u, n orthonormal): per row of nodes, the span where
/// both t and d are in range, widened by a node at each end against rounding. A superset of the
/// rectangle's nodes, never missing one, so the caller still tests each node exactly; it visits
/// about the rectangle's area instead of its bounding box's (for a short segment's band, a fifth).
template <class F>
void forEachNodeNearRectangle(const NodeGrid& g, const Eigen::Vector2d& a, const Eigen::Vector2d& u,
                              const Eigen::Vector2d& n, double t0, double t1, double r, F&& f) {
  Eigen::Vector2d lo(std::numeric_limits<double>::infinity(), std::numeric_limits<double>::infinity());
  Eigen::Vector2d hi = -lo;
  for (double t : {t0, t1})
    for (double d : {-r, r}) {
      const Eigen::Vector2d c = a + t * u + d * n;
      lo = lo.cwiseMin(c);
      hi = hi.cwiseMax(c);
    }
  const auto [i0, i1, j0, j1] = nodesInBox(g, lo, hi);
  constexpr double kFlat = 1e-12;  // a coefficient this small makes the row all in or all out
  const double inv_res = 1.0 / g.res;
  // Each condition m0 <= c * (x - a.x) + k <= m1, with k linear in the row's y.
  struct Condition {
    double c, inv_c, ky, m0, m1;
  };
  const Condition conds[2] = {{u.x(), std::abs(u.x()) < kFlat ? 0.0 : 1.0 / u.x(), u.y(), t0, t1},
                              {n.x(), std::abs(n.x()) < kFlat ? 0.0 : 1.0 / n.x(), n.y(), -r, r}};
  for (int j = j0; j <= j1; ++j) {
    const double y = g.origin.y() + j * g.res, dy = y - a.y();
    // x - a.x in [xl, xh]
    double xl = -std::numeric_limits<double>::infinity(), xh = std::numeric_limits<double>::infinity();
    bool empty = false;
    for (const Condition& cd : conds) {
      const double k = dy * cd.ky;
      if (std::abs(cd.c) < kFlat) {
        empty = empty || k < cd.m0 - 1e-9 || k > cd.m1 + 1e-9;
        continue;
      }
      double e0 = (cd.m0 - k) * cd.inv_c, e1 = (cd.m1 - k) * cd.inv_c;
      if (e0 > e1) std::swap(e0, e1);
      xl = std::max(xl, e0);
      xh = std::min(xh, e1);
    }
    if (empty || xl > xh) continue;
    const int il = std::max(i0, static_cast<int>(std::ceil((a.x() + xl - g.origin.x()) * inv_res)) - 1);
    const int ih = std::min(i1, static_cast<int>(std::floor((a.x() + xh - g.origin.x()) * inv_res)) + 1);
    for (int i = il; i <= ih; ++i) f(i, j, Eigen::Vector2d(g.origin.x() + i * g.res, y));
  }
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
