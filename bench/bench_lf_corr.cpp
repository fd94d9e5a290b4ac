// Micro-benchmarks of likelihood-field and correlative matching on a noise-free simulated
// 360-beam pair of the office world (0.1 m / 3 degrees apart for LF, 0.5 m / 15 degrees for corr).

#include <benchmark/benchmark.h>

#include <memory>
#include <numbers>

#include "lidar2d/registration/correlative.hpp"
#include "lidar2d/registration/likelihood_field.hpp"
#include "lidar2d/sim/path.hpp"
#include "lidar2d/sim/simulator.hpp"
#include "lidar2d/sim/worlds.hpp"

namespace {

using namespace lidar2d;
using namespace lidar2d::registration;

struct Pair {
  Points2 target, source;
};

Pair makePair(const SE2& delta) {
  static const auto scenario = sim::builtinScenario("office");
  auto opts = sim::SimulatorOptions{}.noiseFree();
  opts.laser.beams = 360;
  opts.laser.fov_rad = 2.0 * std::numbers::pi;
  opts.laser.T_robot_laser = SE2();
  const auto route = sim::samplePath(scenario.waypoints, sim::PathOptions{});
  const sim::Simulator s(scenario.world, {{0.0, SE2()}}, opts);
  const SE2 A = route[route.size() / 3].T_world_robot;
  auto scan = [&](const SE2& T) {
    LaserScanFields f;
    f.angle_min = opts.laser.angleMin();
    f.angle_increment = opts.laser.angleIncrement();
    f.range_min = opts.laser.range_min_m;
    f.range_max = opts.laser.range_max_m;
    f.ranges = s.exactRanges(T);
    return LaserScan::create(f).toPoints();
  };
  return {scan(A), scan(A * delta)};
}

void BM_LfMatch(benchmark::State& state) {
  const auto pair = makePair(SE2(0.1, -0.05, 3.0 * std::numbers::pi / 180));
  LikelihoodFieldOptions o;
  o.solver = state.range(0) ? LfSolver::kCeres : LfSolver::kGaussNewton;
  const bool build = state.range(1) != 0;
  const auto field = LikelihoodField::fromPoints(pair.target, o);
  for (auto _ : state) {
    if (build) {
      benchmark::DoNotOptimize(matchLikelihoodField(pair.target, pair.source, SE2(), o));
    } else {
      benchmark::DoNotOptimize(matchLikelihoodField(field, pair.source, SE2(), o));
    }
  }
  state.SetLabel(std::string(o.solver == LfSolver::kCeres ? "ceres" : "gn") + (build ? " +field" : " field prepared"));
}
BENCHMARK(BM_LfMatch)->Args({0, 0})->Args({0, 1})->Args({1, 0})->Args({1, 1})->Unit(benchmark::kMillisecond);

void BM_LfFieldBuild(benchmark::State& state) {
  const auto pair = makePair(SE2());
  for (auto _ : state) benchmark::DoNotOptimize(LikelihoodField::fromPoints(pair.target));
}
BENCHMARK(BM_LfFieldBuild)->Unit(benchmark::kMillisecond);

void BM_CorrelativeWindow(benchmark::State& state) {
  const auto pair = makePair(SE2(0.5, -0.3, 15.0 * std::numbers::pi / 180));
  CorrelativeOptions o;  // 1 m x 30 degree window
  o.refine = state.range(0) != 0;
  const auto grid = CorrelativeGrid::fromPoints(pair.target, o);
  const auto field = LikelihoodField::fromPoints(pair.target, o.refinement);
  std::size_t scored = 0;
  for (auto _ : state) {
    const auto r = matchCorrelative(grid, pair.source, SE2(), o, &field);
    scored = r.candidates_scored;
    benchmark::DoNotOptimize(r);
  }
  state.counters["scored"] = static_cast<double>(scored);
  state.SetLabel(o.refine ? "search + LF refinement" : "search only");
}
BENCHMARK(BM_CorrelativeWindow)->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond);

void BM_CorrelativeGridBuild(benchmark::State& state) {
  const auto pair = makePair(SE2());
  for (auto _ : state) benchmark::DoNotOptimize(CorrelativeGrid::fromPoints(pair.target));
}
BENCHMARK(BM_CorrelativeGridBuild)->Unit(benchmark::kMillisecond);

}  // namespace
