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
#include <numbers>
#include <vector>

#include "lidar2d/core/error.hpp"
#include "lidar2d/localization/localizer.hpp"
#include "src/localization/internal/pair_tree.hpp"

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

// One indexed pair of lines of one position: reference line `ref` (index into Database::lines())
// and second line ref + other_delta, keyed by (d_ref, d_other, k * angle) quantized to 16 bits per
// dimension (PairKeyScale: sub-millimetre steps for the distances of a 30 m scan, far below the
// query's key radius). 12 bytes: the index of a large map holds millions of pairs.
struct Pair {
  std::uint16_t key[3];
  std::uint16_t other_delta = 0;
  std::uint32_t ref = 0;
};

// The metres (or scaled radians) per unit of each quantized key dimension, fixed by the largest
// value of the data so that a database loaded from a file rebuilds the identical index.
struct PairKeyScale {
  float unit[3] = {1.0f, 1.0f, 1.0f};
  std::uint16_t quantize(int dim, double v) const {
    return static_cast<std::uint16_t>(std::clamp<long>(std::lround(v / unit[dim]), 0L, 65535L));
  }
};

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
  std::vector<std::uint32_t> line_position;  // position of each line
  std::vector<internal::Pair> pairs;
  internal::PairKeyScale key_scale;
  internal::ImplicitPairTree tree;    // over `pairs`, which it orders
  std::vector<float> profiles;        // profile_bins per position, or empty
  std::size_t coarse_factor = 1;      // sectors merged per coarse sector (the prefilter of the query)
  std::vector<float> coarse;          // the same at profile_bins / coarse_factor sectors (nearest of each group)
  double coverage = std::numeric_limits<double>::quiet_NaN();  // Database::coverage()

  // Indexes every non-parallel pair of lines of every position (both orders are not needed: the
  // query tries both orders of its own pairs) and derives the coarse profiles of the query.
  void buildIndex();
};

}  // namespace lidar2d::localization
