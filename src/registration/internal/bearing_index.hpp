#pragma once
// Exact nearest-neighbour search over a 2D point set sorted by bearing from the frame's origin: the
// projective association of Censi's PL-ICP ("An ICP variant using a point-to-line metric", ICRA
// 2008, section IV: search the target's scan order around the query's bearing and stop early) made
// exact for any point set, not only scans.
//
// Why it is exact: a point's distance to the query q is at least the distance from q to the ray
// from the origin through that point, |q x u| = |q| sin|d| when q . u > 0 (u the ray's unit
// direction, d the bearing difference) and |q| otherwise. Walking outwards from q's bearing in both
// directions, that bound never decreases until the walk has turned by pi, so each direction stops at
// the first point whose bound is not below the best squared distance found so far; the two walks
// together cover every bearing. Points at the origin (no bearing) are checked one by one.
//
// Cost: a binary search for q's bearing and, for scans, a handful of points per query (the walk
// ends after a few beams at the range of a typical return) instead of a k-d tree descent; no tree
// to build, only a sort. Bearings are compared as a cheap monotone pseudo-angle (no atan2).

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <numeric>
#include <vector>

#include "lidar2d/core/laser_scan.hpp"

namespace lidar2d::registration::internal {

// A monotone function of atan2(y, x) onto [0, 4) ("diamond angle"); (0, 0) maps to 0.
inline double pseudoAngle(double x, double y) {
  const double s = std::abs(x) + std::abs(y);
  if (s == 0.0) return 0.0;
  if (y >= 0.0) return x >= 0.0 ? y / s : 1.0 - x / s;
  return x < 0.0 ? 2.0 - y / s : 3.0 + x / s;
}

class BearingIndex {
 public:
  // `pts` must be finite; they are copied (sorted by bearing).
  explicit BearingIndex(const Points2& pts) {
    std::vector<std::uint32_t> order;
    order.reserve(pts.size());
    for (std::size_t i = 0; i < pts.size(); ++i) {
      if (pts[i].squaredNorm() > 0.0)
        order.push_back(static_cast<std::uint32_t>(i));
      else
        at_origin_.push_back(static_cast<std::uint32_t>(i));
    }
    std::vector<double> key(pts.size());
    for (const std::uint32_t i : order) key[i] = pseudoAngle(pts[i].x(), pts[i].y());
    std::stable_sort(order.begin(), order.end(), [&](std::uint32_t a, std::uint32_t b) { return key[a] < key[b]; });
    nodes_.reserve(order.size());
    keys_.reserve(order.size());
    for (const std::uint32_t i : order) {
      const Eigen::Vector2d& p = pts[i];
      const double r = p.norm();
      nodes_.push_back({p.x(), p.y(), p.x() / r, p.y() / r, i});
      keys_.push_back(key[i]);
    }
    total_ = pts.size();
    // Bucket table over the pseudo-angle: bucket b starts at the first point with key >= b * 4 / B.
    std::size_t buckets = 64;
    while (buckets < 2 * keys_.size()) buckets *= 2;
    bucket_scale_ = static_cast<double>(buckets) / 4.0;
    bucket_start_.resize(buckets + 1);
    std::size_t i = 0;
    for (std::size_t b = 0; b <= buckets; ++b) {
      const double lo = static_cast<double>(b) / bucket_scale_;
      while (i < keys_.size() && keys_[i] < lo) ++i;
      bucket_start_[b] = static_cast<std::uint32_t>(i);
    }
  }

  std::size_t size() const { return total_; }

  // Index (into the constructor's `pts`) of the point nearest to q among those within
  // sqrt(max_dist_sq) of it, and its squared distance; size() and +inf when there is none.
  std::size_t nearest(const Eigen::Vector2d& q, double max_dist_sq, double* dist_sq) const {
    std::size_t best = total_;
    double best_d2 = max_dist_sq;
    auto consider = [&](const Node& nd) {
      const double dx = nd.x - q.x(), dy = nd.y - q.y();
      const double d2 = dx * dx + dy * dy;
      if (d2 < best_d2 || (best == total_ && d2 <= best_d2)) {
        best_d2 = d2;
        best = nd.index;
      }
    };
    walk(
        q, [&](const Node& nd) { consider(nd); }, [&] { return best_d2; });
    for (const std::uint32_t i : at_origin_) {
      const double d2 = q.squaredNorm();  // NaN for a non-finite query: never taken
      if (d2 < best_d2 || (best == total_ && d2 <= best_d2)) {
        best_d2 = d2;
        best = i;
      }
    }
    *dist_sq = best == total_ ? std::numeric_limits<double>::infinity() : best_d2;
    return best;
  }

