// Micro-benchmarks of scan insertion per map model and thread count (InsertOptions::threads):
// cell updates per second.

#include <benchmark/benchmark.h>

#include <cmath>
#include <numbers>
#include <random>

#include "lidar2d/mapping/occupancy_map.hpp"

namespace {

using lidar2d::LaserScan;
using lidar2d::LaserScanFields;
using lidar2d::SE2;
using lidar2d::mapping::MapModel;

// A 360-beam, 180-degree scan in a 20 x 12 m room, seen from pose T (ranges 1-15 m, like an office).
LaserScan roomScan(const SE2& T) {
  LaserScanFields f;
  f.angle_min = -std::numbers::pi / 2;
  f.angle_increment = std::numbers::pi / 360;
  f.range_max = 80;
  const double x0 = -5, x1 = 15, y0 = -4, y1 = 8;
  for (int i = 0; i < 360; ++i) {
    const double a = T.theta() + f.angle_min + i * f.angle_increment;
    const double dx = std::cos(a), dy = std::sin(a);
    double t = 1e9;
    if (dx > 0) t = std::min(t, (x1 - T.x()) / dx);
    if (dx < 0) t = std::min(t, (x0 - T.x()) / dx);
    if (dy > 0) t = std::min(t, (y1 - T.y()) / dy);
    if (dy < 0) t = std::min(t, (y0 - T.y()) / dy);
    f.ranges.push_back(t);
  }
  return LaserScan::create(f);
}

void BM_InsertScan(benchmark::State& state) {
  const auto model = static_cast<MapModel>(state.range(0));
  lidar2d::mapping::MapOptions o;
  o.resolution_m = 0.05;
  o.insert.threads = static_cast<unsigned>(state.range(1));
  if (state.range(2) == 0) o.insert.surface_guard_max_m = 0.0;
  auto map = lidar2d::mapping::makeMap(model, o);
  std::mt19937 rng(1);
  std::uniform_real_distribution<double> ux(-3, 12), uy(-2, 6), ua(-3, 3);
  std::vector<std::pair<LaserScan, SE2>> scans;
  for (int i = 0; i < 64; ++i) {
    const SE2 T(ux(rng), uy(rng), ua(rng));
    scans.emplace_back(roomScan(T), T);
  }
  std::size_t k = 0;
  const auto before = map->cellUpdates();
  for (auto _ : state) {
    const auto& [scan, T] = scans[k++ % scans.size()];
    map->insert(scan, T);
  }
  state.counters["cell_updates_per_s"] =
      benchmark::Counter(static_cast<double>(map->cellUpdates() - before), benchmark::Counter::kIsRate);
  state.counters["split_share"] = static_cast<double>(map->parallelScans()) / static_cast<double>(state.iterations());
  state.SetLabel(lidar2d::mapping::toString(model));
}
// Args: model (0 log-odds, 1 count, 2 TSDF), threads, surface guard (1 on = default, 0 off; the
// TSDF has none). Real time: with two threads CPU time of the
// calling thread alone says little.
BENCHMARK(BM_InsertScan)->ArgsProduct({{0, 1, 2}, {1, 2}, {1}})->UseRealTime();
BENCHMARK(BM_InsertScan)->ArgsProduct({{0, 1}, {1}, {0}})->UseRealTime();

}  // namespace
