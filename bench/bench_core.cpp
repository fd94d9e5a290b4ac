// Micro-benchmarks of the core types.

#include <benchmark/benchmark.h>

#include <numbers>

#include "lidar2d/core/laser_scan.hpp"
#include "lidar2d/core/se2.hpp"

namespace {

void BM_Se2Compose(benchmark::State& state) {
  lidar2d::SE2 a(1.0, 2.0, 0.3), b(0.1, -0.2, 0.01);
  for (auto _ : state) {
    a = a * b;
    benchmark::DoNotOptimize(a);
  }
}
BENCHMARK(BM_Se2Compose);

void BM_ScanToPoints(benchmark::State& state) {
  lidar2d::LaserScanFields f;
  f.angle_min = -std::numbers::pi / 2;
  f.angle_increment = std::numbers::pi / static_cast<double>(state.range(0));
  f.range_max = 80;
  f.ranges.assign(static_cast<std::size_t>(state.range(0)), 5.0);
  const auto scan = lidar2d::LaserScan::create(f);
  for (auto _ : state) benchmark::DoNotOptimize(scan.toPoints());
  state.SetItemsProcessed(state.iterations() * state.range(0));
}
BENCHMARK(BM_ScanToPoints)->Arg(180)->Arg(360);

}  // namespace