  // Up to k nearest points within sqrt(max_dist_sq) of q, sorted by distance: indices into the
  // constructor's `pts` and squared distances; returns the count.
  std::size_t knn(const Eigen::Vector2d& q, std::size_t k, double max_dist_sq, std::uint32_t* idx, double* d2s) const {
    if (k == 0) return 0;
    std::size_t n = 0;
    auto insert = [&](std::uint32_t index, double d2) {
      if (d2 > max_dist_sq) return;
      if (n == k && !(d2 < d2s[k - 1])) return;
      std::size_t pos = n < k ? n++ : k - 1;
      while (pos > 0 && d2s[pos - 1] > d2) {
        d2s[pos] = d2s[pos - 1];
        idx[pos] = idx[pos - 1];
        --pos;
      }
      d2s[pos] = d2;
      idx[pos] = index;
    };
    walk(
        q,
        [&](const Node& nd) {
          const double dx = nd.x - q.x(), dy = nd.y - q.y();
          insert(nd.index, dx * dx + dy * dy);
        },
        [&] { return n == k ? d2s[k - 1] : max_dist_sq; });
    for (const std::uint32_t i : at_origin_) insert(i, q.squaredNorm());
    return n;
  }

 private:
  struct Node {
    double x, y;          // the point
    double ux, uy;        // its unit direction from the origin
    std::uint32_t index;  // position in the constructor's input
  };

  // Visits the points in bearing order outwards from q's bearing, both ways, each way until the
  // ray bound reaches limit() (strictly above it: ties are visited).
  template <class Visit, class Limit>
  void walk(const Eigen::Vector2d& q, Visit&& visit, Limit&& limit) const {
    const std::size_t n = nodes_.size();
    if (n == 0 || !q.allFinite()) return;  // a non-finite query has no neighbour
    const double qn2 = q.squaredNorm();
    const double kq = pseudoAngle(q.x(), q.y());
    // First point with key >= kq: from its bucket's start, a few steps at most.
    const auto b = std::min(static_cast<std::size_t>(kq * bucket_scale_), bucket_start_.size() - 2);
    std::size_t start = bucket_start_[b];
    const std::size_t end = bucket_start_[b + 1];
    while (start < end && keys_[start] < kq) ++start;
    if (start == n) start = 0;
    auto bound2 = [&](const Node& nd) {
      const double dot = q.x() * nd.ux + q.y() * nd.uy;
      if (dot <= 0.0) return qn2;
      const double cross = q.x() * nd.uy - q.y() * nd.ux;
      return cross * cross;
    };
    std::size_t visited = 0;
    std::size_t up = start, down = start == 0 ? n - 1 : start - 1;
    bool up_open = true, down_open = true;
    while ((up_open || down_open) && visited < n) {
      if (up_open) {
        const Node& nd = nodes_[up];
        if (bound2(nd) > limit()) {
          up_open = false;
        } else {
          visit(nd);
          ++visited;
          up = up + 1 == n ? 0 : up + 1;
        }
      }
      if (down_open && visited < n) {
        const Node& nd = nodes_[down];
        if (bound2(nd) > limit()) {
          down_open = false;
        } else {
          visit(nd);
          ++visited;
          down = down == 0 ? n - 1 : down - 1;
        }
      }
    }
  }

  std::vector<Node> nodes_;
  std::vector<double> keys_;
  std::vector<std::uint32_t> at_origin_;
  std::vector<std::uint32_t> bucket_start_;  // size B + 1
  double bucket_scale_ = 0.0;                // B / 4
  std::size_t total_ = 0;
};

}  // namespace lidar2d::registration::internal
