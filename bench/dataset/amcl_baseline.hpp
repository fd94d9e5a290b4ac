#pragma once
// An AMCL-style particle filter (Monte Carlo localization) seeded without an initial pose: the
// baseline `lidar2d track` is compared with in the dataset benchmark (what a user would otherwise
// run: ROS amcl after a "global localization" request). A baseline, not a library feature.
//
// The filter follows ROS amcl (Thrun, Burgard, Fox, "Probabilistic Robotics", 2005):
// - initialisation: `global_particles` poses uniform over the map's free cells, headings uniform;
// - motion: sample_motion_model_odometry (table 5.6) with the four alpha parameters, applied to the
//   odometry step between two scans (constant velocity when a frame has no odometry);
// - measurement: the likelihood-field beam model (section 6.4) on `beams` evenly subsampled scan
//   points; the per-beam likelihood pz = z_hit * exp(-d^2 / (2 sigma_hit^2)) + z_rand / max_range
//   is combined as amcl's LikelihoodFieldModel does, w = 1 + sum pz^3 (a tempered product: the
//   plain product of hundreds of beams makes the filter overconfident). d is the distance to the
//   nearest obstacle, read from registration::LikelihoodField (one level, truncated at
//   `max_obstacle_dist_m`); points off the map count as at that distance.
// - the measurement runs only after the robot moved `update_min_d_m` or turned `update_min_a_rad`
//   (amcl's update_min_d / update_min_a);
// - low-variance resampling (table 4.4) after every `resample_interval`-th measurement, with
//   augmented MCL's random particles (table 8.3, recovery_alpha_slow/fast);
// - the particle count is `tracking_particles` while the cloud is converged, `global_particles`
//   otherwise (a two-size stand-in for KLD sampling).
// The estimate is the weighted mean of the heaviest cluster of particles (as amcl publishes); the
// filter reports it as converged when that cluster holds `converged_weight` of the weight and the
// weighted standard deviation of its positions is under `converged_std_m` and that of its heading
// under `converged_std_rad`.

#include <cstddef>
#include <cstdint>
#include <numbers>
#include <optional>
#include <vector>

#include "lidar2d/core/frame.hpp"
#include "lidar2d/core/occupancy_image.hpp"
#include "lidar2d/core/se2.hpp"
#include "lidar2d/registration/likelihood_field.hpp"
#include "lidar2d/sim/noise.hpp"

namespace lidar2d::bench {

/// Parameters of the particle filter (amcl's names in brackets). `validate()` throws
/// `lidar2d::Error` (kInvalidArgument) naming the first field out of its domain.
struct AmclOptions {
  std::size_t global_particles = 20000;   ///< particles of the uniform start [max_particles], >= 1
  std::size_t tracking_particles = 2000;  ///< particles once converged [min_particles], >= 1
  // Motion noise: variances, e.g. var(rot1) = alpha1 rot1^2 + alpha2 trans^2. amcl's defaults (0.2
  // each) are 45% of every step; these are tuned to the benchmark's odometry (3% of the distance,
  // 3% of the turn and 1 deg per metre), with a margin of about three.
  double alpha1 = 0.01;              ///< rotation noise from rotation [odom_alpha1] [rad^2/rad^2], >= 0
  double alpha2 = 0.003;             ///< rotation noise from translation [odom_alpha2] [rad^2/m^2], >= 0
  double alpha3 = 0.01;              ///< translation noise from translation [odom_alpha3] [m^2/m^2], >= 0
  double alpha4 = 0.003;             ///< translation noise from rotation [odom_alpha4] [m^2/rad^2], >= 0
  std::size_t beams = 60;            ///< scan points used per update [laser_max_beams], >= 1
  double z_hit = 0.95;               ///< [laser_z_hit], in [0, 1]
  double z_rand = 0.05;              ///< [laser_z_rand], in [0, 1]
  double sigma_hit_m = 0.2;          ///< [laser_sigma_hit] [m], > 0
  double max_range_m = 30.0;         ///< range of the uniform term [laser_max_range] [m], > 0
  double max_obstacle_dist_m = 2.0;  ///< distances are clamped here [laser_likelihood_max_dist] [m], > 0
  double update_min_d_m = 0.2;       ///< [update_min_d] [m], >= 0
  double update_min_a_rad = std::numbers::pi / 6.0;  ///< [update_min_a] [rad], >= 0
  std::size_t resample_interval = 2;                 ///< measurements between resamplings [resample_interval], >= 1
  double alpha_slow = 0.001;      ///< [recovery_alpha_slow], in [0, 1]; 0 with alpha_fast 0: no random particles
  double alpha_fast = 0.1;        ///< [recovery_alpha_fast], in [0, 1]
  double converged_weight = 0.5;  ///< weight share of the heaviest cluster for convergence, in (0, 1]
  double converged_std_m = 0.5;   ///< position std under which the cluster is converged [m], > 0
  double converged_std_rad = 15.0 * std::numbers::pi / 180.0;  ///< heading std for that [rad], > 0
  std::uint64_t seed = 1;
  void validate() const;
};

/// The filter's answer for one scan.
struct AmclResult {
  SE2 T_world_robot;            ///< weighted mean of the heaviest cluster of particles
  double cluster_weight = 0.0;  ///< that cluster's share of the weight, in [0, 1]
  bool converged = false;       ///< the cloud is within converged_std_m / converged_std_rad
  bool updated = false;         ///< the measurement ran on this scan (the robot moved enough)
  double std_m = 0.0;           ///< weighted position std of the cluster [m]
  double std_rad = 0.0;         ///< weighted heading std of the cluster [rad]
  std::size_t particles = 0;    ///< particles after this scan
};

/// One robot in one map. Non-copyable (holds the field of the map).
class AmclFilter {
 public:
  /// Builds the distance field of `map` and spreads the particles over its free cells (value
  /// 0..free_max). Throws `lidar2d::Error` (kInvalidArgument) for bad options, (kBadInput) when the
  /// map has no free cell.
  explicit AmclFilter(const OccupancyImage& map, const AmclOptions& options = {});
  AmclFilter(const AmclFilter&) = delete;
  AmclFilter& operator=(const AmclFilter&) = delete;

  /// Motion and (when the robot moved enough) measurement update with the next frame's scan and
  /// odometry (`frame.T_odom_robot`; its truth is ignored).
  AmclResult add(const Frame& frame);
  /// Spreads the particles uniformly again (amcl's global_localization service).
  void globalize();

  std::size_t numParticles() const { return particles_.size(); }

 private:
  struct Particle {
    double x, y, theta, w;
  };
  void motion(const SE2& step);
  void measure(const Points2& points);
  void resample(std::size_t n);
  Particle randomParticle();
  AmclResult estimate() const;

  const AmclOptions o_;
  registration::LikelihoodField field_;
  std::vector<Eigen::Vector2d> free_cells_;  ///< centres of the free cells [m]
  double cell_m_ = 0.0;
  double origin_theta_ = 0.0;
  std::vector<Particle> particles_;
  sim::Rng rng_;
  std::optional<SE2> last_odom_;
  std::optional<SE2> step_;  ///< last odometry step (constant velocity without odometry)
  SE2 moved_;                ///< motion since the last measurement
  bool first_ = true;
  std::size_t measurements_ = 0;  ///< measurement updates since the last resampling
  double w_slow_ = 0.0, w_fast_ = 0.0;
};

}  // namespace lidar2d::bench
