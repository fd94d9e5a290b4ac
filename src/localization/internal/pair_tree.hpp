#pragma once
// A static k-d tree over the line pairs of a localization database that stores no index: build()
// reorders the pairs so that every node of a balanced tree is a contiguous range of them, and keeps
// only each inner node's split (dimension and value, 4 bytes). A database of millions of pairs
// then costs the pairs themselves (a pointer-based tree such as nanoflann's adds an index and the
// nodes, 9-10 bytes per pair on top of the pair's 12).

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <thread>
#include <vector>

namespace lidar2d::localization::internal {

// Requirements on P: `key[3]` of std::uint16_t (quantized coordinates); Scale: `unit[3]`, the
// coordinate of one key step in each dimension (the tree searches in those coordinates).
class ImplicitPairTree {
 public:
  static constexpr std::size_t kLeafSize = 16;

  // Reorders `pairs` and records the splits.
  template <class P, class Scale>
  void build(std::vector<P>& pairs, const Scale& scale) {
    n_ = pairs.size();
    // Ranges at depth k hold at most ceil(n / 2^k) pairs; depth levels have inner nodes.
    std::size_t depth = 0;
    while (((n_ + (std::size_t{1} << depth) - 1) >> depth) > kLeafSize) ++depth;
    nodes_.assign(n_ > kLeafSize ? (std::size_t{1} << depth) : 0, Node{});
    if (n_ > kLeafSize) buildNode(pairs, scale, 0, 0, n_);
  }

  // Calls visit(i) for every pair i (index into the reordered pairs) whose key, in coordinates,
  // is at a squared distance below r2 from q (strictly, as nanoflann's radius search).
  template <class P, class Scale, class Visit>
  void radiusSearch(const std::vector<P>& pairs, const Scale& scale, const float q[3], float r2, Visit&& visit) const {
    if (n_ == 0) return;
    // Pruning radius: a little over sqrt(r2), so that float rounding never prunes a hit.
    const float r = std::sqrt(r2) * (1.0f + 1e-5f) + 1e-6f;
    search(pairs, scale, q, r, r2, 0, 0, n_, visit);
  }

  std::size_t memoryBytes() const { return nodes_.capacity() * sizeof(Node); }

 private:
  struct Node {
    std::uint16_t split = 0;  // key value of the median pair: left keys <= split <= right keys
    std::uint8_t dim = 0;
  };

  template <class P, class Scale>
  void buildNode(std::vector<P>& pairs, const Scale& scale, std::size_t node, std::size_t lo, std::size_t hi) {
    // Split the dimension of largest extent (in coordinates) at the median.
    std::uint16_t mn[3] = {65535, 65535, 65535}, mx[3] = {0, 0, 0};
    for (std::size_t i = lo; i < hi; ++i)
      for (int d = 0; d < 3; ++d) {
        mn[d] = std::min(mn[d], pairs[i].key[d]);
        mx[d] = std::max(mx[d], pairs[i].key[d]);
      }
    int dim = 0;
    float best = -1.0f;
    for (int d = 0; d < 3; ++d) {
      const float extent = static_cast<float>(mx[d] - mn[d]) * scale.unit[d];
      if (extent > best) {
        best = extent;
        dim = d;
      }
    }
    const std::size_t mid = lo + (hi - lo) / 2;
    const auto first = pairs.begin();
    std::nth_element(first + static_cast<std::ptrdiff_t>(lo), first + static_cast<std::ptrdiff_t>(mid),
                     first + static_cast<std::ptrdiff_t>(hi),
                     [dim](const P& a, const P& b) { return a.key[dim] < b.key[dim]; });
    nodes_[node] = {pairs[mid].key[dim], static_cast<std::uint8_t>(dim)};
    // The root's two halves are independent (disjoint pairs and nodes): one in a second thread.
    std::thread left;
    if (mid - lo > kLeafSize) {
      if (node == 0 && hi - lo > (std::size_t{1} << 16))
        left = std::thread([&, node, lo, mid] { buildNode(pairs, scale, 2 * node + 1, lo, mid); });
      else
        buildNode(pairs, scale, 2 * node + 1, lo, mid);
    }
    if (hi - mid > kLeafSize) buildNode(pairs, scale, 2 * node + 2, mid, hi);
    if (left.joinable()) left.join();
  }

  template <class P, class Scale, class Visit>
  void search(const std::vector<P>& pairs, const Scale& scale, const float q[3], float r, float r2, std::size_t node,
              std::size_t lo, std::size_t hi, Visit& visit) const {
    if (hi - lo <= kLeafSize) {
      for (std::size_t i = lo; i < hi; ++i) {
        float d2 = 0.0f;
        for (int d = 0; d < 3; ++d) {
          const float e = static_cast<float>(pairs[i].key[d]) * scale.unit[d] - q[d];
          d2 += e * e;
        }
        if (d2 < r2) visit(i);
      }
      return;
    }
    const Node& nd = nodes_[node];
    const float s = static_cast<float>(nd.split) * scale.unit[nd.dim];
    const std::size_t mid = lo + (hi - lo) / 2;
    if (q[nd.dim] - r <= s) search(pairs, scale, q, r, r2, 2 * node + 1, lo, mid, visit);
    if (q[nd.dim] + r >= s) search(pairs, scale, q, r, r2, 2 * node + 2, mid, hi, visit);
  }

  std::size_t n_ = 0;
  std::vector<Node> nodes_;  // inner nodes in heap order: the children of node i are 2 i + 1 and 2 i + 2
};

}  // namespace lidar2d::localization::internal
