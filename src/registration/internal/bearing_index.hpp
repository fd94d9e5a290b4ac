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
#include <bit>
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

// The next double above x (x itself when +inf or NaN): std::nextafter without the library call.
inline double nextUp(double x) {
  if (x >= 0.0 && x < std::numeric_limits<double>::infinity())
    return std::bit_cast<double>(std::bit_cast<std::uint64_t>(x) + 1);
  return std::nextafter(x, std::numeric_limits<double>::infinity());
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
    // Sorted by (key, index). A scan's points come nearly in that order: in beam order the
    // bearings from the laser increase, with one wrap of the pseudo-angle; from another origin (a
    // laser mounted off the robot's centre) a few neighbours swap where the range jumps. So the
    // order is first rotated at the wrap and insertion-sorted (a few moves), and sorted outright
    // only when that takes too many moves.
    const std::size_t m = order.size();
    auto before = [&](std::uint32_t a, std::uint32_t b) { return key[a] < key[b] || (key[a] == key[b] && a < b); };
    std::size_t rotate_at = 0;
    double biggest_drop = 0.0;
    for (std::size_t k = 0; k + 1 < m; ++k)
      if (const double drop = key[order[k]] - key[order[k + 1]]; drop > biggest_drop) {
        biggest_drop = drop;
        rotate_at = k + 1;
      }
    std::rotate(order.begin(), order.begin() + static_cast<std::ptrdiff_t>(rotate_at), order.end());
    std::size_t moves = 0;
    for (std::size_t k = 1; k < m && moves <= 8 * m; ++k) {
      const std::uint32_t v = order[k];
      std::size_t j = k;
      for (; j > 0 && before(v, order[j - 1]); --j) order[j] = order[j - 1];
      order[j] = v;
      moves += k - j;
    }
    if (moves > 8 * m) std::sort(order.begin(), order.end(), before);
    nodes_.reserve(order.size());
    keys_.reserve(order.size());
    for (const std::uint32_t i : order) {
      const Eigen::Vector2d& p = pts[i];
      const double r = p.norm();
      nodes_.push_back({p.x(), p.y(), p.x() / r, p.y() / r, i});
      keys_.push_back(key[i]);
    }
    keys_.push_back(std::numeric_limits<double>::infinity());  // sentinel (startOf)
    // The ring: the nodes with kPad copies of each end beyond the other, so that the fixed windows
    // around a position (nearest's first points, knnOfEach's neighbours) are read without the
    // wrap-around arithmetic of `offset`.
    if (!nodes_.empty()) {
      const auto n = static_cast<std::ptrdiff_t>(nodes_.size());
      ring_.reserve(nodes_.size() + 2 * kPad);
      for (std::ptrdiff_t j = -kPad; j < n + kPad; ++j) ring_.push_back(nodes_[static_cast<std::size_t>(((j % n) + n) % n)]);
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
  // `hint` (in and out): where q's bearing falls among the points' (a position in bearing order,
  // as this call leaves it for a query at a nearby bearing; any value when unknown). With a good
  // hint the search starts there instead of looking q's bearing up.
  [[gnu::always_inline]] std::size_t nearest(const Eigen::Vector2d& q, double max_dist_sq, double* dist_sq,
                                             std::uint32_t* hint = nullptr) const {
    std::size_t best = total_;
    // A point is taken when strictly nearer than the best so far, or, before any, when within
    // max_dist_sq (inclusive): the limit starts one step above max_dist_sq. Ties go to the point
    // visited first (the walk's order), so the answer does not depend on which path below runs.
    double best_d2 = nextUp(max_dist_sq);
    auto consider = [&](const Node& nd) {
      const double dx = nd.x - q.x(), dy = nd.y - q.y();
      const double d2 = dx * dx + dy * dy;
      // (selects, not a branch: which point wins is data-dependent and mispredicts often)
      // (GCC turns `take ? a : b` on these into a branch; the mask cannot become one.)
      const std::size_t take = 0 - static_cast<std::size_t>(d2 < best_d2);  // all ones or zero
      best ^= (best ^ nd.index) & take;  // = d2 < best_d2 ? nd.index : best
      best_d2 = std::min(best_d2, d2);
    };
    const std::size_t n = nodes_.size();
    if (n >= kWindow + 4 && q.allFinite()) {
      // The walk's first four points (its start, then one down, one up, one down) are nearly
      // always visited and hold the nearest point: take them without the per-point bound test
      // and its unpredictable branches, then walk on from there. Extra points cannot change the
      // answer: a point the walk would have stopped before lies farther than the best point.
      const std::size_t s = hint ? startNear(q, *hint) : startOf(q);
      if (hint) *hint = static_cast<std::uint32_t>(s);
      constexpr std::ptrdiff_t kHalf = kWindow / 2;
      for (std::ptrdiff_t k = 0; k < kHalf; ++k) {
        consider(ringAt(s, k));
        consider(ringAt(s, -k - 1));
      }
      walkFrom(q, offset(s, kHalf), offset(s, -kHalf - 1), kWindow, consider, [&] { return best_d2; });
    } else {
      walk(q, consider, [&] { return best_d2; });
    }
    for (const std::uint32_t i : at_origin_) {
      const double d2 = q.squaredNorm();  // NaN for a non-finite query: never taken
      if (d2 < best_d2) {
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
    Nearest best{k, max_dist_sq, idx, d2s};
    walk(
        q, [&](const Node& nd) { best.insert(nd, q); }, [&] { return best.limit(); });
    for (const std::uint32_t i : at_origin_) best.insert(i, q.squaredNorm());
    return best.n;
  }

  // `knn` of each point in turn, itself included (the query of `pts[i]` is `pts[i]`): calls
  // f(i, idx, d2s, count) for every i, in bearing order (points at the origin last).
  template <class F>
  void knnOfEach(std::size_t k, double max_dist_sq, std::uint32_t* idx, double* d2s, F&& f) const {
    const std::size_t n = nodes_.size();
    if (k == 0) return;
    for (std::size_t p = 0; p < n; ++p) {
      const Node& self = nodes_[p];
      const Eigen::Vector2d q(self.x, self.y);
      Nearest best{k, max_dist_sq, idx, d2s};
      if (n >= 2 * static_cast<std::size_t>(kKnnHalf) + 2) {
        // The walk may start at the point's own position (every point up from it has a bearing at
        // least its own, every point down from it at most), and its nearest points are nearly
        // always its neighbours in bearing order: those are taken without the bound test.
        best.insert(self, q);
        for (std::ptrdiff_t j = 1; j <= kKnnHalf; ++j) {
          best.insert(ringAt(p, -j), q);
          best.insert(ringAt(p, j), q);
        }
        walkFrom(
            q, offset(p, kKnnHalf + 1), offset(p, -kKnnHalf - 1), 2 * kKnnHalf + 1,
            [&](const Node& nd) { best.insert(nd, q); }, [&] { return best.limit(); });
      } else {
        walk(
            q, [&](const Node& nd) { best.insert(nd, q); }, [&] { return best.limit(); });
      }
      for (const std::uint32_t i : at_origin_) best.insert(i, q.squaredNorm());
      f(self.index, idx, d2s, best.n);
    }
    for (const std::uint32_t i : at_origin_) f(i, idx, d2s, knn(Eigen::Vector2d::Zero(), k, max_dist_sq, idx, d2s));
  }

 private:
  struct Node {
    double x, y;          // the point
    double ux, uy;        // its unit direction from the origin
    std::uint32_t index;  // position in the constructor's input
  };

  // The k nearest so far, sorted by distance (ties in the order offered).
  struct Nearest {
    std::size_t k;
    double max_dist_sq;
    std::uint32_t* idx;
    double* d2s;
    std::size_t n = 0;

    void insert(std::uint32_t index, double d2) {
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
    }
    void insert(const Node& nd, const Eigen::Vector2d& q) {
      const double dx = nd.x - q.x(), dy = nd.y - q.y();
      insert(nd.index, dx * dx + dy * dy);
    }
    // The walk may stop beyond this squared distance.
    double limit() const { return n == k ? d2s[k - 1] : max_dist_sq; }
  };

  // Neighbours in bearing order on each side that `knnOfEach` takes without the bound test.
  static constexpr std::ptrdiff_t kKnnHalf = 2;

  // Points `nearest` visits before its first bound test (when there are at least kWindow + 4).
  static constexpr std::size_t kWindow = 4;

  // Copies of the nodes' ends on either side of the ring (see ring_): at least the widest fixed
  // window, kWindow / 2 + 1 and kKnnHalf.
  static constexpr std::ptrdiff_t kPad = 3;
  static_assert(kPad >= static_cast<std::ptrdiff_t>(kWindow / 2) + 1 && kPad >= kKnnHalf);

  // The node `k` places from position `p` in bearing order, around the circle (|k| <= kPad).
  const Node& ringAt(std::size_t p, std::ptrdiff_t k) const {
    return ring_[static_cast<std::size_t>(static_cast<std::ptrdiff_t>(p) + kPad + k)];
  }

  // Position `k` places from position `p` in bearing order, around the circle (|k| < size).
  std::size_t offset(std::size_t p, std::ptrdiff_t k) const {
    const auto n = static_cast<std::ptrdiff_t>(nodes_.size());
    const std::ptrdiff_t i = static_cast<std::ptrdiff_t>(p) + k;
    return static_cast<std::size_t>(i < 0 ? i + n : (i >= n ? i - n : i));
  }

  // Position of the first point (in bearing order) whose key is >= q's (wrapping to 0).
  std::size_t startOf(const Eigen::Vector2d& q) const {
    const double kq = pseudoAngle(q.x(), q.y());
    // From the start of q's bucket, a few steps at most.
    const auto b = std::min(static_cast<std::size_t>(kq * bucket_scale_), bucket_start_.size() - 2);
    std::size_t start = bucket_start_[b];
    const std::size_t end = bucket_start_[b + 1];
    // Buckets hold about half a point on average: two steps without branches (`keys_` ends with a
    // sentinel, so reading one past the last point is safe), then a loop that rarely runs.
    start += static_cast<std::size_t>((start < end) & (keys_[start] < kq));
    start += static_cast<std::size_t>((start < end) & (keys_[start] < kq));
    while (start < end && keys_[start] < kq) ++start;
    return start == nodes_.size() ? 0 : start;
  }

  // startOf(q), found by stepping from position h (a few steps at most when h is a good guess; a
  // load-compare the branch predictor runs ahead of, where the bucket lookup is a chain of
  // dependent loads).
  std::size_t startNear(const Eigen::Vector2d& q, std::size_t h) const {
    constexpr int kMaxSteps = 8;
    const std::size_t n = nodes_.size();
    if (h >= n) return startOf(q);
    const double kq = pseudoAngle(q.x(), q.y());
    std::size_t s = h;
    if (keys_[s] < kq) {
      for (int i = 0; keys_[s] < kq; ++i) {  // keys_[n] is +inf: stops at n at the latest
        if (i == kMaxSteps) return startOf(q);
        ++s;
      }
    } else {
      for (int i = 0; s > 0 && keys_[s - 1] >= kq; ++i) {
        if (i == kMaxSteps) return startOf(q);
        --s;
      }
    }
    return s == n ? 0 : s;
  }

  // Visits the points in bearing order outwards from q's bearing, both ways, each way until the
  // ray bound reaches limit() (strictly above it: ties are visited).
  template <class Visit, class Limit>
  void walk(const Eigen::Vector2d& q, Visit&& visit, Limit&& limit) const {
    const std::size_t n = nodes_.size();
    if (n == 0 || !q.allFinite()) return;  // a non-finite query has no neighbour
    const std::size_t start = startOf(q);
    walkFrom(q, start, start == 0 ? n - 1 : start - 1, 0, visit, limit);
  }

  // The walk from positions `up` and `down` on, `visited` points already visited.
  template <class Visit, class Limit>
  void walkFrom(const Eigen::Vector2d& q, std::size_t up, std::size_t down, std::size_t visited, Visit&& visit,
                Limit&& limit) const {
    const std::size_t n = nodes_.size();
    const double qn2 = q.squaredNorm();
    auto bound2 = [&](const Node& nd) {
      const double dot = q.x() * nd.ux + q.y() * nd.uy;
      if (dot <= 0.0) return qn2;
      const double cross = q.x() * nd.uy - q.y() * nd.ux;
      return cross * cross;
    };
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
  std::vector<Node> ring_;  // nodes_ with kPad copies of the other end before and after it
  std::vector<double> keys_;
  std::vector<std::uint32_t> at_origin_;
  std::vector<std::uint32_t> bucket_start_;  // size B + 1
  double bucket_scale_ = 0.0;                // B / 4
  std::size_t total_ = 0;
};

}  // namespace lidar2d::registration::internal
