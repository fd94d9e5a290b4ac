#pragma once
/// @file
/// The laser and odometry simulator: drives a robot along a sampled path through a `World` and
/// produces `Frame`s with a simulated scan, noisy odometry (`T_odom_robot`), the truth
/// (`T_world_robot`) and the laser mounting (`T_robot_laser`).
///
/// Deterministic per seed: the laser noise and the odometry noise use two independent `Rng`
/// streams derived from `SimulatorOptions::seed`, and every beam and step draws a fixed number of
/// random numbers, so switching one noise source off leaves the other unchanged (the people of a
/// `Crowd` draw from a third).

#include <cstdint>
#include <optional>
#include <utility>
#include <vector>

#include "lidar2d/core/frame.hpp"
#include "lidar2d/core/laser_scan.hpp"
#include "lidar2d/sim/noise.hpp"
#include "lidar2d/sim/path.hpp"
#include "lidar2d/sim/world.hpp"

namespace lidar2d::sim {

/// A 2D laser scanner. Defaults: a Hokuyo UTM-30LX-like scanner (270 degrees, 0.5 degree steps,
/// 30 m), mounted 0.1 m ahead of the robot's centre.
///
/// Beams are evenly spaced and centred on the laser's x axis: with a field of view below 360 degrees,
/// beam 0 is at -fov/2 and the last beam at +fov/2 (increment fov / (beams - 1)); with 360 degrees,
/// beam 0 is at -pi and the increment 2*pi / beams (no duplicated beam).
/// A beam that hits nothing within `range_max_m` reads `range_max_m` ("no return", invalid); a hit
/// reads the true distance plus N(0, range_noise_m^2), and with probability `dropout` is lost and
/// reads 0 instead: an error reading, as real lasers report a lost echo (a Hokuyo URG's error codes
/// below 20 mm, an RPLidar's 0), not "nothing there" - a wall that swallowed the echo is still there,
/// so mapping must not clear through it. Noisy ranges below 0 are clamped to 0. Readings
/// <= range_min are invalid and every algorithm ignores them.
struct LaserModel {
  int beams = 541;                        ///< number of beams, >= 1
  double fov_rad = 4.71238898038469;      ///< field of view [rad] (270 deg), in (0, 2*pi]
  double range_min_m = 0.05;              ///< shorter readings are invalid [m], >= 0
  double range_max_m = 30.0;              ///< maximum range; also the "no return" value [m], > range_min
  double range_noise_m = 0.01;            ///< standard deviation of the range noise [m], >= 0
  double dropout = 0.01;                  ///< probability that a hit is lost (reads 0, invalid) [0, 1]
  SE2 T_robot_laser = SE2(0.1, 0.0, 0.0); ///< mounting pose of the laser on the robot [m, m, rad]

  double angleMin() const;
  double angleIncrement() const;
  /// Throws `lidar2d::Error` (kInvalidArgument) naming the field out of its domain.
  void validate() const;
};

/// People walking the robot's own route, as passers-by in a corridor or a person walking ahead of
/// the robot do: moving obstacles the world does not hold. Person k is a disc of `radius_m` at the
/// robot's true position `lead_k` seconds later (earlier when negative; held at the route's ends),
/// `offset_k` to the left of the route's heading there; |lead_k| is uniform in [min_lead_s,
/// max_lead_s] with a random sign, offset_k uniform in [-max_offset_m, max_offset_m], drawn once
/// from a stream of their own (seed-derived), so the laser and odometry noise are the same with
/// and without people. A person whose centre lies within `radius_m` + 0.3 m of the laser is not seen
/// (no one stands inside the robot).
struct Crowd {
  std::size_t people = 0;
  double radius_m = 0.25;
  double min_lead_s = 2.0;
  double max_lead_s = 20.0;
  double max_offset_m = 0.5;

  /// Throws `lidar2d::Error` (kInvalidArgument) naming the field out of its domain.
  void validate() const;
};

/// Everything the simulator does, in one struct.
struct SimulatorOptions {
  LaserModel laser;
  OdometryNoise odometry;
  Crowd crowd;
  std::uint64_t seed = 1;            ///< seeds both noise streams
  bool odom_starts_at_truth = true;  ///< odometry frame = world frame at the first scan (else odometry starts at identity)

  /// The same options without any noise: exact ranges (hits at their true distance, no dropout)
  /// and odometry whose every step equals the true relative motion.
  SimulatorOptions noiseFree() const;
};

/// Streams frames along a given truth trajectory. Holds a reference to the world, which must
/// outlive the simulator.
class Simulator {
 public:
  /// `truth` gives the time and true pose of every scan (e.g. from `samplePath`). Throws
  /// `lidar2d::Error` (kInvalidArgument) for bad options or non-finite poses.
  Simulator(const World& world, std::vector<TimedPose> truth, SimulatorOptions options);
  Simulator(const Simulator&) = delete;
  Simulator& operator=(const Simulator&) = delete;

  /// The next frame (index, time, scan, odometry, truth, mounting), or std::nullopt after the last.
  std::optional<Frame> next();
  /// Number of frames in total.
  std::size_t size() const { return truth_.size(); }
  const std::vector<TimedPose>& truth() const { return truth_; }
  const SimulatorOptions& options() const { return options_; }

  /// The noise-free ranges the laser would measure with the robot at `T_world_robot` (one per
  /// beam; `range_max_m` for no return), the world alone (no people).
  std::vector<double> exactRanges(const SE2& T_world_robot) const;
  /// Where the people of `SimulatorOptions::crowd` are at time `t_s` (see `Crowd`).
  std::vector<Eigen::Vector2d> peopleAt(double t_s) const;
  /// Those ranges as a scan of this laser (time 0): the noise-free scan at `T_world_robot`, in the
  /// laser frame (`options().laser.T_robot_laser` mounts it on the robot).
  LaserScan exactScan(const SE2& T_world_robot) const;

 private:
  LaserScan makeScan(std::vector<double> ranges, double time_s) const;
  /// exactRanges with the discs of `people` (of radius crowd.radius_m) in the world.
  std::vector<double> ranges(const SE2& T_world_robot, const std::vector<Eigen::Vector2d>& people) const;

  const World& world_;
  std::vector<TimedPose> truth_;
  const SimulatorOptions options_;
  Rng laser_rng_;
  Rng odom_rng_;
  std::vector<std::pair<double, double>> people_;  // each person's lead [s] and offset [m]
  std::size_t k_ = 0;
  SE2 odom_;
};

/// All frames at once.
std::vector<Frame> simulate(const World& world, const std::vector<TimedPose>& truth, const SimulatorOptions& options);

}  // namespace lidar2d::sim
