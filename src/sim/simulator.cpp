#include "lidar2d/sim/simulator.hpp"

#include <fmt/format.h>

#include <cmath>
#include <numbers>

#include "lidar2d/core/error.hpp"

namespace lidar2d::sim {
namespace {

constexpr double kTwoPi = 2.0 * std::numbers::pi;

bool fullCircle(double fov) { return fov >= kTwoPi - 1e-9; }

// SplitMix64 (Steele et al. 2014): decorrelates the seeds of the two noise streams.
std::uint64_t splitmix(std::uint64_t x) {
  x += 0x9e3779b97f4a7c15ULL;
  x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ULL;
  x = (x ^ (x >> 27)) * 0x94d049bb133111ebULL;
  return x ^ (x >> 31);
}

}  // namespace

double LaserModel::angleMin() const { return fullCircle(fov_rad) ? -std::numbers::pi : -fov_rad / 2; }

double LaserModel::angleIncrement() const {
  if (fullCircle(fov_rad)) return kTwoPi / beams;
  if (beams <= 1) return fov_rad > 0 ? fov_rad : 1e-3;  // a single beam at 0 still needs a non-zero step
  return fov_rad / (beams - 1);
}

void LaserModel::validate() const {
  auto fail = [](const char* field, const std::string& what) {
    return invalidArgument(what, ErrorLocation({}, 0, fmt::format("laser {}", field)));
  };
  if (beams < 1 || static_cast<std::size_t>(beams) > LaserScan::kMaxBeams)
    throw fail("beams", fmt::format("must be in 1..{}, got {}", LaserScan::kMaxBeams, beams));
  if (!std::isfinite(fov_rad) || fov_rad <= 0 || fov_rad > kTwoPi + 1e-9)
    throw fail("fov", fmt::format("must be in (0, 360] degrees, got {} rad", fov_rad));
  if (!std::isfinite(range_min_m) || range_min_m < 0) throw fail("range_min", "must be finite and >= 0");
  if (!std::isfinite(range_max_m) || range_max_m <= range_min_m)
    throw fail("range_max", fmt::format("must be finite and > range_min, got {}", range_max_m));
  if (!std::isfinite(range_noise_m) || range_noise_m < 0) throw fail("range_noise", "must be finite and >= 0");
  if (!(dropout >= 0 && dropout <= 1)) throw fail("dropout", fmt::format("must be in [0, 1], got {}", dropout));
  if (!T_robot_laser.isFinite()) throw fail("mount", "must be finite");
}

SimulatorOptions SimulatorOptions::noiseFree() const {
  SimulatorOptions o = *this;
  o.laser.range_noise_m = 0;
  o.laser.dropout = 0;
  o.odometry = OdometryNoise::none();
  return o;
}

Simulator::Simulator(const World& world, std::vector<TimedPose> truth, SimulatorOptions options)
    : world_(world),
      truth_(std::move(truth)),
      options_(std::move(options)),
      laser_rng_(splitmix(options_.seed)),
      odom_rng_(splitmix(options_.seed ^ 0x6f646f6d6574727fULL)) {
  options_.laser.validate();
  options_.odometry.validate();
  for (std::size_t i = 0; i < truth_.size(); ++i)
    if (!truth_[i].T_world_robot.isFinite() || !std::isfinite(truth_[i].time_s))
      throw invalidArgument(fmt::format("truth pose {} is not finite", i), ErrorLocation({}, 0, "path"));
}

std::vector<double> Simulator::exactRanges(const SE2& T_world_robot) const {
  const LaserModel& l = options_.laser;
  const SE2 T_world_laser = T_world_robot * l.T_robot_laser;
  const Eigen::Vector2d origin = T_world_laser.translation();
  const double a0 = l.angleMin(), inc = l.angleIncrement();
  std::vector<double> ranges(static_cast<std::size_t>(l.beams));
  for (std::size_t i = 0; i < ranges.size(); ++i) {
    const double a = T_world_laser.theta() + a0 + static_cast<double>(i) * inc;
    const double r = world_.castRay(origin, Eigen::Vector2d(std::cos(a), std::sin(a)), l.range_max_m);
    ranges[i] = r < l.range_max_m ? r : l.range_max_m;
  }
  return ranges;
}

LaserScan Simulator::makeScan(std::vector<double> ranges, double time_s) const {
  const LaserModel& l = options_.laser;
  LaserScanFields f;
  f.time = time_s;
  f.angle_min = l.angleMin();
  f.angle_increment = l.angleIncrement();
  f.range_min = l.range_min_m;
  f.range_max = l.range_max_m;
  f.ranges = std::move(ranges);
  return LaserScan::create(std::move(f));
}

LaserScan Simulator::exactScan(const SE2& T_world_robot) const { return makeScan(exactRanges(T_world_robot), 0.0); }

std::optional<Frame> Simulator::next() {
  if (k_ >= truth_.size()) return std::nullopt;
  const LaserModel& l = options_.laser;
  const TimedPose& tp = truth_[k_];
  std::vector<double> ranges = exactRanges(tp.T_world_robot);
  for (double& r : ranges) {
    // Fixed draws per beam (one Gaussian, one uniform), whether or not the beam hit.
    const double noise = laser_rng_.gaussian(l.range_noise_m);
    const bool drop = laser_rng_.uniform() < l.dropout;
    if (r >= l.range_max_m) continue;
    // A lost echo reads 0 (an error reading, invalid), never range_max ("no return", which
    // mapping clears along): see LaserModel.
    r = drop ? 0.0 : std::max(0.0, r + noise);
  }
  if (k_ == 0) {
    odom_ = options_.odom_starts_at_truth ? tp.T_world_robot : SE2();
  } else {
    const SE2 T_prev_cur = truth_[k_ - 1].T_world_robot.inverse() * tp.T_world_robot;
    odom_ = odom_ * noisyOdometryStep(T_prev_cur, options_.odometry, odom_rng_);
  }
  Frame frame;
  frame.index = k_;
  frame.time = tp.time_s;
  frame.scan = makeScan(std::move(ranges), tp.time_s);
  frame.T_odom_robot = odom_;
  frame.T_world_robot = tp.T_world_robot;
  frame.T_robot_laser = l.T_robot_laser;
  ++k_;
  return frame;
}

std::vector<Frame> simulate(const World& world, const std::vector<TimedPose>& truth, const SimulatorOptions& options) {
  Simulator sim(world, truth, options);
  std::vector<Frame> frames;
  frames.reserve(sim.size());
  while (auto f = sim.next()) frames.push_back(std::move(*f));
  return frames;
}

}  // namespace lidar2d::sim
