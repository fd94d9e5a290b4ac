// geometry::castRay against a per-cell reference (the ray clipped to every occupied cell of the grid,
// Liang-Barsky) on seeded random grids and rays, GridRay's walk (4-connected, entry parameters in
// order), and GridRay against mapping's RayWalk on the same segments.

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <random>
#include <vector>

#include "lidar2d/geometry/ray_cast.hpp"
#include "lidar2d/mapping/ray_trace.hpp"

namespace lidar2d::geometry {
namespace {

using V = Eigen::Vector2d;
constexpr double kInf = std::numeric_limits<double>::infinity();

// The parameters [t_in, t_out] at which the ray start + t dir (t >= 0) is inside cell (x, y), or
// t_in > t_out when it misses the cell.
std::pair<double, double> clip(const V& start, const V& dir, int x, int y) {
  double t_in = 0.0, t_out = kInf;
  for (int k = 0; k < 2; ++k) {
    const double lo = (k == 0 ? x : y), hi = lo + 1.0;
    if (dir[k] == 0.0) {
      if (start[k] < lo || start[k] >= hi) return {1.0, 0.0};
      continue;
    }
    double ta = (lo - start[k]) / dir[k], tb = (hi - start[k]) / dir[k];
    if (ta > tb) std::swap(ta, tb);
    t_in = std::max(t_in, ta);
    t_out = std::min(t_out, tb);
  }
  return {t_in, t_out};
}

struct Grid {
  int width = 0, height = 0;
  std::vector<std::uint8_t> occupied;
  bool at(int x, int y) const { return occupied[static_cast<std::size_t>(y) * width + x] != 0; }
};

// The reference: the smallest entry parameter over the occupied cells the ray passes through over a
// positive length, if at most max_t; its cell in *hit_x, *hit_y.
double referenceCast(const Grid& g, const V& start, const V& dir, double max_t, int* hit_x, int* hit_y) {
  double best = kInf;
  for (int y = 0; y < g.height; ++y)
    for (int x = 0; x < g.width; ++x) {
      if (!g.at(x, y)) continue;
      const auto [t_in, t_out] = clip(start, dir, x, y);
      if (t_out - t_in > 1e-12 && t_in <= max_t && t_in < best) {
        best = t_in;
        *hit_x = x;
        *hit_y = y;
      }
    }
  return best;
}

TEST(CastRay, MatchesPerCellReferenceOnRandomGridsAndRays) {
  std::mt19937_64 rng(21);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  for (int trial = 0; trial < 2000; ++trial) {
    Grid g;
    g.width = 5 + static_cast<int>(rng() % 40);
    g.height = 5 + static_cast<int>(rng() % 40);
    const double density = trial % 4 == 0 ? 0.0 : 0.02 + 0.1 * u(rng);
    for (int i = 0; i < g.width * g.height; ++i) g.occupied.push_back(u(rng) < density);
    const V start(u(rng) * g.width, u(rng) * g.height);
    // Random directions, some along the axes and the diagonals.
    double angle = 2.0 * std::numbers::pi * u(rng);
    if (trial % 5 == 1) angle = std::numbers::pi / 2 * static_cast<double>(rng() % 4);
    if (trial % 5 == 2) angle = std::numbers::pi / 4 * static_cast<double>(1 + 2 * (rng() % 4));
    const V dir(std::cos(angle), std::sin(angle));
    const double max_t = trial % 3 == 0 ? kInf : 60.0 * u(rng);

    int ref_x = -1, ref_y = -1;
    const double ref = referenceCast(g, start, dir, max_t, &ref_x, &ref_y);
    int hit_x = -1, hit_y = -1;
    const double t = castRay(start, dir, max_t, g.width, g.height, [&](std::int32_t x, std::int32_t y) {
      EXPECT_TRUE(x >= 0 && y >= 0 && x < g.width && y < g.height);
      hit_x = x;
      hit_y = y;
      return g.at(x, y);
    });
    if (std::isinf(ref)) {
      EXPECT_EQ(t, kInf) << "trial " << trial;
      continue;
    }
    ASSERT_NEAR(t, ref, 1e-9) << "trial " << trial;
    EXPECT_EQ(hit_x, ref_x) << "trial " << trial;
    EXPECT_EQ(hit_y, ref_y) << "trial " << trial;
  }
}

// The clearance of every cell by brute force: 0 on obstacles, else 1 + floor of the distance
// between its square and the nearest obstacle square, at most 255.
TEST(ClearanceGrid, IsTheDistanceBetweenSquaresToTheNearestObstacle) {
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  for (int trial = 0; trial < 60; ++trial) {
    Grid g;
    g.width = 1 + static_cast<int>(rng() % 40);
    g.height = 1 + static_cast<int>(rng() % 40);
    const double density = trial % 5 == 0 ? 0.0 : 0.002 + 0.05 * u(rng);
    for (int i = 0; i < g.width * g.height; ++i) g.occupied.push_back(u(rng) < density);
    const ClearanceGrid c(g.occupied, g.width, g.height);
    const ClearanceGrid c3(g.occupied, g.width, g.height, 3);  // in three threads: the same
    // From an occupancy grid's values (obstacles at least 65): the same.
    std::vector<std::int8_t> values;
    for (std::uint8_t o : g.occupied) values.push_back(static_cast<std::int8_t>(o ? 65 + rng() % 36 : rng() % 66 - 1));
    const ClearanceGrid cv(values, 65, g.width, g.height, 2);
    for (int y = 0; y < g.height; ++y)
      for (int x = 0; x < g.width; ++x) {
        ASSERT_EQ(c3.at(x, y), c.at(x, y)) << "trial " << trial << " cell " << x << " " << y;
        ASSERT_EQ(cv.at(x, y), c.at(x, y)) << "trial " << trial << " cell " << x << " " << y;
        double best = 1e9;
        for (int oy = 0; oy < g.height; ++oy)
          for (int ox = 0; ox < g.width; ++ox)
            if (g.at(ox, oy)) {
              const double gx = std::max(0, std::abs(ox - x) - 1), gy = std::max(0, std::abs(oy - y) - 1);
              best = std::min(best, std::sqrt(gx * gx + gy * gy));
            }
        const int expected = g.at(x, y) ? 0 : 1 + static_cast<int>(std::min(254.0, std::floor(best)));
        ASSERT_EQ(c.at(x, y), expected) << "trial " << trial << " cell " << x << " " << y;
      }
  }
  // Open space farther than 255 cells saturates.
  const ClearanceGrid open(std::vector<std::uint8_t>(300 * 2, 0), 300, 2);
  EXPECT_EQ(open.at(150, 1), 255);
}

// The leaping cast gives castRay's answer, on grids with open space (so that it leaps) and clutter.
TEST(CastRayInClearance, MatchesCastRayOnRandomGridsAndRays) {
  std::mt19937_64 rng(33);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  int leaps_possible = 0;
  for (int trial = 0; trial < 3000; ++trial) {
    Grid g;
    g.width = 5 + static_cast<int>(rng() % 120);
    g.height = 5 + static_cast<int>(rng() % 120);
    const double density = trial % 4 == 0 ? 0.0 : (trial % 4 == 1 ? 0.002 : 0.01 + 0.05 * u(rng));
    for (int i = 0; i < g.width * g.height; ++i) g.occupied.push_back(u(rng) < density);
    // A few walls, as in a building.
    for (int w = 0; w < 3; ++w) {
      const int x0 = static_cast<int>(rng() % g.width), y0 = static_cast<int>(rng() % g.height);
      const bool horizontal = rng() % 2;
      for (int k = 0; k < 40; ++k) {
        const int x = horizontal ? x0 + k : x0, y = horizontal ? y0 : y0 + k;
        if (x < g.width && y < g.height) g.occupied[static_cast<std::size_t>(y) * g.width + x] = 1;
      }
    }
    const ClearanceGrid c(g.occupied, g.width, g.height);
    const V start(u(rng) * g.width, u(rng) * g.height);
    leaps_possible += c.at(static_cast<int>(start.x()), static_cast<int>(start.y())) >= 4;  // leaps of 3+ cells
    double angle = 2.0 * std::numbers::pi * u(rng);
    if (trial % 5 == 1) angle = std::numbers::pi / 2 * static_cast<double>(rng() % 4);
    if (trial % 5 == 2) angle = std::numbers::pi / 4 * static_cast<double>(1 + 2 * (rng() % 4));
    const V dir(std::cos(angle), std::sin(angle));
    const double max_t = trial % 3 == 0 ? kInf : 150.0 * u(rng);
    const double ref =
        castRay(start, dir, max_t, g.width, g.height, [&](std::int32_t x, std::int32_t y) { return g.at(x, y); });
    const double t = castRayInClearance(start, dir, max_t, c);
    if (std::isinf(ref))
      EXPECT_EQ(t, kInf) << "trial " << trial;
    else
      ASSERT_NEAR(t, ref, 1e-9) << "trial " << trial;
    // The batched cast answers exactly as the single one, for any number of rays.
    std::vector<V> dirs;
    const std::size_t n = 1 + rng() % 20;
    for (std::size_t i = 0; i < n; ++i) {
      const double a = 2.0 * std::numbers::pi * u(rng);
      dirs.emplace_back(std::cos(a), std::sin(a));
    }
    std::vector<double> batch(n);
    castRaysInClearance(start, dirs.data(), n, max_t, c, batch.data());
    for (std::size_t i = 0; i < n; ++i)
      ASSERT_EQ(batch[i], castRayInClearance(start, dirs[i], max_t, c)) << "trial " << trial << " ray " << i;
  }
  EXPECT_GT(leaps_possible, 500);  // the test exercises the leaps
}

TEST(CastRay, StartCellLeavingTheGridAndRange) {
  Grid g{4, 3, std::vector<std::uint8_t>(12, 0)};
  g.occupied[1 * 4 + 1] = 1;  // cell (1, 1)
  auto hit = [&](std::int32_t x, std::int32_t y) { return g.at(x, y); };
  EXPECT_EQ(castRay(V(1.5, 1.5), V(1, 0), 10.0, 4, 3, hit), 0.0);          // starts in it
  EXPECT_DOUBLE_EQ(castRay(V(3.5, 1.5), V(-1, 0), 10.0, 4, 3, hit), 1.5);  // enters it at x = 2
  EXPECT_EQ(castRay(V(3.5, 1.5), V(-1, 0), 1.49, 4, 3, hit), kInf);        // too far
  EXPECT_EQ(castRay(V(3.5, 0.5), V(-1, 0), 10.0, 4, 3, hit), kInf);        // leaves the grid at x = 0
  EXPECT_EQ(castRay(V(1.5, 0.5), V(0, -1), 10.0, 4, 3, hit), kInf);        // leaves the grid at y = 0
}

TEST(GridRay, WalksFourConnectedCellsWithIncreasingEntryParameters) {
  std::mt19937_64 rng(4);
  std::uniform_real_distribution<double> u(-100.0, 100.0);
  for (int trial = 0; trial < 1000; ++trial) {
    const V start(u(rng), u(rng));
    const V dir = V(u(rng), u(rng)).normalized();
    GridRay ray(start, dir);
    EXPECT_EQ(ray.x(), static_cast<int>(std::floor(start.x())));
    EXPECT_EQ(ray.y(), static_cast<int>(std::floor(start.y())));
    EXPECT_EQ(ray.t(), 0.0);
    for (int k = 0; k < 100; ++k) {
      const int x = ray.x(), y = ray.y();
      const double t = ray.t();
      ray.step();
      EXPECT_EQ(std::abs(ray.x() - x) + std::abs(ray.y() - y), 1);
      EXPECT_GE(ray.t(), t);
      // The point at the entry parameter lies on the boundary of the new cell.
      const V p = start + ray.t() * dir;
      EXPECT_LE(std::max(ray.x() - p.x(), p.x() - (ray.x() + 1)), 1e-9) << "trial " << trial;
      EXPECT_LE(std::max(ray.y() - p.y(), p.y() - (ray.y() + 1)), 1e-9) << "trial " << trial;
    }
  }
}

TEST(GridRay, VisitsTheCellsOfMappingsRayWalk) {
  std::mt19937_64 rng(8);
  std::uniform_real_distribution<double> u(-50.0, 50.0);
  for (int trial = 0; trial < 2000; ++trial) {
    const V a(u(rng), u(rng));
    const V b = a + V(u(rng), u(rng)) * 0.5;
    GridRay ray(a, b - a);
    for (mapping::RayWalk walk(a, b);; walk.step()) {
      ASSERT_EQ(ray.x(), walk.x()) << "trial " << trial;
      ASSERT_EQ(ray.y(), walk.y()) << "trial " << trial;
      if (walk.done()) break;
      ray.step();
    }
  }
}

}  // namespace
}  // namespace lidar2d::geometry
