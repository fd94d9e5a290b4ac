// Ray casting in the simulator's worlds (items per second = rays per second), grid against the
// brute-force reference, and a whole simulated scan.

#include <benchmark/benchmark.h>

#include <cmath>
#include <numbers>
#include <vector>

#include "lidar2d/sim/noise.hpp"
#include "lidar2d/sim/path.hpp"
#include "lidar2d/sim/simulator.hpp"
#include "lidar2d/sim/worlds.hpp"

namespace {

using lidar2d::sim::builtinScenario;

struct Ray {
  Eigen::Vector2d origin, dir;
};

// Rays from the poses of the world's own route (where the simulator casts them), all directions.
std::vector<Ray> routeRays(const std::string& world) {
  const auto s = builtinScenario(world);
  const auto poses = lidar2d::sim::samplePath(s.waypoints, lidar2d::sim::PathOptions{});
  lidar2d::sim::Rng rng(1);
  std::vector<Ray> rays;
  for (int i = 0; i < 4096; ++i) {
    const auto& p = poses[static_cast<std::size_t>(rng.uniform() * static_cast<double>(poses.size()))];
    const double a = 2 * std::numbers::pi * rng.uniform();
    rays.push_back({p.T_world_robot.translation(), Eigen::Vector2d(std::cos(a), std::sin(a))});
  }
  return rays;
}

void BM_CastRayGrid(benchmark::State& state, const std::string& world) {
  const auto s = builtinScenario(world);
  const auto rays = routeRays(world);
  std::size_t i = 0;
  for (auto _ : state) {
    const Ray& r = rays[i++ & 4095];
    benchmark::DoNotOptimize(s.world.castRay(r.origin, r.dir, 30.0));
  }
  state.SetItemsProcessed(static_cast<std::int64_t>(state.iterations()));
}
BENCHMARK_CAPTURE(BM_CastRayGrid, office, std::string("office"));
BENCHMARK_CAPTURE(BM_CastRayGrid, corridor, std::string("corridor"));
BENCHMARK_CAPTURE(BM_CastRayGrid, open, std::string("open"));

void BM_CastRayBruteForce(benchmark::State& state) {
  const auto s = builtinScenario("office");
  const auto rays = routeRays("office");
  std::size_t i = 0;
  for (auto _ : state) {
    const Ray& r = rays[i++ & 4095];
    benchmark::DoNotOptimize(s.world.castRayBruteForce(r.origin, r.dir, 30.0));
  }
  state.SetItemsProcessed(static_cast<std::int64_t>(state.iterations()));
}
BENCHMARK(BM_CastRayBruteForce);

// One full scan (541 beams, noise included) in the office world.
void BM_SimulateScan(benchmark::State& state) {
  const auto s = builtinScenario("office");
  const auto poses = lidar2d::sim::samplePath(s.waypoints, lidar2d::sim::PathOptions{});
  lidar2d::sim::SimulatorOptions o;
  std::size_t i = 0;
  for (auto _ : state) {
    lidar2d::sim::Simulator sim(s.world, {poses[i++ % poses.size()]}, o);
    benchmark::DoNotOptimize(sim.next());
  }
  state.SetItemsProcessed(static_cast<std::int64_t>(state.iterations()) * o.laser.beams);
}
BENCHMARK(BM_SimulateScan);

}  // namespace
