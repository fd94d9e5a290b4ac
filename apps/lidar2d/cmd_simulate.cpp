// lidar2d simulate --world NAME -o LOG: scans, noisy odometry and truth from a built-in world or a
// map_server map, written as a CARMEN log with TRUEPOS lines.
//
// Exit codes: an unknown --world name, a malformed triple (--odom-noise ...) or an out-of-range
// number (--beams 0, --rate -1, ...) is a usage error (exit 2, CLI11's message); a missing or
// malformed --map/--path file, a map without room for the route, or an unwritable output is bad
// input (exit 1, "lidar2d: error: ..."). Output is written atomically: nothing appears on failure.

#include <fmt/format.h>

#include <cmath>
#include <iostream>
#include <memory>
#include <numbers>
#include <sstream>

#include "commands.hpp"
#include "map_input.hpp"
#include "lidar2d/core/error.hpp"
#include "lidar2d/io/carmen_writer.hpp"
#include "lidar2d/io/map_file.hpp"
#include "lidar2d/io/trajectory.hpp"
#include "lidar2d/sim/path.hpp"
#include "lidar2d/sim/simulator.hpp"
#include "lidar2d/sim/worlds.hpp"

namespace lidar2d::cli {
namespace {

constexpr double kDeg = std::numbers::pi / 180.0;

// "a,b,c" -> `count` finite numbers (non-negative unless allow_negative).
bool parseNumbers(const std::string& s, double* out, int count, bool allow_negative) {
  std::stringstream ss(s);
  std::string part;
  int n = 0;
  while (std::getline(ss, part, ',')) {
    if (n == count || part.empty()) return false;
    char* end = nullptr;
    const double v = std::strtod(part.c_str(), &end);
    if (end == part.c_str() || *end != '\0' || !std::isfinite(v) || (!allow_negative && v < 0)) return false;
    out[n++] = v;
  }
  return n == count && s.back() != ',';
}

CLI::Validator numbers(const std::string& name, int count, bool allow_negative) {
  return CLI::Validator(
      [allow_negative, name, count](std::string& s) -> std::string {
        double v[3];
        if (parseNumbers(s, v, count, allow_negative)) return {};
        return fmt::format("expected {}: {} comma-separated {}numbers, got '{}'", name, count,
                           allow_negative ? "" : "non-negative ", s);
      },
      name);
}

struct SimulateArgs {
  std::string world;
  std::string map;
  BareMapOptions bare;
  std::string path;
  std::string output;
  std::uint64_t seed = 1;
  std::size_t scans = 0;
  double rate_hz = 10.0;
  double speed_mps = 0.8;
  int beams = 541;
  double fov_deg = 270.0;
  double max_range_m = 30.0;
  double min_range_m = 0.05;
  double range_noise_m = 0.01;
  double dropout = 0.01;
  std::string mount = "0.1,0,0";
  std::string odom_noise = "0.002,0.001,0.001";
  std::string odom_drift = "0.02,0.02,0.005";
  std::string odom_bias = "0.005,0.002";
  double clearance_m = 0.4;
  std::size_t people = 0;
  bool noise_free = false;
};

void run(const SimulateArgs& a) {
  const CreatedFolders out_folders = prepareOutputFile(a.output);
  if (a.world.empty() == a.map.empty())
    throw CLI::ValidationError("simulate", "give exactly one of --world NAME or --map MAP.yaml");
  if (a.map.empty() && a.bare.given())
    throw CLI::ValidationError("--resolution/--origin", "apply to a bare --map image, not to --world");
  sim::SimulatorOptions o;
  o.seed = a.seed;
  o.laser.beams = a.beams;
  o.laser.fov_rad = a.fov_deg * kDeg;
  o.laser.range_min_m = a.min_range_m;
  o.laser.range_max_m = a.max_range_m;
  o.laser.range_noise_m = a.range_noise_m;
  o.laser.dropout = a.dropout;
  double m[3], n[3], d[3], b[2];
  parseNumbers(a.mount, m, 3, true);  // already validated by the option checks
  parseNumbers(a.odom_noise, n, 3, false);
  parseNumbers(a.odom_drift, d, 3, false);
  parseNumbers(a.odom_bias, b, 2, true);
  if (!io::laserMountOffsetOk(m[0], m[1]))
    throw invalidArgument(fmt::format("X and Y must be within +-{:g} m of the robot's centre", io::kMaxLaserMountOffset),
                          ErrorLocation({}, 0, "--mount"));
  o.laser.T_robot_laser = SE2(m[0], m[1], m[2] * kDeg);
  o.odometry = {n[0], n[1], n[2], d[0], d[1], d[2], b[0], b[1]};
  if (a.noise_free) o = o.noiseFree();
  o.crowd.people = a.people;
  sim::PathOptions po;
  po.rate_hz = a.rate_hz;
  po.speed_mps = a.speed_mps;

  // The world and the truth trajectory.
  sim::World world;
  std::vector<sim::TimedPose> truth;
  std::string world_desc;
  if (!a.world.empty()) {
    sim::Scenario s = sim::builtinScenario(a.world);
    world = std::move(s.world);
    world_desc = fmt::format("world={}", a.world);
    if (a.path.empty()) truth = sim::samplePath(s.waypoints, po, a.scans);
  } else {
    const io::MapFile mf = readMapChecked(a.map, a.bare);
    world = sim::worldFromMap(mf.map, 65, a.map);
    world_desc = fmt::format("map={}", a.map);
    if (a.path.empty()) {
      const std::size_t scans = a.scans > 0 ? a.scans : 500;
      sim::RandomWalkOptions rw;
      rw.seed = a.seed;
      rw.clearance_m = a.clearance_m;
      rw.length_m = static_cast<double>(scans) / a.rate_hz * a.speed_mps + 1.0;
      truth = sim::samplePath(sim::randomWalk(mf.map, rw), po, scans);
    }
  }
  if (!a.path.empty()) {
    for (const StampedPose& p : io::readTrajectory(a.path)) truth.push_back({p.time, p.pose});
    if (truth.empty()) throw badInput("trajectory has no poses", ErrorLocation(a.path));
    if (a.scans > 0 && a.scans < truth.size()) truth.resize(a.scans);
  }

  sim::Simulator simulator(world, truth, o);
  io::CarmenWriter writer(a.output);
  const sim::LaserModel& l = o.laser;
  const sim::OdometryNoise& on = o.odometry;
  writer.comment(fmt::format(
      "lidar2d simulate: {} seed={} scans={} rate_hz={} speed_mps={} path={} beams={} fov_deg={} range_min_m={} "
      "range_max_m={} range_noise_m={} dropout={} mount=[{},{},{}] odom_noise=[{},{},{}] odom_drift=[{},{},{}] "
      "odom_bias=[{},{}]{}{}",
      world_desc, a.seed, truth.size(), a.rate_hz, a.speed_mps, a.path.empty() ? "route" : a.path, l.beams, a.fov_deg,
      l.range_min_m, l.range_max_m, l.range_noise_m, l.dropout, l.T_robot_laser.x(), l.T_robot_laser.y(),
      l.T_robot_laser.theta(), on.sigma_x_m, on.sigma_y_m, on.sigma_theta_rad, on.trans_sigma_per_m,
      on.rot_sigma_per_rad, on.rot_sigma_per_m, on.scale_bias, on.heading_bias_per_m, a.noise_free ? " noise_free" : "",
      a.people > 0 ? fmt::format(" people={}", a.people) : std::string()));
  std::size_t count = 0;
  while (auto f = simulator.next()) {
    writer.write(*f);
    ++count;
  }
  writer.commit();
  const double duration = truth.empty() ? 0.0 : truth.back().time_s - truth.front().time_s;
  std::cout << fmt::format("simulated {} scans ({}), path {:.1f} m in {:.1f} s -> {}\n", count, world_desc,
                           sim::pathLength(truth), duration, a.output);
}

}  // namespace

void addSimulateCommand(CLI::App& app) {
  auto a = std::make_shared<SimulateArgs>();
  auto* sub = app.add_subcommand(
      "simulate",
      "Simulate a robot with a 2D laser in a built-in world or a map_server map: scans, noisy odometry and "
      "truth, written as a CARMEN log with TRUEPOS lines. Deterministic per --seed.");
  std::string worlds;
  for (const auto& w : sim::listWorlds()) worlds.append(worlds.empty() ? "" : ", ").append(w);
  auto* world = sub->add_option("--world", a->world,
                                fmt::format("built-in world: {} (an unknown name is a usage error, exit 2)", worlds))
                    ->check(CLI::IsMember(sim::listWorlds()).description(""));
  std::string world_words;
  for (const auto& w : sim::listWorlds()) world_words.append(world_words.empty() ? "" : "|").append(w);
  world->type_name(world_words);
  auto* map = sub->add_option("--map", a->map,
                              "map_server YAML, or a bare PGM/PNG image with --resolution (and --origin): occupied cells "
                              "become walls; the route is a random walk through free space (default 500 scans)");
  addBareMapOptions(sub, a->bare, "--map");
  world->excludes(map);
  sub->add_option("-o,--output", a->output, "output CARMEN log")->required();
  sub->add_option("--seed", a->seed, "random seed (noise and random walks)")->capture_default_str();
  sub->add_option("--scans", a->scans,
                  "number of scans; 0 = the whole built-in route (driven back and forth when more are asked for)")
      ->capture_default_str();
  sub->add_option("--path", a->path,
                  "trajectory file (timestamp x y theta per line): one scan at each pose instead of the route");
  sub->add_option("--rate", a->rate_hz, "scan rate [Hz]")->capture_default_str()->check(positiveNumber());
  sub->add_option("--speed", a->speed_mps, "driving speed [m/s]")->capture_default_str()->check(positiveNumber());
  sub->add_option("--beams", a->beams, "beams per scan")->capture_default_str()->check(CLI::Range(1, 1 << 20));
  sub->add_option("--fov", a->fov_deg, "field of view [deg], centred on the laser's x axis")
      ->capture_default_str()
      ->check(CLI::Range(1e-6, 360.0));
  sub->add_option("--max-range", a->max_range_m, "maximum range [m]; no return reads this value")
      ->capture_default_str()
      ->check(positiveNumber());
  sub->add_option("--min-range", a->min_range_m, "minimum valid range [m]")->capture_default_str()->check(nonNegativeNumber());
  sub->add_option("--range-noise", a->range_noise_m, "std of the range noise [m]")
      ->capture_default_str()
      ->check(nonNegativeNumber());
  sub->add_option("--dropout", a->dropout, "probability that a return is lost")
      ->capture_default_str()
      ->check(CLI::Range(0.0, 1.0));
  sub->add_option("--mount", a->mount, "laser pose on the robot X,Y,YAW [m, m, deg]")
      ->capture_default_str()
      ->check(numbers("X,Y,YAW", 3, true));
  sub->add_option("--odom-noise", a->odom_noise,
                  "constant std of the odometry error per scan step SX,SY,STH [m, m, rad]")
      ->capture_default_str()
      ->check(numbers("SX,SY,STH", 3, false));
  sub->add_option("--odom-drift", a->odom_drift,
                  "extra std proportional to the motion: TRANS [m per m], ROT [rad per rad turned], ROTM [rad per m]")
      ->capture_default_str()
      ->check(numbers("TRANS,ROT,ROTM", 3, false));
  sub->add_option("--odom-bias", a->odom_bias,
                  "systematic odometry error SCALE,HEADING: distance scale error [] and heading drift [rad per m]")
      ->capture_default_str()
      ->check(numbers("SCALE,HEADING", 2, true));
  sub->add_option("--clearance", a->clearance_m, "--map random walks keep this distance from non-free cells [m]")
      ->capture_default_str()
      ->check(nonNegativeNumber());
  sub->add_flag("--noise-free", a->noise_free, "no range noise, no dropout, odometry equal to the true motion");
  sub->add_option("--people", a->people,
                  "N people walking the robot's route 2-20 s ahead of or behind it, within 0.5 m of it: discs of "
                  "0.25 m the laser sees and the world does not hold (moving obstacles; seeded)")
      ->capture_default_str()
      ->check(CLI::Range(std::size_t{0}, std::size_t{1000}));
  sub->callback([a] { run(*a); });
}

}  // namespace lidar2d::cli
