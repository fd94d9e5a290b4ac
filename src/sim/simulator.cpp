#include "lidar2d/sim/simulator.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <numbers>

#include "lidar2d/core/error.hpp"
#include "lidar2d/sim/log_perturbation.hpp"

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

void Crowd::validate() const {
  auto fail = [](const char* field, const std::string& what) {
    return invalidArgument(what, ErrorLocation({}, 0, fmt::format("crowd {}", field)));
  };
  if (people > 1000) throw fail("people", fmt::format("must be at most 1000, got {}", people));
  if (!std::isfinite(radius_m) || radius_m <= 0 || radius_m > 2)
    throw fail("radius", fmt::format("must be in (0, 2] m, got {}", radius_m));
  if (!std::isfinite(min_lead_s) || !std::isfinite(max_lead_s) || min_lead_s < 0 || max_lead_s < min_lead_s)
    throw fail("lead", fmt::format("must satisfy 0 <= min <= max, got [{}, {}] s", min_lead_s, max_lead_s));
  if (!std::isfinite(max_offset_m) || max_offset_m < 0)
    throw fail("offset", fmt::format("must be finite and >= 0, got {}", max_offset_m));
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
  options_.crowd.validate();
  for (std::size_t i = 0; i < truth_.size(); ++i)
    if (!truth_[i].T_world_robot.isFinite() || !std::isfinite(truth_[i].time_s))
      throw invalidArgument(fmt::format("truth pose {} is not finite", i), ErrorLocation({}, 0, "path"));
  const Crowd& c = options_.crowd;
  Rng crowd_rng(splitmix(options_.seed ^ 0x70656f706c650000ULL));
  for (std::size_t k = 0; k < c.people; ++k) {
    const double lead = c.min_lead_s + crowd_rng.uniform() * (c.max_lead_s - c.min_lead_s);
    const double sign = crowd_rng.uniform() < 0.5 ? -1.0 : 1.0;
    const double offset = (2.0 * crowd_rng.uniform() - 1.0) * c.max_offset_m;
    people_.emplace_back(sign * lead, offset);
  }
}

std::vector<double> Simulator::exactRanges(const SE2& T_world_robot) const { return ranges(T_world_robot, {}); }

std::vector<Eigen::Vector2d> Simulator::peopleAt(double t_s) const {
  std::vector<Eigen::Vector2d> out;
  out.reserve(people_.size());
  for (const auto& [lead, offset] : people_) {
    // From the last scan at or before the time (the route's times increase): sim::truthAt
    // interpolates forward from there, and holds the route's ends.
    const double t = t_s + lead;
    const auto it =
        std::upper_bound(truth_.begin(), truth_.end(), t, [](double v, const TimedPose& p) { return v < p.time_s; });
    const SE2 T = truthAt(truth_, it == truth_.begin() ? 0 : static_cast<std::size_t>(it - truth_.begin()) - 1, t);
    out.push_back(T.translation() + offset * Eigen::Vector2d(-std::sin(T.theta()), std::cos(T.theta())));
  }
  return out;
}

std::vector<double> Simulator::ranges(const SE2& T_world_robot, const std::vector<Eigen::Vector2d>& people) const {
  const LaserModel& l = options_.laser;
  const SE2 T_world_laser = T_world_robot * l.T_robot_laser;
  const Eigen::Vector2d origin = T_world_laser.translation();
  const double a0 = l.angleMin(), inc = l.angleIncrement();
  const double radius = options_.crowd.radius_m;
  std::vector<Eigen::Vector2d> seen;
  for (const Eigen::Vector2d& c : people)
    if ((c - origin).norm() > radius + 0.3) seen.push_back(c);
  std::vector<double> out(static_cast<std::size_t>(l.beams));
  for (std::size_t i = 0; i < out.size(); ++i) {
    const double a = T_world_laser.theta() + a0 + static_cast<double>(i) * inc;
    const Eigen::Vector2d dir(std::cos(a), std::sin(a));
    double r = world_.castRay(origin, dir, l.range_max_m);
    // The nearer intersection of the ray with each person's disc (the laser is outside every disc).
    for (const Eigen::Vector2d& c : seen) {
      const Eigen::Vector2d f = origin - c;
      const double b = f.dot(dir), disc = b * b - (f.squaredNorm() - radius * radius);
      if (disc < 0) continue;
      const double t = -b - std::sqrt(disc);
      if (t > 0 && t < r) r = t;
    }
    out[i] = r < l.range_max_m ? r : l.range_max_m;
  }
  return out;
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
  std::vector<double> ranges = this->ranges(tp.T_world_robot, peopleAt(tp.time_s));
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
