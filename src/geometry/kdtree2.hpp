#pragma once
// A nanoflann k-d tree over a Points2 (2D, squared Euclidean distance). Library-private: modules that
// may use geometry include it as "src/geometry/kdtree2.hpp"; it is never installed, because nanoflann
// is a private dependency of the library and never appears in public headers.

#include <nanoflann.hpp>

#include <cstddef>
#include <cstdint>
#include <limits>

#include "lidar2d/core/laser_scan.hpp"

namespace lidar2d::geometry {

// nanoflann's dataset interface over a vector of Eigen 2D points (which must outlive the adaptor
// and stay unchanged while the tree is used).
struct Points2Adaptor {
  const Points2* pts = nullptr;
  std::size_t kdtree_get_point_count() const { return pts->size(); }
  double kdtree_get_pt(std::size_t i, std::size_t dim) const { return (*pts)[i][static_cast<Eigen::Index>(dim)]; }
  template <class BBox>
  bool kdtree_get_bbox(BBox&) const {
    return false;  // let nanoflann compute it
  }
};

class KdTree2 {
 public:
  using Tree = nanoflann::KDTreeSingleIndexAdaptor<nanoflann::L2_Simple_Adaptor<double, Points2Adaptor>, Points2Adaptor,
                                                   2, std::uint32_t>;

  // `pts` must outlive the tree and not change. Leaf size 8: a good balance of build and query
  // time for a few hundred to a few thousand points (measured in bench_registration).
  explicit KdTree2(const Points2& pts) : adaptor_{&pts}, tree_(2, adaptor_, nanoflann::KDTreeSingleIndexAdaptorParams(8)) {}
  KdTree2(const KdTree2&) = delete;
  KdTree2& operator=(const KdTree2&) = delete;

  // Nearest point to p: its index (size() when empty) and squared distance.
  std::size_t nearest(const Eigen::Vector2d& p, double* dist_sq) const {
    std::uint32_t idx = 0;
    double d2 = std::numeric_limits<double>::infinity();
    nanoflann::KNNResultSet<double, std::uint32_t> rs(1);
    rs.init(&idx, &d2);
    const double q[2] = {p.x(), p.y()};
    if (adaptor_.pts->empty() || !tree_.findNeighbors(rs, q, nanoflann::SearchParams(32, 0.0f, false))) {
      *dist_sq = std::numeric_limits<double>::infinity();
      return adaptor_.pts->size();
    }
    *dist_sq = d2;
    return idx;
  }

  // Up to k nearest points (sorted by distance); returns the count found.
  std::size_t knn(const Eigen::Vector2d& p, std::size_t k, std::uint32_t* idx, double* dist_sq) const {
    if (adaptor_.pts->empty()) return 0;
    const double q[2] = {p.x(), p.y()};
    return tree_.knnSearch(q, k, idx, dist_sq);
  }

 private:
  Points2Adaptor adaptor_;
  Tree tree_;
};

}  // namespace lidar2d::geometry
