// Simulated worlds: closed-form intersections, the accelerated ray caster against the brute-force
// reference, built-in worlds' geometry, worlds from occupancy maps against a per-cell reference.

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <numbers>
#include <random>

#include "lidar2d/core/error.hpp"
#include "lidar2d/sim/noise.hpp"
#include "lidar2d/sim/world.hpp"
#include "lidar2d/sim/worlds.hpp"

namespace lidar2d::sim {
namespace {

using V = Eigen::Vector2d;
constexpr double kInf = std::numeric_limits<double>::infinity();
constexpr double kPi = std::numbers::pi;

V unit(double a) { return {std::cos(a), std::sin(a)}; }

TEST(Intersect, SegmentHitsAtKnownDistance) {
  const Segment wall{V(2, -1), V(2, 1)};
  EXPECT_DOUBLE_EQ(intersectSegment(wall, V(0, 0), V(1, 0)), 2.0);
  // 45 degrees: hits (2, 2)? No: the wall ends at y = 1, so only up to atan(1/2).
  EXPECT_EQ(intersectSegment(wall, V(0, 0), unit(kPi / 4)), kInf);
  EXPECT_NEAR(intersectSegment(wall, V(0, 0), unit(std::atan2(1, 2))), std::sqrt(5.0), 1e-12);  // through the end point
  EXPECT_EQ(intersectSegment(wall, V(0, 0), V(-1, 0)), kInf);                                     // behind
  EXPECT_EQ(intersectSegment(wall, V(0, 0), V(0, 1)), kInf);                                      // parallel
  EXPECT_DOUBLE_EQ(intersectSegment(wall, V(2, 0), V(1, 0)), 0.0);                               // starts on it
}

TEST(Intersect, CircleAndArc) {
  const Arc c = Arc::circle(V(5, 0), 1.0);
  EXPECT_DOUBLE_EQ(intersectArc(c, V(0, 0), V(1, 0)), 4.0);
  EXPECT_DOUBLE_EQ(intersectArc(c, V(5, 0), V(1, 0)), 1.0);  // from inside: the far side
  EXPECT_EQ(intersectArc(c, V(0, 0), V(-1, 0)), kInf);
  // Tangent ray: touches at distance sqrt(25 - 1).
  const double a = std::asin(1.0 / 5.0);
  EXPECT_NEAR(intersectArc(c, V(0, 0), unit(a)), std::sqrt(24.0), 1e-6);
  EXPECT_EQ(intersectArc(c, V(0, 0), unit(a + 1e-6)), kInf);
  // Half circle facing away from the origin (angles -90..90 deg): the near side is missing.
  const Arc half{V(5, 0), 1.0, -kPi / 2, kPi};
  EXPECT_DOUBLE_EQ(intersectArc(half, V(0, 0), V(1, 0)), 6.0);
  // The other half (90..270 deg) is hit at its near side.
  const Arc other{V(5, 0), 1.0, kPi / 2, kPi};
  EXPECT_DOUBLE_EQ(intersectArc(other, V(0, 0), V(1, 0)), 4.0);
}

TEST(World, RejectsDegeneratePrimitives) {
  EXPECT_THROW(World({{V(0, 0), V(0, 0)}}, {}), Error);
  EXPECT_THROW(World({}, {Arc{V(0, 0), 0.0, 0, 1}}), Error);
  EXPECT_THROW(World({}, {Arc{V(0, 0), 1.0, 0, 0}}), Error);
  EXPECT_THROW(World({{V(0, 0), V(std::nan(""), 1)}}, {}), Error);
  const World empty;
  EXPECT_EQ(empty.castRay(V(0, 0), 0.0, 10.0), kInf);
}

TEST(World, MaxRangeIsInclusiveAndLimits) {
  const World w({{V(3, -1), V(3, 1)}}, {});
  EXPECT_DOUBLE_EQ(w.castRay(V(0, 0), 0.0, 3.0), 3.0);
  EXPECT_EQ(w.castRay(V(0, 0), 0.0, 2.999), kInf);
  EXPECT_EQ(w.castRay(V(0, 0), kPi, 100.0), kInf);
}

// Rays from random origins in random directions, rays aimed exactly at segment end points, and
// rays tangent to every circle/arc: the grid caster must equal the brute-force loop.
class WorldRayCast : public ::testing::TestWithParam<std::string> {};

TEST_P(WorldRayCast, GridEqualsBruteForce) {
  const Scenario s = builtinScenario(GetParam());
  const World& w = s.world;
  Rng rng(42);
  const V lo = w.boundsMin() - V(2, 2), hi = w.boundsMax() + V(2, 2);
  auto randomPoint = [&] { return V(lo.x() + (hi.x() - lo.x()) * rng.uniform(), lo.y() + (hi.y() - lo.y()) * rng.uniform()); };
  std::size_t hits = 0, checked = 0;
  auto check = [&](const V& o, const V& d, double max_range) {
    const double fast = w.castRay(o, d, max_range);
    const double ref = w.castRayBruteForce(o, d, max_range);
    ++checked;
    if (std::isfinite(ref)) ++hits;
    if (std::isinf(ref)) {
      EXPECT_TRUE(std::isinf(fast)) << "origin " << o.transpose() << " dir " << d.transpose() << " fast " << fast;
    } else {
      EXPECT_NEAR(fast, ref, 1e-9) << "origin " << o.transpose() << " dir " << d.transpose();
    }
  };
  for (int i = 0; i < 20000; ++i) check(randomPoint(), unit(2 * kPi * rng.uniform()), i % 2 ? 30.0 : 8.0);
  for (const Segment& seg : w.segments()) {
    for (const V& end : {seg.a, seg.b}) {
      for (int k = 0; k < 3; ++k) {
        const V o = randomPoint();
        if ((end - o).norm() < 1e-6) continue;
        check(o, (end - o).normalized(), 100.0);
      }
    }
  }
  for (const Arc& a : w.arcs()) {
    for (int k = 0; k < 4; ++k) {
      const V o = randomPoint();
      const V oc = a.center - o;
      const double dist = oc.norm();
      if (dist <= a.radius_m) continue;
      const double base = std::atan2(oc.y(), oc.x()), half = std::asin(a.radius_m / dist);
      check(o, unit(base + half), 100.0);
      check(o, unit(base - half), 100.0);
      // Aimed at the arc's end points.
      check(o, (a.center + a.radius_m * unit(a.start_rad) - o).normalized(), 100.0);
      check(o, (a.center + a.radius_m * unit(a.start_rad + a.sweep_rad) - o).normalized(), 100.0);
    }
  }
  EXPECT_GT(hits, checked / 20) << "the test should exercise hits, not only misses";
}

INSTANTIATE_TEST_SUITE_P(AllWorlds, WorldRayCast, ::testing::Values("office", "corridor", "symmetric", "open"));

TEST(BuiltinWorlds, ListAndSizes) {
  EXPECT_EQ(listWorlds(), (std::vector<std::string>{"office", "corridor", "symmetric", "open"}));
  EXPECT_THROW(builtinScenario("moon"), Error);
  const World office = builtinScenario("office").world;
  EXPECT_EQ(office.boundsMin().x(), 0.0);  // (y: the curved desk's whole circle reaches below 0)
  EXPECT_EQ(office.boundsMax(), V(20, 15));
  // From the corridor the west wall is 0.7 m away and the east wall 19.3 m (nothing in between).
  EXPECT_NEAR(office.castRay(V(0.7, 7.5), kPi, 50), 0.7, 1e-12);
  EXPECT_NEAR(office.castRay(V(0.7, 7.5), 0.0, 50), 19.3, 1e-12);
  // The corridor world's corridor: 60 m of straight walls 2 m apart.
  const World corridor = builtinScenario("corridor").world;
  for (double x = 0.5; x < 60; x += 0.5) {
    EXPECT_NEAR(corridor.castRay(V(x, 0), kPi / 2, 30), 1.0, 1e-12);
    EXPECT_NEAR(corridor.castRay(V(x, 0), -kPi / 2, 30), 1.0, 1e-12);
  }
  // Along the axis: the cabinets on the end rooms' far walls (x = 67.5 and x = -7.5).
  EXPECT_NEAR(corridor.castRay(V(30, 0.5), 0.0, 100), 37.5, 1e-12);
  EXPECT_NEAR(corridor.castRay(V(30, 0.5), kPi, 100), 37.5, 1e-12);
  EXPECT_EQ(corridor.castRay(V(30, 0.5), 0.0, 30), std::numeric_limits<double>::infinity());
}

TEST(BuiltinWorlds, SymmetricWorldIsInvariantUnderQuarterTurns) {
  const World w = builtinScenario("symmetric").world;
  Rng rng(7);
  for (int i = 0; i < 2000; ++i) {
    const V o(6 * rng.uniform(), 6 * rng.uniform());  // room I
    const V d = unit(2 * kPi * rng.uniform());
    const double r0 = w.castRay(o, d, 30);
    V oi = o, di = d;
    for (int k = 1; k < 4; ++k) {
      oi = V(-oi.y(), oi.x());
      di = V(-di.y(), di.x());
      const double rk = w.castRay(oi, di, 30);
      if (std::isinf(r0))
        EXPECT_TRUE(std::isinf(rk));
      else
        EXPECT_NEAR(rk, r0, 1e-9) << "room " << k << " origin " << o.transpose();
    }
  }
}

TEST(BuiltinWorlds, DistanceToNearestPrimitive) {
  const World w({{V(0, 0), V(10, 0)}}, {Arc::circle(V(5, 5), 1.0), Arc{V(20, 0), 1.0, 0, kPi / 2}});
  EXPECT_NEAR(w.distance(V(3, 2)), 2.0, 1e-12);
  EXPECT_NEAR(w.distance(V(-3, 4)), 5.0, 1e-12);  // to the end point (0, 0)
  EXPECT_NEAR(w.distance(V(5, 5.5)), 0.5, 1e-12);
  EXPECT_NEAR(w.distance(V(20, -3)), std::hypot(1.0, 3.0), 1e-12);  // to the arc's end point (21, 0)
}

// ---- worlds from occupancy maps ----

// Reference: the ray's entry parameter into every obstacle cell (slab test), minimum over cells.
double perCellReference(const OccupancyImage& m, const V& o, const V& d, double max_range) {
  double best = kInf;
  for (int r = 0; r < m.height(); ++r)
    for (int c = 0; c < m.width(); ++c) {
      if (m.at(c, r) < 65) continue;
      const V lo = m.origin().translation() + V(c, r) * m.resolution();
      const V hi = lo + V::Constant(m.resolution());
      double t0 = 0, t1 = max_range;
      bool miss = false;
      for (int k = 0; k < 2 && !miss; ++k) {
        if (d[k] == 0) {
          miss = o[k] < lo[k] || o[k] > hi[k];
          continue;
        }
        double ta = (lo[k] - o[k]) / d[k], tb = (hi[k] - o[k]) / d[k];
        if (ta > tb) std::swap(ta, tb);
        t0 = std::max(t0, ta);
        t1 = std::min(t1, tb);
      }
      if (!miss && t0 <= t1) best = std::min(best, t0);
    }
  return best;
}

TEST(MapWorld, RayCastEqualsPerCellReference) {
  Rng rng(3);
  const int w = 40, h = 30;
  std::vector<std::int8_t> cells(w * h, 0);
  for (auto& c : cells) {
    const double u = rng.uniform();
    c = u < 0.08 ? 100 : (u < 0.12 ? -1 : (u < 0.15 ? 50 : 0));
  }
  for (int c = 0; c < w; ++c) cells[c] = 100;  // a wall along the bottom row
  const auto map = OccupancyImage::create(w, h, 0.1, SE2(-1.0, 2.0, 0.0), cells);
  const World world = worldFromMap(map);
  int compared = 0;
  for (int i = 0; i < 3000; ++i) {
    const auto col = static_cast<int>(rng.uniform() * w), row = static_cast<int>(rng.uniform() * h);
    if (map.at(col, row) >= 65) continue;  // rays start in free space
    const V o = map.origin().translation() + V(col + rng.uniform(), row + rng.uniform()) * 0.1;
    const V d = unit(2 * kPi * rng.uniform());
    const double ref = perCellReference(map, o, d, 10.0);
    const double got = world.castRay(o, d, 10.0);
    ++compared;
    if (std::isinf(ref))
      EXPECT_TRUE(std::isinf(got)) << got;
    else
      EXPECT_NEAR(got, ref, 1e-9) << "origin " << o.transpose() << " dir " << d.transpose();
  }
  EXPECT_GT(compared, 2000);
}

TEST(MapWorld, EdgesAreMergedIntoRuns) {
  // A 3 x 3 block of occupied cells: four edges only.
  auto map = OccupancyImage::filled(5, 5, 1.0, SE2(), 0);
  for (int r = 1; r <= 3; ++r)
    for (int c = 1; c <= 3; ++c) map.set(c, r, 100);
  const World world = worldFromMap(map);
  EXPECT_EQ(world.segments().size(), 4u);
  EXPECT_NEAR(world.castRay(V(0.5, 2.5), 0.0, 10), 0.5, 1e-12);
}

TEST(MapWorld, RandomWalkKeepsClearance) {
  // A 10 x 6 m room with a 2 m pillar block in the middle, 5 cm cells.
  auto map = OccupancyImage::filled(200, 120, 0.05, SE2(1.0, -2.0, 0.0), 0);
  for (int r = 0; r < 120; ++r)
    for (int c = 0; c < 200; ++c)
      if (r == 0 || c == 0 || r == 119 || c == 199 || (c >= 80 && c < 120 && r >= 40 && r < 80)) map.set(c, r, 100);
  const World world = worldFromMap(map);
  RandomWalkOptions o;
  o.length_m = 60;
  o.clearance_m = 0.5;
  o.seed = 11;
  const auto route = randomWalk(map, o);
  ASSERT_GE(route.size(), 2u);
  double len = 0;
  for (std::size_t i = 1; i < route.size(); ++i) {
    len += (route[i] - route[i - 1]).norm();
    for (double f = 0; f <= 1.0; f += 0.02) EXPECT_GE(world.distance(route[i - 1] + f * (route[i] - route[i - 1])), 0.45);
  }
  EXPECT_GE(len, 60.0);
  // Deterministic per seed.
  EXPECT_EQ(randomWalk(map, o), route);
  // No room for the clearance.
  o.clearance_m = 5.0;
  EXPECT_THROW(randomWalk(map, o), Error);
}

}  // namespace
}  // namespace lidar2d::sim
