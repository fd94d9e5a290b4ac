#include "amcl_baseline.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>
#include <unordered_map>

#include "lidar2d/core/error.hpp"

namespace lidar2d::bench {

namespace {

void check(bool ok, const char* field, double value) {
  if (!ok) throw invalidArgument(fmt::format("AmclOptions.{} = {} is out of its domain", field, value));
}

// Smallest signed difference of two headings [rad].
double dtheta(double a, double b) { return angleDiff(a, b); }

}  // namespace

void AmclOptions::validate() const {
  check(global_particles >= 1, "global_particles", static_cast<double>(global_particles));
  check(tracking_particles >= 1, "tracking_particles", static_cast<double>(tracking_particles));
  check(alpha1 >= 0, "alpha1", alpha1);
  check(alpha2 >= 0, "alpha2", alpha2);
  check(alpha3 >= 0, "alpha3", alpha3);
  check(alpha4 >= 0, "alpha4", alpha4);
  check(beams >= 1, "beams", static_cast<double>(beams));
  check(z_hit >= 0 && z_hit <= 1, "z_hit", z_hit);
  check(z_rand >= 0 && z_rand <= 1, "z_rand", z_rand);
  check(sigma_hit_m > 0 && std::isfinite(sigma_hit_m), "sigma_hit_m", sigma_hit_m);
  check(max_range_m > 0 && std::isfinite(max_range_m), "max_range_m", max_range_m);
  check(max_obstacle_dist_m > 0 && std::isfinite(max_obstacle_dist_m), "max_obstacle_dist_m", max_obstacle_dist_m);
  check(update_min_d_m >= 0, "update_min_d_m", update_min_d_m);
  check(update_min_a_rad >= 0, "update_min_a_rad", update_min_a_rad);
  check(resample_interval >= 1, "resample_interval", static_cast<double>(resample_interval));
  check(alpha_slow >= 0 && alpha_slow <= 1, "alpha_slow", alpha_slow);
  check(alpha_fast >= 0 && alpha_fast <= 1, "alpha_fast", alpha_fast);
  check(converged_weight > 0 && converged_weight <= 1, "converged_weight", converged_weight);
  check(converged_std_m > 0, "converged_std_m", converged_std_m);
  check(converged_std_rad > 0, "converged_std_rad", converged_std_rad);
}

AmclFilter::AmclFilter(const OccupancyImage& map, const AmclOptions& options)
    : o_((options.validate(), options)), rng_(options.seed) {
  // One level of the library's distance field: the nearest obstacle cell's distance, clamped at
  // max_obstacle_dist_m (amcl's laser_likelihood_max_dist). The line search and levels are the
  // matcher's business; only `sample` is used here.
  registration::LikelihoodFieldOptions fo;
  fo.resolution_m = map.resolution();
  fo.levels = 1;
  fo.truncation_m = std::max(o_.max_obstacle_dist_m, 2.0 * map.resolution());
  field_ = registration::LikelihoodField::fromMap(map, fo);
  cell_m_ = map.resolution();
  origin_theta_ = map.origin().theta();
  // Free cells: known and below amcl's free threshold (0.25 occupancy).
  for (int row = 0; row < map.height(); ++row)
    for (int col = 0; col < map.width(); ++col) {
      const int v = map.at(col, row);
      if (v >= 0 && v < 25) free_cells_.push_back(map.cellCenter(col, row));
    }
  if (free_cells_.empty()) throw badInput("the map has no free cell to spread particles over");
  globalize();
}

AmclFilter::Particle AmclFilter::randomParticle() {
  const std::size_t k = std::min(free_cells_.size() - 1,
                                 static_cast<std::size_t>(rng_.uniform() * static_cast<double>(free_cells_.size())));
  // A uniform offset inside the cell (its sides along the map frame's axes).
  const double u = (rng_.uniform() - 0.5) * cell_m_, v = (rng_.uniform() - 0.5) * cell_m_;
  const double c = std::cos(origin_theta_), s = std::sin(origin_theta_);
  return {free_cells_[k].x() + c * u - s * v, free_cells_[k].y() + s * u + c * v,
          (2.0 * rng_.uniform() - 1.0) * std::numbers::pi, 1.0};
}

void AmclFilter::globalize() {
  particles_.clear();
  particles_.reserve(o_.global_particles);
  for (std::size_t i = 0; i < o_.global_particles; ++i) particles_.push_back(randomParticle());
  for (auto& p : particles_) p.w = 1.0 / static_cast<double>(particles_.size());
  w_slow_ = w_fast_ = 0.0;
  first_ = true;
  measurements_ = 0;
  moved_ = SE2();
}

// Probabilistic Robotics, table 5.6 (sample_motion_model_odometry), as amcl's AMCLOdom does it:
// the step is split into a first rotation, a translation and a second rotation, each perturbed
// with a variance from the alphas. Steps mostly backwards use the reversed first rotation
// (amcl's trick so that reversing does not read as a half turn).
void AmclFilter::motion(const SE2& step) {
  const double dx = step.x(), dy = step.y();
  const double trans = std::hypot(dx, dy);
  double rot1 = trans < 0.01 ? 0.0 : std::atan2(dy, dx);
  const double rot2_full = dtheta(step.theta(), rot1);
  const double rot1_noise = std::min(std::abs(wrapAngle(rot1)), std::abs(wrapAngle(rot1 - std::numbers::pi)));
  const double rot2_noise = std::min(std::abs(wrapAngle(rot2_full)), std::abs(wrapAngle(rot2_full - std::numbers::pi)));
  const double a1 = o_.alpha1, a2 = o_.alpha2, a3 = o_.alpha3, a4 = o_.alpha4;
  for (Particle& p : particles_) {
    const double r1 = dtheta(rot1, rng_.gaussian(std::sqrt(a1 * rot1_noise * rot1_noise + a2 * trans * trans)));
    const double t =
        trans -
        rng_.gaussian(std::sqrt(a3 * trans * trans + a4 * rot1_noise * rot1_noise + a4 * rot2_noise * rot2_noise));
    const double r2 = dtheta(rot2_full, rng_.gaussian(std::sqrt(a1 * rot2_noise * rot2_noise + a2 * trans * trans)));
    p.x += t * std::cos(p.theta + r1);
    p.y += t * std::sin(p.theta + r1);
    p.theta = wrapAngle(p.theta + r1 + r2);
  }
}

// Likelihood field model (Probabilistic Robotics, table 6.3) combined as amcl does: w *= 1 + sum pz^3.
void AmclFilter::measure(const Points2& points) {
  const double z_rand_mult = o_.z_rand / o_.max_range_m;
  const double denom = 2.0 * o_.sigma_hit_m * o_.sigma_hit_m;
  const double d_max = o_.max_obstacle_dist_m;
  double total = 0.0;
  for (Particle& p : particles_) {
    const double c = std::cos(p.theta), s = std::sin(p.theta);
    double sum = 0.0;
    for (const Eigen::Vector2d& q : points) {
      const Eigen::Vector2d w(p.x + c * q.x() - s * q.y(), p.y + s * q.x() + c * q.y());
      const auto smp = field_.sample(w, 0);
      const double d = std::min(d_max, std::abs(smp.value));
      const double pz = o_.z_hit * std::exp(-d * d / denom) + z_rand_mult;
      sum += pz * pz * pz;
    }
    p.w *= 1.0 + sum;
    total += p.w;
  }
  // Augmented MCL (table 8.3): short- and long-term averages of the measurement likelihood. The
  // weights summed to 1 before this update, so `total` is the cloud's mean likelihood (amcl divides
  // it by the particle count too, which makes the averages jump when the count changes).
  const double w_avg = total;
  for (Particle& p : particles_) p.w /= total;
  if (w_slow_ == 0.0)
    w_slow_ = w_avg;
  else
    w_slow_ += o_.alpha_slow * (w_avg - w_slow_);
  if (w_fast_ == 0.0)
    w_fast_ = w_avg;
  else
    w_fast_ += o_.alpha_fast * (w_avg - w_fast_);
}

// Low-variance resampling (Probabilistic Robotics, table 4.4) to `n` particles, each replaced by a
// random one with probability max(0, 1 - w_fast / w_slow) (table 8.3).
void AmclFilter::resample(std::size_t n) {
  const double p_random =
      (o_.alpha_slow > 0 && o_.alpha_fast > 0 && w_slow_ > 0) ? std::max(0.0, 1.0 - w_fast_ / w_slow_) : 0.0;
  std::vector<Particle> out;
  out.reserve(n);
  const double step = 1.0 / static_cast<double>(n);
  const double r = rng_.uniform() * step;
  double c = particles_[0].w;
  std::size_t i = 0;
  for (std::size_t m = 0; m < n; ++m) {
    const double u = r + static_cast<double>(m) * step;
    while (u > c && i + 1 < particles_.size()) c += particles_[++i].w;
    out.push_back(rng_.uniform() < p_random ? randomParticle() : particles_[i]);
  }
  for (auto& p : out) p.w = 1.0 / static_cast<double>(n);
  // amcl resets the averages after injecting random particles.
  if (p_random > 0) w_slow_ = w_fast_ = 0.0;
  particles_ = std::move(out);
}

// amcl publishes the mean of the heaviest cluster of particles, not of the whole cloud (whose mean
// the random particles and distant modes pull about). The cluster here: the heaviest bin of amcl's
// histogram (0.5 m x 0.5 m x 10 deg), grown to the particles within `kClusterRadiusM` and
// `kClusterRadiusRad` of its weighted mean (twice, re-centred).
AmclResult AmclFilter::estimate() const {
  constexpr double kBinM = 0.5, kBinRad = 10.0 * std::numbers::pi / 180.0;
  constexpr double kClusterRadiusM = 1.0, kClusterRadiusRad = 30.0 * std::numbers::pi / 180.0;
  std::unordered_map<std::int64_t, double> bins;
  bins.reserve(particles_.size());
  auto key = [&](const Particle& p) {
    const auto i = static_cast<std::int64_t>(std::floor(p.x / kBinM)) & 0xFFFFF;
    const auto j = static_cast<std::int64_t>(std::floor(p.y / kBinM)) & 0xFFFFF;
    const auto k = static_cast<std::int64_t>(std::floor((p.theta + std::numbers::pi) / kBinRad));
    return (i << 28) | (j << 8) | k;
  };
  for (const Particle& p : particles_) bins[key(p)] += p.w;
  std::int64_t best = 0;
  double best_w = -1.0;
  for (const auto& [k, w] : bins)
    if (w > best_w) best = k, best_w = w;
  // Weighted mean and spread of the particles selected by `in`.
  struct Moments {
    double w = 0, x = 0, y = 0, theta = 0, var_xy = 0, var_theta = 0;
  };
  auto moments = [&](auto&& in) {
    Moments m;
    double sx = 0, sy = 0, sc = 0, ss = 0;
    for (const Particle& p : particles_)
      if (in(p)) {
        m.w += p.w;
        sx += p.w * p.x;
        sy += p.w * p.y;
        sc += p.w * std::cos(p.theta);
        ss += p.w * std::sin(p.theta);
      }
    if (m.w <= 0) return m;
    m.x = sx / m.w;
    m.y = sy / m.w;
    m.theta = std::atan2(ss, sc);
    for (const Particle& p : particles_)
      if (in(p)) {
        m.var_xy += p.w * ((p.x - m.x) * (p.x - m.x) + (p.y - m.y) * (p.y - m.y));
        const double e = dtheta(p.theta, m.theta);
        m.var_theta += p.w * e * e;
      }
    m.var_xy /= m.w;
    m.var_theta /= m.w;
    return m;
  };
  Moments c = moments([&](const Particle& p) { return key(p) == best; });
  for (int round = 0; round < 2; ++round) {
    const Moments centre = c;
    c = moments([&](const Particle& p) {
      return std::hypot(p.x - centre.x, p.y - centre.y) <= kClusterRadiusM &&
             std::abs(dtheta(p.theta, centre.theta)) <= kClusterRadiusRad;
    });
  }
  double total = 0;
  for (const Particle& p : particles_) total += p.w;
  AmclResult r;
  r.T_world_robot = SE2(c.x, c.y, c.theta);
  r.std_m = std::sqrt(c.var_xy);
  r.std_rad = std::sqrt(c.var_theta);
  r.cluster_weight = total > 0 ? c.w / total : 0.0;
  r.converged =
      r.cluster_weight >= o_.converged_weight && r.std_m <= o_.converged_std_m && r.std_rad <= o_.converged_std_rad;
  r.particles = particles_.size();
  return r;
}

AmclResult AmclFilter::add(const Frame& frame) {
  // The odometry step since the previous frame; without odometry on both, the last step.
  SE2 step;
  const bool odom_ok = frame.T_odom_robot && frame.T_odom_robot->isFinite();
  if (odom_ok && last_odom_)
    step = last_odom_->inverse() * *frame.T_odom_robot;
  else if (step_)
    step = *step_;
  if (odom_ok && last_odom_) step_ = step;
  last_odom_ = odom_ok ? frame.T_odom_robot : std::nullopt;

  if (!first_) motion(step);
  moved_ = moved_ * step;
  const bool due =
      first_ || moved_.translation().norm() >= o_.update_min_d_m || std::abs(moved_.theta()) >= o_.update_min_a_rad;
  bool updated = false;
  if (due) {
    Points2 all;
    for (const auto& p : frame.scan.toPoints(frame.T_robot_laser))
      if (p.allFinite()) all.push_back(p);
    if (!all.empty()) {
      Points2 sub;
      const std::size_t n = std::min(o_.beams, all.size());
      sub.reserve(n);
      for (std::size_t k = 0; k < n; ++k) sub.push_back(all[k * all.size() / n]);
      measure(sub);
      updated = true;
      first_ = false;
      moved_ = SE2();
      // The count follows the cloud, as KLD sampling would: few particles around one converged pose,
      // the full set while it is spread out.
      const std::size_t target = estimate().converged ? o_.tracking_particles : o_.global_particles;
      if (++measurements_ >= o_.resample_interval || target != particles_.size()) {
        resample(target);
        measurements_ = 0;
      }
    }
  }
  AmclResult r = estimate();
  r.updated = updated;
  return r;
}

}  // namespace lidar2d::bench
