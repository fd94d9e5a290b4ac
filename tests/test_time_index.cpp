// TimeIndex (core/trajectory.hpp): nearest-time lookup with tolerance, ties and repeated times,
// against a linear scan on seeded random times.

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <random>
#include <vector>

#include "lidar2d/core/trajectory.hpp"

namespace lidar2d {
namespace {

TEST(TimeIndex, NearestWithinToleranceTiesAndRepeats) {
  // Unsorted with a repeat: original indices 0..5.
  const TimeIndex idx(std::vector<double>{3.0, 1.0, 2.0, 2.0, 5.0, 4.0});
  EXPECT_TRUE(idx.hasRepeatedTimes());
  EXPECT_EQ(idx.nearest(1.0, 0.1), std::optional<std::size_t>(1));
  EXPECT_EQ(idx.nearest(1.09, 0.1), std::optional<std::size_t>(1));
  EXPECT_EQ(idx.nearest(1.11, 0.1), std::nullopt);
  EXPECT_EQ(idx.nearest(0.95, 0.1), std::optional<std::size_t>(1));
  EXPECT_EQ(idx.nearest(5.5, 0.1), std::nullopt);
  EXPECT_EQ(idx.nearest(5.5, 1.0), std::optional<std::size_t>(4));
  EXPECT_EQ(idx.nearest(2.04, 0.1), std::optional<std::size_t>(2));  // repeated 2.0: first in file order
  EXPECT_EQ(idx.nearest(1.96, 0.1), std::optional<std::size_t>(2));
  EXPECT_EQ(idx.nearest(3.5, 0.5), std::optional<std::size_t>(0));   // tie 3.0 / 4.0: the earlier time
  EXPECT_EQ(idx.nearest(3.6, 0.5), std::optional<std::size_t>(5));
  EXPECT_EQ(idx.nearest(std::nan(""), 1.0), std::nullopt);
  EXPECT_FALSE(TimeIndex(std::vector<double>{1.0, 2.0}).hasRepeatedTimes());
  EXPECT_EQ(TimeIndex(std::vector<double>{}).nearest(1.0, 1.0), std::nullopt);
}

TEST(TimeIndex, AgreesWithLinearScanOnRandomTimes) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(0.0, 10.0);
  std::vector<double> times(200);
  for (auto& t : times) t = std::round(u(rng) * 100.0) / 100.0;  // rounding makes repeats likely
  const TimeIndex idx(times);
  for (int q = 0; q < 2000; ++q) {
    const double t = u(rng);
    double best = std::numeric_limits<double>::infinity();
    for (double x : times) best = std::min(best, std::abs(x - t));
    const auto got = idx.nearest(t, 0.05);
    if (best <= 0.05) {
      ASSERT_TRUE(got.has_value()) << t;
      EXPECT_EQ(std::abs(times[*got] - t), best) << t;
    } else {
      EXPECT_FALSE(got.has_value()) << t;
    }
  }
}

}  // namespace
}  // namespace lidar2d
