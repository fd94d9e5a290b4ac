// traceRay against a per-cell reference: a cell is crossed when the segment overlaps its interior
// over a positive length (Liang-Barsky clipping of the segment to the cell).

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <set>

#include "lidar2d/mapping/ray_trace.hpp"

namespace lidar2d::mapping {
namespace {

double clippedLength(const Eigen::Vector2d& a, const Eigen::Vector2d& b, int cx, int cy) {
  double t0 = 0, t1 = 1;
  const Eigen::Vector2d d = b - a;
  const double p[4] = {-d.x(), d.x(), -d.y(), d.y()};
  const double q[4] = {a.x() - cx, cx + 1 - a.x(), a.y() - cy, cy + 1 - a.y()};
  for (int i = 0; i < 4; ++i) {
    if (p[i] == 0) {
      if (q[i] < 0) return 0;
      continue;
    }
    const double t = q[i] / p[i];
    if (p[i] < 0)
      t0 = std::max(t0, t);
    else
      t1 = std::min(t1, t);
  }
  return t1 > t0 ? (t1 - t0) * d.norm() : 0.0;
}

std::set<std::pair<int, int>> referenceCells(const Eigen::Vector2d& a, const Eigen::Vector2d& b) {
  std::set<std::pair<int, int>> cells;
  const int x0 = static_cast<int>(std::floor(std::min(a.x(), b.x()))) - 1;
  const int x1 = static_cast<int>(std::floor(std::max(a.x(), b.x()))) + 1;
  const int y0 = static_cast<int>(std::floor(std::min(a.y(), b.y()))) - 1;
  const int y1 = static_cast<int>(std::floor(std::max(a.y(), b.y()))) + 1;
  for (int y = y0; y <= y1; ++y)
    for (int x = x0; x <= x1; ++x)
      if (clippedLength(a, b, x, y) > 1e-9) cells.insert({x, y});
  return cells;
}

TEST(TraceRay, MatchesPerCellReferenceOnRandomSegments) {
  std::mt19937_64 rng(42);
  std::uniform_real_distribution<double> u(-50.0, 50.0);
  for (int trial = 0; trial < 3000; ++trial) {
    const Eigen::Vector2d a(u(rng), u(rng));
    const Eigen::Vector2d b = a + Eigen::Vector2d(u(rng), u(rng)) * (trial % 3 == 0 ? 0.05 : 0.6);
    std::vector<std::pair<int, int>> visited;
    const CellIndex end = traceRay(a, b, [&](CellIndex c) { visited.emplace_back(c.x, c.y); });
    visited.emplace_back(end.x, end.y);
    EXPECT_EQ(end.x, static_cast<int>(std::floor(b.x())));
    EXPECT_EQ(end.y, static_cast<int>(std::floor(b.y())));
    EXPECT_EQ(visited.front(), std::make_pair(static_cast<int>(std::floor(a.x())), static_cast<int>(std::floor(a.y()))));
    // Each cell once, consecutive cells 4-adjacent.
    const std::set<std::pair<int, int>> unique(visited.begin(), visited.end());
    ASSERT_EQ(unique.size(), visited.size()) << "a cell visited twice, trial " << trial;
    for (std::size_t i = 1; i < visited.size(); ++i)
      EXPECT_EQ(std::abs(visited[i].first - visited[i - 1].first) + std::abs(visited[i].second - visited[i - 1].second), 1);
    EXPECT_EQ(unique, referenceCells(a, b)) << "trial " << trial;
  }
}

TEST(TraceRay, AxisAlignedAndDegenerateSegments) {
  std::vector<std::pair<int, int>> v;
  auto collect = [&](CellIndex c) { v.emplace_back(c.x, c.y); };
  CellIndex e = traceRay({0.5, 0.5}, {0.7, 0.2}, collect);  // same cell
  EXPECT_TRUE(v.empty());
  EXPECT_EQ(e, (CellIndex{0, 0}));
  e = traceRay({0.5, 0.5}, {-3.5, 0.5}, collect);  // along -x
  EXPECT_EQ(v, (std::vector<std::pair<int, int>>{{0, 0}, {-1, 0}, {-2, 0}, {-3, 0}}));
  EXPECT_EQ(e, (CellIndex{-4, 0}));
  v.clear();
  // Exactly through a corner: stays 4-connected and ends in the end cell.
  e = traceRay({0.5, 0.5}, {2.5, 2.5}, collect);
  EXPECT_EQ(e, (CellIndex{2, 2}));
  EXPECT_EQ(v.size(), 4u);
}

// RayWalk::run takes the steps of `step()`: on random segments (some through cell corners and
// along grid lines, where the walk's running sums decide), with random step counts and lap lengths
// (1 makes every step a lap; lap boundaries anywhere), the cells it visits, the coordinates it
// reports at each lap and the walk after it are those of the step loop, and a further step loop
// continues as if `step()` had been used throughout.
TEST(RayWalk, RunTakesTheStepsOfStep) {
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> u(-40.0, 40.0);
  std::uniform_int_distribution<int> lap_len(1, 9), coin(0, 3);
  for (int trial = 0; trial < 4000; ++trial) {
    Eigen::Vector2d a(u(rng), u(rng));
    Eigen::Vector2d b = a + Eigen::Vector2d(u(rng), u(rng)) * (trial % 4 == 0 ? 0.1 : 0.8);
    if (trial % 5 == 1) {  // grid points: the segment passes through cell corners
      a = a.array().round();
      b = a + Eigen::Vector2d(std::round(u(rng) / 4), std::round(u(rng) / 4));
    } else if (trial % 5 == 2) {  // along a grid line, or parallel to an axis
      b.y() = a.y() = coin(rng) == 0 ? std::round(a.y()) : a.y();
    } else if (trial % 5 == 3) {  // diagonal: the crossings tie
      b = a + Eigen::Vector2d(1, 1) * u(rng) / 3;
    }
    const RayWalk start(a, b);
    // The reference: step() throughout.
    std::vector<CellIndex> ref;
    for (RayWalk w = start; !w.done(); w.step()) ref.push_back(w.cell());
    const auto total = static_cast<std::int32_t>(ref.size());
    ASSERT_EQ(total, start.stepsLeft());
    const std::int32_t n = total == 0 ? 0 : std::uniform_int_distribution<std::int32_t>(0, total)(rng);
    const std::int32_t lap = lap_len(rng);
    const std::int32_t first_x = std::uniform_int_distribution<std::int32_t>(1, lap)(rng);
    const std::int32_t first_y = std::uniform_int_distribution<std::int32_t>(1, lap)(rng);
    // Follow the walk as a caller of run() does: by the steps, corrected at the laps.
    RayWalk w = start;
    CellIndex at = w.cell();
    std::vector<CellIndex> visited;
    std::int32_t xs = 0, ys = 0, lap_errors = 0, laps = 0;
    w.run(
        n, first_x, first_y, lap, [&] { visited.push_back(at); },
        [&] {
          at.x += start.stepX();
          ++xs;
        },
        [&] {
          at.y += start.stepY();
          ++ys;
        },
        [&](std::int32_t x, std::int32_t y, bool visit) {
          ++laps;
          lap_errors += !(x == at.x && y == at.y);
          lap_errors += visit != (static_cast<std::int32_t>(visited.size()) < n);  // the new cell is visited
        });
    ASSERT_EQ(visited.size(), static_cast<std::size_t>(n)) << "trial " << trial;
    EXPECT_TRUE(std::equal(visited.begin(), visited.end(), ref.begin())) << "trial " << trial;
    EXPECT_EQ(lap_errors, 0) << "trial " << trial;
    // Laps after first_x, first_x + lap, ... x steps (and the same for y).
    const std::int32_t expected_laps =
        (xs >= first_x ? 1 + (xs - first_x) / lap : 0) + (ys >= first_y ? 1 + (ys - first_y) / lap : 0);
    EXPECT_EQ(laps, expected_laps) << "trial " << trial;
    EXPECT_EQ(w.stepsLeft(), total - n) << "trial " << trial;
    EXPECT_EQ(w.cell(), n < total ? ref[static_cast<std::size_t>(n)] : traceRay(a, b, [](CellIndex) {}))
        << "trial " << trial;
    std::vector<CellIndex> rest;
    for (; !w.done(); w.step()) rest.push_back(w.cell());
    EXPECT_TRUE(std::equal(rest.begin(), rest.end(), ref.begin() + n, ref.end())) << "trial " << trial;
    EXPECT_EQ(w.cell(), traceRay(a, b, [](CellIndex) {})) << "trial " << trial;
  }
}

// floorToInt32 (the walk's and insertion's floor) equals std::floor over the int32 range: at and
// just beside integers, at signed zeros, near the limits and on random values.
TEST(FloorToInt32, EqualsStdFloor) {
  std::vector<double> values = {0.0, -0.0, 0.5, -0.5, 1.0, -1.0, 2147483646.5, -2147483647.5, -2147483648.0,
                                2147483647.0, 1e-300, -1e-300, 4.9e-324, -4.9e-324};
  for (int k = -1000; k <= 1000; ++k) {
    const double v = k;
    values.insert(values.end(), {v, std::nextafter(v, -1e300), std::nextafter(v, 1e300), v + 0.5});
  }
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> wide(-2.1e9, 2.1e9), narrow(-3000.0, 3000.0);
  for (int i = 0; i < 100000; ++i) values.insert(values.end(), {wide(rng), narrow(rng)});
  for (const double v : values) ASSERT_EQ(floorToInt32(v), static_cast<std::int32_t>(std::floor(v))) << v;
}

}  // namespace
}  // namespace lidar2d::mapping
