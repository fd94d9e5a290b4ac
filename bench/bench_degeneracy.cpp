// Micro-benchmarks of degeneracy detection on one 360-beam scan (270 degrees, 30 m, 1 cm noise)
// simulated in the middle of the corridor world (degenerate) and in a room of the office world (well
// constrained): each detector on its own and both together (degeneracy::analyze, one k-d tree).

#include <benchmark/benchmark.h>

#include <numbers>

#include "lidar2d/degeneracy/degeneracy.hpp"
#include "lidar2d/sim/simulator.hpp"
#include "lidar2d/sim/worlds.hpp"

namespace {

namespace deg = lidar2d::degeneracy;
using lidar2d::Points2;
using lidar2d::SE2;

Points2 simulatedScan(const std::string& world, const SE2& T_world_robot, int beams) {
  const lidar2d::sim::Scenario sc = lidar2d::sim::builtinScenario(world);
  lidar2d::sim::SimulatorOptions o;
  o.laser.beams = beams;
  lidar2d::sim::Simulator s(sc.world, {{0.0, T_world_robot}}, o);
  const lidar2d::Frame f = *s.next();
  return f.scan.toPoints(f.T_robot_laser);
}

const Points2& scanOf(int which) {
  static const Points2 corridor = simulatedScan("corridor", SE2(20, 0.1, 0.05), 360);
  static const Points2 office = simulatedScan("office", SE2(3, 3, 0.5), 360);
  return which == 0 ? corridor : office;
}

void BM_Combined(benchmark::State& state) {
  const Points2& pts = scanOf(static_cast<int>(state.range(0)));
  for (auto _ : state) benchmark::DoNotOptimize(deg::analyze(pts));
  state.SetLabel(state.range(0) == 0 ? "corridor, 360 beams" : "office room, 360 beams");
}
BENCHMARK(BM_Combined)->Arg(0)->Arg(1)->Unit(benchmark::kMicrosecond);

void BM_Geometric(benchmark::State& state) {
  const Points2& pts = scanOf(static_cast<int>(state.range(0)));
  for (auto _ : state) benchmark::DoNotOptimize(deg::analyzeGeometric(pts));
  state.SetLabel(state.range(0) == 0 ? "corridor, 360 beams" : "office room, 360 beams");
}
BENCHMARK(BM_Geometric)->Arg(0)->Arg(1)->Unit(benchmark::kMicrosecond);

void BM_Information(benchmark::State& state) {
  const Points2& pts = scanOf(static_cast<int>(state.range(0)));
  for (auto _ : state) benchmark::DoNotOptimize(deg::analyzeInformation(pts));
  state.SetLabel(state.range(0) == 0 ? "corridor, 360 beams" : "office room, 360 beams");
}
BENCHMARK(BM_Information)->Arg(0)->Arg(1)->Unit(benchmark::kMicrosecond);

}  // namespace
