// Occupancy models (log-odds, count, TSDF) on a tiny synthetic world: an axis-aligned room seen
// from several poses with exact ranges.

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <numbers>
#include <optional>
#include <random>
#include <set>
#include <thread>
#include <utility>

#include "lidar2d/core/error.hpp"
#include "lidar2d/mapping/occupancy_map.hpp"
#include "lidar2d/mapping/ray_trace.hpp"

namespace lidar2d::mapping {

void PrintTo(MapModel m, std::ostream* os) { *os << toString(m); }

namespace {

// Room [x0, x1] x [y0, y1]; walls at non-grid-aligned positions so sub-cell accuracy matters.
constexpr double kX0 = -2.013, kX1 = 3.021, kY0 = -1.537, kY1 = 2.478;

double rangeInRoom(const Eigen::Vector2d& o, double a) {
  const double dx = std::cos(a), dy = std::sin(a);
  double t = std::numeric_limits<double>::infinity();
  if (dx > 0) t = std::min(t, (kX1 - o.x()) / dx);
  if (dx < 0) t = std::min(t, (kX0 - o.x()) / dx);
  if (dy > 0) t = std::min(t, (kY1 - o.y()) / dy);
  if (dy < 0) t = std::min(t, (kY0 - o.y()) / dy);
  return t;
}

LaserScan roomScan(const SE2& T_world_laser, std::size_t beams = 720) {
  LaserScanFields f;
  f.angle_min = -std::numbers::pi;
  f.angle_increment = 2 * std::numbers::pi / static_cast<double>(beams);
  f.range_max = 30;
  for (std::size_t i = 0; i < beams; ++i)
    f.ranges.push_back(rangeInRoom(T_world_laser.translation(), T_world_laser.theta() + f.angle_min + i * f.angle_increment));
  return LaserScan::create(f);
}

double distanceToWalls(const Eigen::Vector2d& p) {
  return std::min({std::abs(p.x() - kX0), std::abs(p.x() - kX1), std::abs(p.y() - kY0), std::abs(p.y() - kY1)});
}

const std::vector<SE2> kPoses = {{0, 0, 0}, {1.5, 1.0, 0.7}, {-1.0, -0.5, -2.0}, {2.0, -1.0, 3.0}, {-1.2, 1.8, 1.1}};

class ModelTest : public ::testing::TestWithParam<MapModel> {};

TEST_P(ModelTest, WallsOccupiedInteriorFree) {
  MapOptions o;
  o.resolution_m = 0.05;
  auto map = makeMap(GetParam(), o);
  for (int rep = 0; rep < 3; ++rep)
    for (const SE2& T : kPoses) map->insert(roomScan(T), T);
  const GridGeometry& g = map->geometry();
  int wall_cells = 0, wall_occupied = 0, inner = 0, inner_free = 0, false_occ = 0;
  const CellBox b = map->bounds();
  for (int y = b.min.y; y <= b.max.y; ++y)
    for (int x = b.min.x; x <= b.max.x; ++x) {
      const Eigen::Vector2d c = g.centerOf({x, y});
      const bool inside = c.x() > kX0 && c.x() < kX1 && c.y() > kY0 && c.y() < kY1;
      const double d = distanceToWalls(c);
      const CellState s = map->state({x, y});
      // Cells a wall passes through (the wall line crosses the cell), away from the corners.
      const bool near_x_wall = std::min(std::abs(c.x() - kX0), std::abs(c.x() - kX1)) < 0.1;
      const bool near_y_wall = std::min(std::abs(c.y() - kY0), std::abs(c.y() - kY1)) < 0.1;
      const double h = 0.5 * g.resolution();
      const bool in_box = c.x() > kX0 - h && c.x() < kX1 + h && c.y() > kY0 - h && c.y() < kY1 + h;
      const bool on_wall = in_box && d < h && !(near_x_wall && near_y_wall);
      if (on_wall) {
        ++wall_cells;
        wall_occupied += s == CellState::kOccupied;
      }
      if (inside && d > 2 * g.resolution()) {
        ++inner;
        inner_free += s == CellState::kFree;
        false_occ += s == CellState::kOccupied;
      }
    }
  ASSERT_GT(wall_cells, 300);
  EXPECT_GE(wall_occupied, wall_cells * 98 / 100) << toString(GetParam()) << ": " << wall_occupied << "/" << wall_cells;
  EXPECT_GE(inner_free, inner * 99 / 100) << toString(GetParam()) << ": " << inner_free << "/" << inner;
  EXPECT_EQ(false_occ, 0) << toString(GetParam());
  EXPECT_GT(map->cellUpdates(), 0u);
}

TEST_P(ModelTest, NoReturnBeamsClearButMarkNothing) {
  MapOptions o;
  o.insert.no_return_clear_m = 2.0;
  auto map = makeMap(GetParam(), o);
  LaserScanFields f;
  f.angle_min = -0.5;
  f.angle_increment = 0.01;
  f.range_max = 10;
  f.ranges.assign(100, 10.0);  // all no-return
  // Several passes: with Cartographer's log-odds one pass (p = 0.49) is not yet "free".
  for (int i = 0; i < 10; ++i) map->insert(LaserScan::create(f), SE2());
  const CellBox b = map->bounds();
  ASSERT_FALSE(b.empty());
  for (int y = b.min.y; y <= b.max.y; ++y)
    for (int x = b.min.x; x <= b.max.x; ++x) EXPECT_NE(map->state({x, y}), CellState::kOccupied);
  EXPECT_LE(b.max.x, 2.0 / 0.05 + 1);
  EXPECT_EQ(map->state(map->geometry().cellOf({1.0, 0.0})), CellState::kFree);
  EXPECT_EQ(map->state(map->geometry().cellOf({3.0, 0.0})), CellState::kUnknown);
}

TEST_P(ModelTest, AbsurdPoseIsAnErrorAndLeavesTheMapUnchanged) {
  MapOptions o;
  o.insert.cell_budget = 10'000'000;
  auto map = makeMap(GetParam(), o);
  map->insert(roomScan(SE2()), SE2());
  const auto updates = map->cellUpdates();
  EXPECT_THROW(map->insert(roomScan(SE2()), SE2(1e7, 0, 0)), Error);
  EXPECT_THROW(map->insert(roomScan(SE2()), SE2(1e12, 0, 0)), Error);
  EXPECT_THROW(map->insert(roomScan(SE2()), SE2(std::nan(""), 0, 0)), Error);
  EXPECT_EQ(map->cellUpdates(), updates);
}

// Random scans for the threads=1 vs threads=2 comparison: random ranges (some NaN, below
// range_min, +inf, beyond max_range or at range_max) over a full turn, so beams cross split lines
// in every direction; beam 0 points exactly along the laser's x axis.
LaserScan randomScan(std::mt19937& rng, std::size_t beams) {
  LaserScanFields f;
  f.angle_min = 0;
  f.angle_increment = 2 * std::numbers::pi / static_cast<double>(beams);
  f.range_min = 0.1;
  f.range_max = 15;
  std::uniform_real_distribution<double> ur(0.0, 14.0), u01(0, 1);
  for (std::size_t i = 0; i < beams; ++i) {
    const double p = u01(rng);
    f.ranges.push_back(p < 0.03   ? std::nan("")
                       : p < 0.06 ? 0.05
                       : p < 0.10 ? std::numeric_limits<double>::infinity()
                       : p < 0.13 ? 15.0
                                  : ur(rng));
  }
  return LaserScan::create(f);
}

// Every observable of two maps, cell by cell (bit-identical probabilities, not "near").
void expectIdentical(const OccupancyMap& a, const OccupancyMap& b) {
  ASSERT_EQ(a.bounds().min, b.bounds().min);
  ASSERT_EQ(a.bounds().max, b.bounds().max);
  EXPECT_EQ(a.cellUpdates(), b.cellUpdates());
  EXPECT_EQ(a.cellVisits(), b.cellVisits());
  EXPECT_EQ(a.memoryBytes(), b.memoryBytes());
  const CellBox box = a.bounds();
  std::size_t differing = 0, observed = 0;
  for (int y = box.min.y - 1; y <= box.max.y + 1; ++y)
    for (int x = box.min.x - 1; x <= box.max.x + 1; ++x) {
      const auto pa = a.probability({x, y}), pb = b.probability({x, y});
      observed += pa.has_value();
      differing += pa != pb || a.state({x, y}) != b.state({x, y});
    }
  EXPECT_EQ(differing, 0u);
  EXPECT_GT(observed, 1000u);
  if (a.model() == MapModel::kTsdf) {
    const auto sa = tsdfSurface(a), sb = tsdfSurface(b);
    ASSERT_EQ(sa.size(), sb.size());
    for (std::size_t i = 0; i < sa.size(); ++i) {
      EXPECT_EQ(sa[i].p_world, sb[i].p_world);
      EXPECT_EQ(sa[i].weight, sb[i].weight);
    }
  }
}

// Two threads split each scan's cells by a line on a tile border; the result must be exactly the
// single-threaded map. Resolution 1/8 m makes tile borders (8 m) and cell corners exact in
// floating point, so the poses below put the laser exactly on borders and corners and send beams
// exactly along them (theta 0, beam 0) or through cell corners (45 degrees).
TEST_P(ModelTest, TwoThreadsGiveTheSingleThreadedMapExactly) {
  for (const double res : {0.125, 0.05}) {
    MapOptions o1;
    o1.resolution_m = res;
    o1.insert.threads = 1;
    MapOptions o2 = o1;
    o2.insert.threads = 2;
    o2.insert.adaptive_threads = false;  // split every scan worth it, however busy the machine
    auto one = makeMap(GetParam(), o1), two = makeMap(GetParam(), o2);
    std::mt19937 rng(7);
    std::uniform_real_distribution<double> ux(-12, 12), ua(-std::numbers::pi, std::numbers::pi);
    std::vector<std::pair<LaserScan, SE2>> scans;
    for (const SE2& T : {SE2(0, 0, 0), SE2(8, 8, 0), SE2(8, -8, std::numbers::pi / 4), SE2(-8, 0.5, std::numbers::pi / 2),
                         SE2(7.999, 8.001, 0), SE2(16, 0, -std::numbers::pi / 4)})
      scans.emplace_back(randomScan(rng, 360), T);
    for (int i = 0; i < 40; ++i) {
      const SE2 T(ux(rng), ux(rng), ua(rng));
      scans.emplace_back(randomScan(rng, i % 5 == 0 ? 24 : 360), T);  // some scans too small to split
    }
    for (const SE2& T : kPoses) scans.emplace_back(roomScan(T), T);  // dense, overlapping: many cells per scan
    for (int rep = 0; rep < 2; ++rep)
      for (const auto& [scan, T] : scans) {
        one->insert(scan, T);
        two->insert(scan, T);
      }
    EXPECT_EQ(one->parallelScans(), 0u);
    EXPECT_GT(two->parallelScans(), scans.size());  // most scans (of both passes) were split
    expectIdentical(*one, *two);
  }
}

// prepare() on another thread, a few scans ahead, then insert(PreparedScan&): the same map as
// insert(scan, pose); a prepared scan is inserted once, and only into the map that prepared it.
TEST_P(ModelTest, PreparedAheadOnAnotherThreadGivesTheSameMap) {
  MapOptions o;
  o.resolution_m = 0.05;
  auto direct = makeMap(GetParam(), o), piped = makeMap(GetParam(), o), other = makeMap(GetParam(), o);
  std::mt19937 rng(11);
  std::vector<std::pair<LaserScan, SE2>> scans;
  for (const SE2& T : kPoses) scans.emplace_back(roomScan(T), T);
  for (int i = 0; i < 20; ++i) scans.emplace_back(randomScan(rng, 360), SE2(0.3 * i, -0.2 * i, 0.4 * i));
  for (const auto& [scan, T] : scans) direct->insert(scan, T);
  std::vector<OccupancyMap::PreparedScan> prepared(scans.size());
  std::thread preparer([&] {
    for (std::size_t i = 0; i < scans.size(); ++i) piped->prepare(scans[i].first, scans[i].second, prepared[i]);
  });
  preparer.join();
  for (auto& p : prepared) piped->insert(p);
  expectIdentical(*direct, *piped);
  EXPECT_EQ(direct->cellUpdates(), piped->cellUpdates());
  // Reusing a slot: prepared again, inserted again - still the same as inserting twice directly.
  piped->prepare(scans[0].first, scans[0].second, prepared[0]);
  piped->insert(prepared[0]);
  direct->insert(scans[0].first, scans[0].second);
  expectIdentical(*direct, *piped);
  // Inserted already, or prepared by another map: an error, and the map is unchanged.
  EXPECT_THROW(piped->insert(prepared[0]), Error);
  other->prepare(scans[1].first, scans[1].second, prepared[1]);
  EXPECT_THROW(piped->insert(prepared[1]), Error);
  expectIdentical(*direct, *piped);
  OccupancyMap::PreparedScan never;
  EXPECT_THROW(piped->insert(never), Error);
}

TEST_P(ModelTest, ManyMapsWithWorkersComeAndGo) {
  // Each map owns its worker; creating, using and destroying maps must not leak or hang.
  MapOptions o;
  o.insert.threads = 2;
  for (int i = 0; i < 20; ++i) {
    auto map = makeMap(GetParam(), o);
    map->insert(roomScan(SE2(0.1 * i, 0, 0)), SE2(0.1 * i, 0, 0));
    EXPECT_EQ(map->parallelScans(), 1u);
  }
}

INSTANTIATE_TEST_SUITE_P(Models, ModelTest, ::testing::Values(MapModel::kLogOdds, MapModel::kCount, MapModel::kTsdf),
                         [](const auto& info) { return std::string(toString(info.param)); });

TEST(LogOdds, ClassicIntegerPreset) {
  MapOptions o;
  o.logodds.classic_integer = true;
  auto map = makeMap(MapModel::kLogOdds, o);
  LaserScanFields f;
  f.angle_min = 0;
  f.angle_increment = 0.01;
  f.range_max = 10;
  f.ranges = {1.0};
  const auto scan = LaserScan::create(f);
  map->insert(scan, SE2(0.025, 0.025, 0));  // along the row of cells y = 0
  const GridGeometry& g = map->geometry();
  EXPECT_DOUBLE_EQ(*map->probability(g.cellOf({0.5, 0.025})), 0.49);  // one pass: 50 - 1
  EXPECT_DOUBLE_EQ(*map->probability(g.cellOf({1.03, 0.025})), 0.52);  // one hit: 50 + 2
  for (int i = 0; i < 100; ++i) map->insert(scan, SE2(0.025, 0.025, 0));
  EXPECT_DOUBLE_EQ(*map->probability(g.cellOf({0.5, 0.025})), 0.01);  // clamped at 1
  EXPECT_DOUBLE_EQ(*map->probability(g.cellOf({1.03, 0.025})), 1.0);  // clamped at 100
  EXPECT_FALSE(map->probability(g.cellOf({0.5, 1.0})).has_value());
}

TEST(LogOdds, CartographerDefaultsAndCellUpdatedOncePerBeam) {
  auto map = makeMap(MapModel::kLogOdds);
  LaserScanFields f;
  f.angle_min = 0;
  f.angle_increment = 0.01;
  f.range_max = 10;
  f.ranges = {1.0};
  map->insert(LaserScan::create(f), SE2(0.025, 0.025, 0));
  const GridGeometry& g = map->geometry();
  EXPECT_NEAR(*map->probability(g.cellOf({0.5, 0.025})), 0.49, 1e-6);
  EXPECT_NEAR(*map->probability(g.cellOf({1.03, 0.025})), 0.55, 1e-6);
  EXPECT_EQ(map->cellUpdates(), 21u);  // cells 0..20 along the beam, each once
}

// Beam i of `scan` from a laser at T as insertion computes it (OccupancyMap::prepare) [cells]: from
// `laserCells(T)` to the return, or, for a beam with no return (an infinite range), `clear_m` long;
// none for a NaN range.
Eigen::Vector2d laserCells(const SE2& T, double resolution_m) { return T.translation() * (1.0 / resolution_m); }
struct BeamSegment {
  Eigen::Vector2d end;
  bool hit;
};
std::optional<BeamSegment> beamSegment(const LaserScan& scan, std::size_t i, const SE2& T, double resolution_m,
                                       double clear_m = 0.0) {
  const double range = scan.ranges()[i];
  if (std::isnan(range)) return std::nullopt;
  const bool hit = std::isfinite(range);
  const double c0 = std::cos(T.theta()), s0 = std::sin(T.theta());
  const double a = scan.angle(i), ca = std::cos(a), sa = std::sin(a);
  const Eigen::Vector2d dir(c0 * ca - s0 * sa, s0 * ca + c0 * sa);
  return BeamSegment{laserCells(T, resolution_m) + dir * ((hit ? range : clear_m) * (1.0 / resolution_m)), hit};
}

// The cells the beams of `scan` pass (all but their end cells) and their end cells, from segments
// computed as insertion computes them (beamSegment; finite ranges), and the returns [cells].
struct TracedScan {
  std::set<std::pair<int, int>> passed, ends;
  std::vector<Eigen::Vector2d> returns;
  Eigen::Vector2d origin;
};
TracedScan traceScan(const LaserScan& scan, const SE2& T, double resolution_m) {
  TracedScan t;
  t.origin = laserCells(T, resolution_m);
  for (std::size_t i = 0; i < scan.size(); ++i) {
    const Eigen::Vector2d end = beamSegment(scan, i, T, resolution_m)->end;
    const CellIndex e = traceRay(t.origin, end, [&](CellIndex c) { t.passed.insert({c.x, c.y}); });
    t.ends.insert({e.x, e.y});
    t.returns.push_back(end);
  }
  return t;
}

// Every cell a beam passes gets one miss and its return's cell one hit, and no other cell is
// touched: the traversal reaches each cell's storage through its tile (entered as the walk crosses
// tile borders, in every direction, at negative coordinates too). Beams from near tile corners,
// guard off; the expected cells come from traceRay on the segments insertion computes.
TEST(Insertion, UpdatesExactlyTheTracedCellsAcrossTileBorders) {
  const double tile_m = 64 * 0.05;
  const std::vector<Eigen::Vector2d> origins = {
      {-tile_m + 0.0123, -tile_m + 0.0371}, {tile_m - 0.011, -0.013}, {0.013, tile_m - 0.002}, {-2 * tile_m + 0.07, 0.5}};
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> range(0.3, 9.0), heading(-std::numbers::pi, std::numbers::pi);
  for (const MapModel model : {MapModel::kLogOdds, MapModel::kCount}) {
    for (const Eigen::Vector2d& o : origins) {
      MapOptions opt;
      opt.resolution_m = 0.05;
      opt.insert.surface_guard_max_m = 0.0;
      auto map = makeMap(model, opt);
      LaserScanFields f;
      f.angle_min = -std::numbers::pi;
      f.angle_increment = 2 * std::numbers::pi / 360;
      f.range_max = 30;
      for (int i = 0; i < 360; ++i) f.ranges.push_back(range(rng));
      const LaserScan scan = LaserScan::create(f);
      const SE2 T(o.x(), o.y(), heading(rng));
      map->insert(scan, T);
      const auto [passed, ends, returns, origin] = traceScan(scan, T, opt.resolution_m);
      const double hit = model == MapModel::kLogOdds ? 0.55 : 1.0, miss = model == MapModel::kLogOdds ? 0.49 : 0.0;
      std::size_t checked = 0, mismatches = 0;
      for (int y = static_cast<int>(std::floor(origin.y())) - 200; y <= static_cast<int>(std::floor(origin.y())) + 200; ++y)
        for (int x = static_cast<int>(std::floor(origin.x())) - 200; x <= static_cast<int>(std::floor(origin.x())) + 200; ++x) {
          const auto p = map->probability(CellIndex{x, y});
          std::optional<double> expected;
          if (ends.count({x, y}))
            expected = hit;  // hits first: a passed cell holding a return keeps its hit
          else if (passed.count({x, y}))
            expected = miss;
          ++checked;
          if (p.has_value() != expected.has_value() || (p && std::abs(*p - *expected) > 1e-6)) ++mismatches;
        }
      EXPECT_EQ(mismatches, 0u) << toString(model) << " from (" << o.x() << ", " << o.y() << "), " << checked << " cells";
      EXPECT_GT(passed.size(), 5000u);
    }
  }
}

// The same with the surface guard on (the default), in a scene full of occluding edges: posts a
// few beams wide in front of a far wall, so that the guard keeps the cells of each post's surface
// and of its continuation past the post's edges. A beam touches only the cells it passes (and its
// return's), a kept cell is left untouched, and cells are kept only near a surface (a point of a
// surface segment lies within half of surface_guard_max_m of a return): every passed cell farther
// than that from every return is cleared.
TEST(Insertion, SurfaceGuardKeepsCellsOnlyNearSurfaces) {
  const std::vector<Eigen::Vector2d> origins = {{0.0123, 0.0371}, {-3.2 + 0.011, 1.613}, {2.3, -3.19}};
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> heading(-std::numbers::pi, std::numbers::pi), post(1.2, 4.0);
  std::size_t guarded_scenes = 0;
  for (const MapModel model : {MapModel::kLogOdds, MapModel::kCount}) {
    for (const Eigen::Vector2d& o : origins) {
      MapOptions opt;
      opt.resolution_m = 0.05;
      ASSERT_GT(opt.insert.surface_guard_max_m, 0.0);
      auto map = makeMap(model, opt);
      LaserScanFields f;
      f.angle_min = -std::numbers::pi;
      f.angle_increment = 2 * std::numbers::pi / 360;
      f.range_max = 30;
      f.ranges.assign(360, 8.0);
      for (int k = 0; k < 24; ++k) {  // posts 3 to 5 beams wide
        const int first = 15 * k + static_cast<int>(rng() % 5), width = 3 + static_cast<int>(rng() % 3);
        const double r = post(rng);
        for (int i = first; i < first + width && i < 360; ++i) f.ranges[static_cast<std::size_t>(i)] = r;
      }
      const LaserScan scan = LaserScan::create(f);
      const SE2 T(o.x(), o.y(), heading(rng));
      map->insert(scan, T);
      const auto [passed, ends, returns, origin] = traceScan(scan, T, opt.resolution_m);
      const double inv_res = 1.0 / opt.resolution_m;
      // A segment between two returns is at most surface_guard_max_m long, so each of its points
      // lies within half that of a return (an edge's segment: within 2 sqrt(2) cells); a cell it
      // keeps has its centre within half a cell diagonal of such a point.
      const double near_cells = (0.5 * opt.insert.surface_guard_max_m + 0.05) * inv_res;
      const int ox = static_cast<int>(std::floor(origin.x())), oy = static_cast<int>(std::floor(origin.y()));
      // Cells whose centre lies within near_cells of a return, over the checked square.
      constexpr int kHalf = 200, kSide = 2 * kHalf + 1;
      std::vector<std::uint8_t> near(kSide * kSide, 0);
      const int reach = static_cast<int>(std::ceil(near_cells));
      for (const Eigen::Vector2d& r : returns) {
        const int rx = static_cast<int>(std::floor(r.x())), ry = static_cast<int>(std::floor(r.y()));
        for (int y = std::max(ry - reach, oy - kHalf); y <= std::min(ry + reach, oy + kHalf); ++y)
          for (int x = std::max(rx - reach, ox - kHalf); x <= std::min(rx + reach, ox + kHalf); ++x) {
            const double dx = x + 0.5 - r.x(), dy = y + 0.5 - r.y();
            if (dx * dx + dy * dy <= near_cells * near_cells) near[(y - oy + kHalf) * kSide + (x - ox + kHalf)] = 1;
          }
      }
      auto nearSurface = [&](int x, int y) { return near[(y - oy + kHalf) * kSide + (x - ox + kHalf)] != 0; };
      const double hit = model == MapModel::kLogOdds ? 0.55 : 1.0, miss = model == MapModel::kLogOdds ? 0.49 : 0.0;
      std::size_t stray = 0, spared_far = 0, spared_near = 0, cleared_far = 0;
      for (int y = oy - kHalf; y <= oy + kHalf; ++y)
        for (int x = ox - kHalf; x <= ox + kHalf; ++x) {
          const auto p = map->probability(CellIndex{x, y});
          if (ends.count({x, y})) {
            if (!p || std::abs(*p - hit) > 1e-6) ++stray;
          } else if (!passed.count({x, y})) {
            if (p) ++stray;
          } else if (!p) {
            (nearSurface(x, y) ? spared_near : spared_far) += 1;
          } else if (std::abs(*p - miss) > 1e-6) {
            ++stray;
          } else if (!nearSurface(x, y)) {
            ++cleared_far;
          }
        }
      const std::string where = std::string(toString(model)) + " from (" + std::to_string(o.x()) + ", " + std::to_string(o.y()) + ")";
      EXPECT_EQ(stray, 0u) << where;
      EXPECT_EQ(spared_far, 0u) << where;
      EXPECT_GT(cleared_far, 5000u) << where;
      if (spared_near > 0) ++guarded_scenes;
    }
  }
  EXPECT_EQ(guarded_scenes, 6u);  // the guard kept cells in every scene
}

// The surface guard keeps every cell of a wall that the scan saw: a straight wall at an angle to
// the grid, 1 m from the laser, seen by 720 beams, many of them at grazing incidence, which cross
// the wall's cells before their returns. Between two returns on the wall (at most
// surface_neighbor_max_m apart), every cell the wall passes through is hit or untouched by the
// scan, never cleared; without the guard, grazing beams clear some of them.
TEST(Insertion, SurfaceGuardKeepsTheWallCellsBetweenReturns) {
  const double res = 0.05;
  const Eigen::Vector2d laser(0.0123, 0.0371);
  // The wall: points q with n . q = c (n a unit normal), 1 m from the laser.
  const double wall_angle = 0.07;  // [rad] from the x axis
  const Eigen::Vector2d n(-std::sin(wall_angle), std::cos(wall_angle));
  const double c = n.dot(laser) + 1.0;
  LaserScanFields f;
  f.angle_min = -std::numbers::pi;
  f.angle_increment = 2 * std::numbers::pi / 720;
  f.range_max = 30;
  std::vector<Eigen::Vector2d> wall_returns;
  for (int i = 0; i < 720; ++i) {
    const double a = f.angle_min + i * f.angle_increment;
    const Eigen::Vector2d u(std::cos(a), std::sin(a));
    const double along = n.dot(u);  // the wall is hit where (laser + r u) . n = c
    const double r = along > 1e-9 ? (c - n.dot(laser)) / along : 1e9;
    if (r < 20) {
      f.ranges.push_back(static_cast<float>(r));
      wall_returns.push_back(laser + static_cast<double>(f.ranges.back()) * u);
    } else {
      f.ranges.push_back(std::numeric_limits<float>::infinity());  // no return
    }
  }
  const LaserScan scan = LaserScan::create(f);
  ASSERT_GT(wall_returns.size(), 300u);
  std::size_t checked = 0;
  std::size_t cleared[2] = {0, 0};  // guard on, off
  for (const bool guard : {true, false}) {
    MapOptions opt;
    opt.resolution_m = res;
    if (!guard) opt.insert.surface_guard_max_m = 0.0;
    for (const MapModel model : {MapModel::kLogOdds, MapModel::kCount}) {
      auto map = makeMap(model, opt);
      map->insert(scan, SE2(laser.x(), laser.y(), 0.0));
      const double miss = model == MapModel::kLogOdds ? 0.49 : 0.0;
      std::set<std::pair<int, int>> seen;
      for (std::size_t k = 0; k + 1 < wall_returns.size(); ++k) {
        const Eigen::Vector2d a = wall_returns[k], b = wall_returns[k + 1];
        if ((b - a).norm() > opt.insert.surface_neighbor_max_m) continue;
        // The cells the wall passes through between the two returns (sampled every 0.5 mm).
        const int steps = static_cast<int>(std::ceil((b - a).norm() / 0.0005));
        for (int s = 0; s <= steps; ++s) {
          const Eigen::Vector2d q = a + (b - a) * (static_cast<double>(s) / steps);
          const CellIndex cell{static_cast<int>(std::floor(q.x() / res)), static_cast<int>(std::floor(q.y() / res))};
          if (!seen.insert({cell.x, cell.y}).second) continue;
          const auto p = map->probability(cell);
          if (p && std::abs(*p - miss) < 1e-6) ++cleared[guard ? 0 : 1];
          if (guard && model == MapModel::kLogOdds) ++checked;
        }
      }
    }
  }
  EXPECT_GT(checked, 300u);
  EXPECT_EQ(cleared[0], 0u) << "wall cells cleared with the guard, of " << checked;
  EXPECT_GT(cleared[1], 20u) << "the scene does not test the guard";
}

// Beam directions are reused from the previous scan only when its angles are the same: scans of
// the same size but other angles, one after the other, put their returns where their own angles
// say.
TEST(Insertion, ScansWithOtherAnglesOfTheSameSizeUseTheirOwnDirections) {
  auto map = makeMap(MapModel::kLogOdds);
  const GridGeometry& g = map->geometry();
  auto scan = [](double angle_min, double increment) {
    LaserScanFields f;
    f.angle_min = angle_min;
    f.angle_increment = increment;
    f.range_max = 10;
    f.ranges = {2.0, 2.0, 2.0};
    return LaserScan::create(f);
  };
  const SE2 T(0.013, 0.027, 0.0);
  const std::vector<std::pair<double, double>> angles = {{0.0, 0.5}, {2.5, 0.5}, {2.5, -0.7}, {0.0, 0.5}};
  for (const auto& [angle_min, increment] : angles) {
    map->insert(scan(angle_min, increment), T);
    for (int i = 0; i < 3; ++i) {
      const double a = angle_min + i * increment;
      const Eigen::Vector2d end = T.translation() + 2.0 * Eigen::Vector2d(std::cos(a), std::sin(a));
      const auto p = map->probability(g.cellOf(end));
      ASSERT_TRUE(p.has_value()) << "angle " << a;
      EXPECT_GT(*p, 0.5) << "angle " << a;
    }
  }
}

// The part [t0, t1] of the segment p -> q (t in [0, 1]) inside the closed cell `c` shrunk by
// `inset` on each side, if any (Liang-Barsky clipping).
std::optional<std::pair<double, double>> clipToCell(const Eigen::Vector2d& p, const Eigen::Vector2d& q, CellIndex c,
                                                    double inset = 0.0) {
  double t0 = 0, t1 = 1;
  const Eigen::Vector2d d = q - p;
  for (int k = 0; k < 2; ++k) {
    const double lo = (k == 0 ? c.x : c.y) + inset, hi = lo + 1 - 2 * inset;
    if (d[k] == 0) {
      if (p[k] < lo || p[k] > hi) return std::nullopt;
      continue;
    }
    double a = (lo - p[k]) / d[k], b = (hi - p[k]) / d[k];
    if (a > b) std::swap(a, b);
    t0 = std::max(t0, a);
    t1 = std::min(t1, b);
  }
  if (t0 > t1) return std::nullopt;
  return std::make_pair(t0, t1);
}

// Log-odds and count start most walks away from the laser, where the beams around them certainly
// pass every cell the walk would (OccupancyMap::prepare). Scans with 0.25 to 1 degree between
// beams (and a negative increment), with short beams (posts) among long ones, runs of equal
// ranges, NaNs and beams with no return (which clear their end cell too); guard off.
// - From a generic pose, the cells a scan updates are exactly those its beams pass from the laser
//   (traceRay on the segments insertion computes, every walk from the laser).
// - From poses on cell corners or a cell centre, along the grid or the diagonal, beams run through
//   cell corners (or along cell borders), where the cell beside a corner that a walk takes depends
//   on rounding, and so on where the walk started. There, every cell that a beam crosses (a chord
//   longer than 1e-6 cells at least 1e-6 cells inside the cell, its end cell excepted) is cleared,
//   a return's cell holds a hit, and every updated cell is touched by a beam (within 1e-6 cells).
TEST(Insertion, WalksStartingAwayFromTheLaserUpdateTheSameCells) {
  constexpr double kRes = 0.05, kClear = 2.0;
  constexpr int kHalf = 200;  // cells checked around the laser (the beams reach 9 m = 180 cells)
  struct Layout {
    double angle_min, increment;
    int beams;
  };
  const std::vector<Layout> layouts = {{-std::numbers::pi, 2 * std::numbers::pi / 1440, 1440},
                                       {-std::numbers::pi / 2, std::numbers::pi / 360, 361},
                                       {-0.75 * std::numbers::pi, 1.5 * std::numbers::pi / 1080, 1081},
                                       {std::numbers::pi, -2 * std::numbers::pi / 360, 360}};
  struct Pose {
    Eigen::Vector2d xy;
    bool generic;
  };
  const std::vector<Pose> origins = {{{0.0123, -0.0371}, true},
                                     {{-1.2345, 0.6789}, true},
                                     {{0.0, 0.0}, false},
                                     {{7 * kRes, -3 * kRes}, false},
                                     {{0.025, 0.025}, false}};
  const std::vector<std::pair<double, bool>> headings = {
      {0.3719, true}, {2.2, true}, {0.0, false}, {std::numbers::pi / 4, false}, {std::numbers::pi / 2, false}};
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> wall(2.0, 9.0), post(0.2, 1.5), u(0.0, 1.0);
  std::size_t generic_scenes = 0, corner_scenes = 0;
  for (const MapModel model : {MapModel::kLogOdds, MapModel::kCount}) {
    const double hit_p = model == MapModel::kLogOdds ? 0.55 : 1.0, miss_p = model == MapModel::kLogOdds ? 0.49 : 0.0;
    for (const Layout& layout : layouts) {
      for (const auto& [o, generic_origin] : origins) {
        for (const auto& [heading, generic_heading] : headings) {
          const bool generic = generic_origin && generic_heading;
          MapOptions opt;
          opt.resolution_m = kRes;
          opt.insert.surface_guard_max_m = 0.0;
          opt.insert.no_return_clear_m = kClear;
          auto map = makeMap(model, opt);
          LaserScanFields f;
          f.angle_min = layout.angle_min;
          f.angle_increment = layout.increment;
          f.range_max = 10;
          double r = wall(rng);
          for (int i = 0; i < layout.beams; ++i) {
            const double v = u(rng);
            if (v < 0.05) r = wall(rng);  // another wall from here on (runs of similar ranges)
            r = std::clamp(r + 0.02 * (u(rng) - 0.5), 2.0, 9.0);
            f.ranges.push_back(v < 0.10   ? post(rng)
                               : v < 0.12 ? std::numeric_limits<double>::quiet_NaN()
                               : v < 0.15 ? std::numeric_limits<double>::infinity()
                               : v < 0.20 ? 5.0
                                          : r);
          }
          const LaserScan scan = LaserScan::create(f);
          const SE2 T(o.x(), o.y(), heading);
          map->insert(scan, T);
          // Per cell around the laser: 1 passed by a full walk (a miss), 2 a return's cell (a hit,
          // which wins); and, for the poses on corners, whether a beam crosses it (4) or touches it (8).
          const Eigen::Vector2d origin = laserCells(T, kRes);
          const int ox = static_cast<int>(std::floor(origin.x())), oy = static_cast<int>(std::floor(origin.y()));
          std::vector<int> expected((2 * kHalf + 1) * (2 * kHalf + 1), 0);
          auto at = [&](CellIndex c) -> int& {
            return expected[(c.y - oy + kHalf) * (2 * kHalf + 1) + (c.x - ox + kHalf)];
          };
          std::uint64_t full_walks = 0;
          for (std::size_t i = 0; i < scan.size(); ++i) {
            const auto segment = beamSegment(scan, i, T, kRes, kClear);
            if (!segment) continue;
            const Eigen::Vector2d end = segment->end;
            const bool hit = segment->hit;
            const CellIndex e = traceRay(origin, end, [&](CellIndex c) {
              at(c) |= 1;
              ++full_walks;
              if (generic) return;
              for (int dy = -1; dy <= 1; ++dy)
                for (int dx = -1; dx <= 1; ++dx) {
                  const CellIndex d{c.x + dx, c.y + dy};
                  if ((at(d) & 4) != 0) continue;                    // (crossed already, by this or another beam)
                  if (!clipToCell(origin, end, d, -1e-6)) continue;  // (touched, give or take rounding)
                  const auto inner = clipToCell(origin, end, d, 1e-6);
                  const bool crossed = inner && (inner->second - inner->first) * (end - origin).norm() > 1e-6;
                  at(d) |=
                      crossed && !(hit && d.x == floorToInt32(end.x()) && d.y == floorToInt32(end.y())) ? 4 | 8 : 8;
                }
            });
            ++full_walks;
            at(e) |= hit ? 2 | 8 : 1 | 4 | 8;
          }
          std::size_t mismatches = 0, updated = 0;
          for (int y = oy - kHalf; y <= oy + kHalf; ++y)
            for (int x = ox - kHalf; x <= ox + kHalf; ++x) {
              const auto p = map->probability(CellIndex{x, y});
              const int e = at(CellIndex{x, y});
              const bool is_hit = p && std::abs(*p - hit_p) < 1e-6, is_miss = p && std::abs(*p - miss_p) < 1e-6;
              bool ok;
              if (generic) {
                ok = (e & 2) ? is_hit : (e & 1) ? is_miss : !p.has_value();
                updated += e != 0;
              } else {
                ok = (e & 2) ? is_hit : (e & 4) ? is_miss : (e & 8) ? (!p || is_miss) : !p.has_value();
              }
              mismatches += ok ? 0 : 1;
            }
          EXPECT_EQ(mismatches, 0u) << toString(model) << ", " << layout.beams << " beams from (" << o.x() << ", "
                                    << o.y() << ") heading " << heading;
          if (generic) {
            EXPECT_EQ(map->cellUpdates(), updated);
          }
          // The walks did start away from the laser (visited cells / the full walks': 0.5-0.55 at
          // 0.25 degree, 0.68-0.74 at 0.5, 0.8-0.87 at 1 degree between beams, in these scenes).
          EXPECT_LT(map->cellVisits(), full_walks * 9 / 10) << toString(model) << ", " << layout.beams << " beams";
          ++(generic ? generic_scenes : corner_scenes);
        }
      }
    }
  }
  EXPECT_EQ(generic_scenes, 32u);
  EXPECT_EQ(corner_scenes, 168u);
}

TEST(Count, HitsOverHitsPlusMisses) {
  auto map = makeMap(MapModel::kCount);
  LaserScanFields f;
  f.angle_min = 0;
  f.angle_increment = 0.01;
  f.range_max = 10;
  f.ranges = {1.0};
  const auto near = LaserScan::create(f);
  f.ranges = {2.0};
  const auto far = LaserScan::create(f);
  const SE2 T(0.025, 0.025, 0);
  map->insert(near, T);
  map->insert(far, T);
  map->insert(far, T);
  EXPECT_NEAR(*map->probability(map->geometry().cellOf({1.03, 0.025})), 1.0 / 3.0, 1e-12);
}

TEST(Tsdf, SurfaceIsSubCellAndBetterThanOccupancyCells) {
  MapOptions o;
  o.resolution_m = 0.05;
  auto tsdf = makeMap(MapModel::kTsdf, o);
  auto logodds = makeMap(MapModel::kLogOdds, o);
  for (const SE2& T : kPoses) {
    tsdf->insert(roomScan(T), T);
    logodds->insert(roomScan(T), T);
  }
  const auto surface = tsdfSurface(*tsdf);
  ASSERT_GT(surface.size(), 300u);
  double sum = 0;
  int n = 0;
  for (const auto& s : surface) {
    // Skip the corners, where two walls meet and the distance is ambiguous.
    const Eigen::Vector2d& p = s.p_world;
    if (p.x() < kX0 + 0.2 || p.x() > kX1 - 0.2 || p.y() < kY0 + 0.2 || p.y() > kY1 - 0.2) {
      if (!(std::abs(p.x() - kX0) < 0.3 || std::abs(p.x() - kX1) < 0.3) || !(std::abs(p.y() - kY0) < 0.3 || std::abs(p.y() - kY1) < 0.3)) {
        sum += distanceToWalls(p);
        ++n;
      }
    }
  }
  ASSERT_GT(n, 200);
  const double tsdf_mean = sum / n;
  // Occupied log-odds cells, measured at their centres.
  double occ_sum = 0;
  int occ_n = 0;
  const CellBox b = logodds->bounds();
  for (int y = b.min.y; y <= b.max.y; ++y)
    for (int x = b.min.x; x <= b.max.x; ++x)
      if (logodds->state({x, y}) == CellState::kOccupied) {
        occ_sum += distanceToWalls(logodds->geometry().centerOf({x, y}));
        ++occ_n;
      }
  const double occ_mean = occ_sum / occ_n;
  EXPECT_LT(tsdf_mean, 0.25 * o.resolution_m) << "tsdf " << tsdf_mean << " occupancy " << occ_mean;
  EXPECT_LT(tsdf_mean, occ_mean);
  EXPECT_THROW(tsdfSurface(*logodds), Error);
}

TEST(MakeMap, RejectsOutOfDomainOptions) {
  auto expectField = [](MapOptions o, const std::string& field) {
    try {
      (void)makeMap(MapModel::kLogOdds, o);
      ADD_FAILURE() << field;
    } catch (const Error& e) {
      EXPECT_EQ(e.where().field, field) << e.what();
    }
  };
  MapOptions o;
  o.resolution_m = 0;
  expectField(o, "resolution");
  o = {};
  o.logodds.hit_probability = 1.0;
  expectField(o, "hit_probability");
  o = {};
  o.logodds.min_probability = 0.99;
  expectField(o, "min_probability");
  o = {};
  o.tsdf.truncation_m = -1;
  expectField(o, "truncation_m");
  o = {};
  o.insert.max_range_m = 1e9;
  expectField(o, "max_range_m");
  o = {};
  o.insert.threads = 0;
  expectField(o, "threads");
}

}  // namespace
}  // namespace lidar2d::mapping
