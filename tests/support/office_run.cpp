#include "support/office_run.hpp"

#include "lidar2d/mapping/export.hpp"
#include "lidar2d/mapping/occupancy_map.hpp"
#include "lidar2d/sim/path.hpp"
#include "lidar2d/sim/simulator.hpp"
#include "lidar2d/sim/worlds.hpp"

namespace lidar2d::test {

const OfficeRun& officeMapAndRun() {
  static const OfficeRun o = [] {
    OfficeRun s;
    const auto scenario = sim::builtinScenario("office");
    sim::PathOptions po;
    po.rate_hz = 5.0;
    const auto truth = sim::samplePath(scenario.waypoints, po, 400);
    sim::SimulatorOptions so;
    so.laser.beams = 361;
    so.seed = 7;
    const auto clean = sim::simulate(scenario.world, truth, so.noiseFree());
    auto m = mapping::makeMap(mapping::MapModel::kLogOdds, {});
    for (const Frame& f : clean) m->insert(f.scan, *f.T_world_robot * f.T_robot_laser);
    s.map = mapping::toOccupancyImage(*m);
    s.frames = sim::simulate(scenario.world, truth, so);
    return s;
  }();
  return o;
}

}  // namespace lidar2d::test
