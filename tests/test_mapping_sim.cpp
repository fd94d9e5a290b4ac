// Mapping accuracy on the simulator's office world with noise off: walls seen are occupied, free
// space seen is free (compared with the world geometry at the map's resolution), and the TSDF's
// sub-cell surface is closer to the true walls than the occupancy models' cells.

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <numbers>
#include <set>
#include <string>
#include <tuple>

#include "lidar2d/io/carmen_writer.hpp"
#include "lidar2d/io/frame_source.hpp"
#include "lidar2d/mapping/occupancy_map.hpp"
#include "lidar2d/sim/path.hpp"
#include "lidar2d/sim/simulator.hpp"
#include "lidar2d/sim/worlds.hpp"
#include "support/test_support.hpp"

namespace lidar2d::mapping {

void PrintTo(MapModel m, std::ostream* os) { *os << toString(m); }

namespace {

struct SimData {
  sim::Scenario scenario = sim::builtinScenario("office");
  std::vector<Frame> frames;
  SimData() {
    sim::PathOptions p;
    p.rate_hz = 2.0;  // a scan every 0.4 m keeps the test fast
    frames = sim::simulate(scenario.world, sim::samplePath(scenario.waypoints, p), sim::SimulatorOptions{}.noiseFree());
  }
};

const SimData& data() {
  static const SimData d;
  return d;
}

// Where the world lies on the grid. The office's walls run along multiples of 5 cm, i.e. along
// cell borders of a 5 cm grid: such a wall passes through no cell (it only touches two rows), and
// which of the two a return falls into is decided by rounding. So the world is placed off the cell
// borders: shifted by a fraction of a cell, and also turned so that every wall crosses the grid
// at an angle (the harder case: walls clip cell corners and beams graze them).
struct Placement {
  const char* name;
  SE2 T_grid_world;
};
const Placement kShifted{"shifted", SE2(0.0123, 0.0371, 0.0)};
const Placement kTurned{"turned", SE2(0.0123, 0.0371, 7.0 * std::numbers::pi / 180.0)};

std::unique_ptr<OccupancyMap> buildMap(MapModel model, const SE2& T_grid_world = kShifted.T_grid_world) {
  MapOptions o;
  o.resolution_m = 0.05;
  auto map = makeMap(model, o);
  for (const Frame& f : data().frames) map->insert(f.scan, T_grid_world * *f.T_world_robot * f.T_robot_laser);
  return map;
}

void PrintTo(const Placement& p, std::ostream* os) { *os << p.name; }

class SimMapping : public ::testing::TestWithParam<std::tuple<MapModel, Placement>> {};

TEST_P(SimMapping, SeenWallsOccupiedSeenFreeSpaceFree) {
  const auto [model, placement] = GetParam();
  const SE2& S = placement.T_grid_world;
  const auto map = buildMap(model, S);
  const GridGeometry& g = map->geometry();
  const sim::World& world = data().scenario.world;
  // Wall cells that a beam endpoint fell into: the cells the laser actually saw a wall pass through.
  std::set<std::pair<int, int>> seen_wall;
  for (const Frame& f : data().frames)
    for (const auto& p : f.scan.toPoints(S * *f.T_world_robot * f.T_robot_laser)) {
      const CellIndex c = g.cellOf(p);
      seen_wall.insert({c.x, c.y});
    }
  ASSERT_GT(seen_wall.size(), 2000u);
  // Strictly (the endpoint's own cell occupied) and within one cell (as the real-data benchmark
  // counts).
  std::size_t wall_ok = 0, wall_near = 0;
  for (const auto& [x, y] : seen_wall) {
    wall_ok += map->state({x, y}) == CellState::kOccupied;
    bool near = false;
    for (int dy = -1; dy <= 1 && !near; ++dy)
      for (int dx = -1; dx <= 1 && !near; ++dx) near = map->state({x + dx, y + dy}) == CellState::kOccupied;
    wall_near += near;
  }
  // Free space: observed cells whose whole square is clear of the world (centre farther than half
  // a cell diagonal from every primitive) must be free, never occupied.
  std::size_t clear_cells = 0, clear_free = 0, clear_occupied = 0;
  const CellBox b = map->bounds();
  const SE2 T_world_grid = S.inverse();
  for (int y = b.min.y; y <= b.max.y; ++y)
    for (int x = b.min.x; x <= b.max.x; ++x) {
      const CellState st = map->state({x, y});
      if (st == CellState::kUnknown && model != MapModel::kTsdf) continue;
      if (!map->probability({x, y})) continue;  // never observed
      if (world.distance(T_world_grid * g.centerOf({x, y})) < 0.75 * g.resolution()) continue;
      ++clear_cells;
      clear_free += st == CellState::kFree;
      clear_occupied += st == CellState::kOccupied;
    }
  ASSERT_GT(clear_cells, 20000u);
  const double wall_frac = static_cast<double>(wall_ok) / static_cast<double>(seen_wall.size());
  const double wall_near_frac = static_cast<double>(wall_near) / static_cast<double>(seen_wall.size());
  const double free_frac = static_cast<double>(clear_free) / static_cast<double>(clear_cells);
  const double occ_frac = static_cast<double>(clear_occupied) / static_cast<double>(clear_cells);
  std::printf("%s %s: seen wall cells occupied %.2f%% (%zu of %zu not; within one cell %.2f%%), clear cells free %.2f%%, "
              "occupied %.3f%%\n",
              toString(model), placement.name, 100 * wall_frac, seen_wall.size() - wall_ok, seen_wall.size(),
              100 * wall_near_frac, 100 * free_frac, 100 * occ_frac);
  // Strict coverage. Log-odds and count: the few cells left are on the 5 cm table legs (one cell
  // across, seen by a few returns) and at wall ends. TSDF: its export marks the cells its zero
  // contour passes through, and at corners and wall ends the averaged field of one-sided views does
  // not cross zero inside the corner cell (2-4% of the seen wall cells; BENCHMARK.md).
  EXPECT_GE(wall_frac, model == MapModel::kTsdf ? 0.95 : 0.995) << toString(model);
  EXPECT_GE(wall_near_frac, 0.999) << toString(model);
  if (model == MapModel::kTsdf) {
    // The TSDF marks cells just behind every surface negative (unknown in the export): inside the
    // 0.2 m walls and behind table legs. World::distance measures to the faces, so this test cannot
    // tell those cells from free space; they make up the few percent that are not "free". Occupied
    // clear cells: the contour of the projective field strays from the true surface behind the
    // 5 cm table legs and at room corners (about half each); marking every cell the contour passes
    // through (not only the nearer cell of each crossing) took this from 0.13% to 0.2-0.25%.
    EXPECT_GE(free_frac, 0.93);
    EXPECT_LE(occ_frac, 0.003);
  } else {
    EXPECT_GE(free_frac, 0.99) << toString(model);
    EXPECT_LE(occ_frac, 0.001) << toString(model);
  }
}

INSTANTIATE_TEST_SUITE_P(Models, SimMapping,
                         ::testing::Combine(::testing::Values(MapModel::kLogOdds, MapModel::kCount, MapModel::kTsdf),
                                            ::testing::Values(kShifted, kTurned)),
                         [](const auto& info) {
                           return std::string(toString(std::get<0>(info.param))) + "_" + std::get<1>(info.param).name;
                         });

// The office is closed by its outer walls: a scan taken inside it sees nothing outside. A lost echo
// (the simulator's dropout) reads as an error, not as "no return", so no beam clears through a wall.
TEST(SimMapping, LostEchoesClearNothingOutsideTheBuilding) {
  const sim::Scenario& s = data().scenario;
  sim::SimulatorOptions o;
  o.laser.dropout = 0.05;
  sim::PathOptions p;
  p.rate_hz = 2.0;
  const auto frames = sim::simulate(s.world, sim::samplePath(s.waypoints, p), o);
  std::size_t dropped = 0;
  for (const Frame& f : frames)
    for (std::size_t i = 0; i < f.scan.size(); ++i) dropped += f.scan.ranges()[i] == 0.0;
  ASSERT_GT(dropped, 1000u);
  // The same frames through a CARMEN log, as `lidar2d simulate` writes them and `map` reads them.
  std::vector<Frame> logged;
  {
    test::TempDir tmp;
    const std::string log = (tmp / "office.log").string();
    io::CarmenWriter w(log);
    for (const Frame& f : frames) w.write(f);
    w.commit();
    auto src = io::openLog(log);
    while (auto f = src->next()) logged.push_back(std::move(*f));
  }
  ASSERT_EQ(logged.size(), frames.size());
  for (const MapModel model : {MapModel::kLogOdds, MapModel::kCount, MapModel::kTsdf})
    for (const std::vector<Frame>* input : {&frames, static_cast<const std::vector<Frame>*>(&logged)}) {
      MapOptions mo;
      mo.resolution_m = 0.05;
      auto map = makeMap(model, mo);
      for (const Frame& f : *input) map->insert(f.scan, *f.T_world_robot * f.T_robot_laser);
      const GridGeometry& g = map->geometry();
      const Eigen::Vector2d lo = s.world.boundsMin(), hi = s.world.boundsMax();
      std::size_t free_outside = 0;
      const CellBox b = map->bounds();
      for (int y = b.min.y; y <= b.max.y; ++y)
        for (int x = b.min.x; x <= b.max.x; ++x) {
          const Eigen::Vector2d c = g.centerOf({x, y});
          const bool outside =
              c.x() < lo.x() - 0.1 || c.y() < lo.y() - 0.1 || c.x() > hi.x() + 0.1 || c.y() > hi.y() + 0.1;
          free_outside += outside && map->state({x, y}) == CellState::kFree;
        }
      EXPECT_EQ(free_outside, 0u) << toString(model) << (input == &logged ? " (through a CARMEN log)" : "");
    }
}

TEST(SimMapping, TsdfSurfaceIsSubCellAndBeatsOccupancyCells) {
  const sim::World& world = data().scenario.world;
  const auto tsdf = buildMap(MapModel::kTsdf);
  const auto surface = tsdfSurface(*tsdf);
  ASSERT_GT(surface.size(), 2000u);
  double sum = 0;
  const SE2 T_world_grid = kShifted.T_grid_world.inverse();
  for (const auto& s : surface) sum += world.distance(T_world_grid * s.p_world);
  const double tsdf_mean = sum / static_cast<double>(surface.size());
  for (MapModel m : {MapModel::kLogOdds, MapModel::kCount}) {
    const auto occ = buildMap(m);
    double occ_sum = 0;
    std::size_t n = 0;
    const CellBox b = occ->bounds();
    for (int y = b.min.y; y <= b.max.y; ++y)
      for (int x = b.min.x; x <= b.max.x; ++x)
        if (occ->state({x, y}) == CellState::kOccupied) {
          occ_sum += world.distance(T_world_grid * occ->geometry().centerOf({x, y}));
          ++n;
        }
    std::printf("mean distance to the walls: TSDF surface points %.4f m, %s occupied cell centres %.4f m\n", tsdf_mean,
                toString(m), occ_sum / static_cast<double>(n));
    EXPECT_LT(tsdf_mean, occ_sum / static_cast<double>(n)) << toString(m);
  }
  EXPECT_LT(tsdf_mean, 0.25 * 0.05) << "mean distance of TSDF surface points to the walls [m]";
}

}  // namespace
}  // namespace lidar2d::mapping
