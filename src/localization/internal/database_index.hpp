#pragma once
// The index of a localization Database and the helpers its build and its lookup share (private to
// the localization module).

#include <fmt/format.h>

#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <memory>
#include <nanoflann.hpp>
#include <numbers>
#include <vector>

#include "lidar2d/core/error.hpp"
#include "lidar2d/localization/localizer.hpp"

namespace lidar2d::localization {
namespace internal {

inline constexpr double kPi = std::numbers::pi;
inline constexpr double kTwoPi = 2.0 * std::numbers::pi;

inline Error badOption(const char* field, double v) {
  return invalidArgument(fmt::format("localization option {} = {} is out of its domain", field, v),
                         ErrorLocation({}, 0, field));
}

// Angle in [0, 2 pi).
inline double wrapTwoPi(double a) {
  a = std::fmod(a, kTwoPi);
  if (a < 0) a += kTwoPi;
  if (a >= kTwoPi) a -= kTwoPi;
  return a;
}

// Range-profile sector of direction `angle`: sector k covers [-pi + k w, -pi + (k + 1) w), w = 2 pi / bins.
inline std::size_t sectorOf(double angle, std::size_t bins) {
  return std::min(bins - 1, static_cast<std::size_t>(wrapTwoPi(angle + kPi) / kTwoPi * static_cast<double>(bins)));
}

// One indexed pair: reference line `ref` and second line `other` of position `pos`.
struct Pair {
  float key[3];
  std::uint32_t ref = 0, other = 0, pos = 0;
};

struct PairAdaptor {
  const std::vector<Pair>* pairs = nullptr;
  std::size_t kdtree_get_point_count() const { return pairs->size(); }
  float kdtree_get_pt(std::size_t i, std::size_t dim) const { return (*pairs)[i].key[dim]; }
  template <class BBox>
  bool kdtree_get_bbox(BBox&) const {
    return false;
  }
};

using PairTree = nanoflann::KDTreeSingleIndexAdaptor<nanoflann::L2_Simple_Adaptor<float, PairAdaptor>, PairAdaptor, 3,
                                                     std::uint32_t>;

// Candidates from the range profiles (lookup.cpp): the `k` database positions whose profile, at its
// best turn, best matches the profile of `pts` (robot frame) seen from `sensor`; empty when the
// database has no profiles or the scan shows too little of the circle.
std::vector<PoseVote> profileCandidates(const Database& database, const Points2& pts, const Eigen::Vector2d& sensor,
                                        std::size_t k);

}  // namespace internal

struct Database::Impl {
  DatabaseOptions options;
  std::uint64_t map_checksum = 0;
  std::vector<Position> positions;
  std::vector<LineFeature> lines;
  std::vector<internal::Pair> pairs;
  internal::PairAdaptor adaptor;
  std::unique_ptr<internal::PairTree> tree;
  std::vector<float> profiles;        // profile_bins per position, or empty
  std::vector<float> doubled;         // each profile twice in a row: turning it is then a contiguous slice
  std::size_t coarse_factor = 1;      // sectors merged per coarse sector (the prefilter of the query)
  std::vector<float> coarse_doubled;  // the same at profile_bins / coarse_factor sectors (nearest of each group)
  double coverage = std::numeric_limits<double>::quiet_NaN();  // Database::coverage()

  // Indexes every non-parallel pair of lines of every position (both orders are not needed: the
  // query tries both orders of its own pairs) and lays out the profiles for the query.
  void buildIndex();
};

}  // namespace lidar2d::localization
