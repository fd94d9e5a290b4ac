#include "lidar2d/degeneracy/ground_truth.hpp"

#include <cmath>
#include <numbers>
#include <vector>

namespace lidar2d::degeneracy {

TruthLabel labelFromWorld(const sim::World& world, const SE2& T_world_robot, const sim::LaserModel& laser,
                          const TruthOptions& options) {
  const SE2 T_world_laser = T_world_robot * laser.T_robot_laser;
  const Eigen::Vector2d origin = T_world_laser.translation();
  const auto& segs = world.segments();
  const auto& arcs = world.arcs();
  std::vector<std::size_t> hits(segs.size() + arcs.size(), 0);
  TruthLabel label;
  for (int i = 0; i < laser.beams; ++i) {
    const double a = T_world_laser.theta() + laser.angleMin() + i * laser.angleIncrement();
    const Eigen::Vector2d dir(std::cos(a), std::sin(a));
    double best = laser.range_max_m;
    std::size_t which = hits.size();
    for (std::size_t k = 0; k < segs.size(); ++k) {
      const double t = sim::intersectSegment(segs[k], origin, dir);
      if (t < best) {
        best = t;
        which = k;
      }
    }
    for (std::size_t k = 0; k < arcs.size(); ++k) {
      const double t = sim::intersectArc(arcs[k], origin, dir);
      if (t < best) {
        best = t;
        which = segs.size() + k;
      }
    }
    // The simulator reads range_max as "no return" and ranges <= range_min as invalid.
    if (which < hits.size() && best > laser.range_min_m) {
      ++hits[which];
      ++label.hits;
    }
  }
  label.enough_hits = label.hits >= options.min_hits;
  bool all_parallel = true;
  bool have_ref = false;
  double ref = 0.0;
  const double tol = options.parallel_tol_deg * std::numbers::pi / 180.0;
  for (std::size_t k = 0; k < hits.size(); ++k) {
    if (hits[k] < options.min_hits_visible) continue;
    ++label.visible;
    if (k >= segs.size()) {
      all_parallel = false;
      continue;
    }
    const Eigen::Vector2d d = segs[k].b - segs[k].a;
    const double ang = std::atan2(d.y(), d.x());
    if (!have_ref) {
      ref = ang;
      have_ref = true;
    } else if (std::abs(0.5 * wrapAngle(2.0 * (ang - ref))) > tol) {
      all_parallel = false;
    }
  }
  label.degenerate = have_ref && all_parallel;
  if (label.degenerate) label.direction_rad = 0.5 * wrapAngle(2.0 * (ref - T_world_robot.theta()));
  return label;
}

}  // namespace lidar2d::degeneracy
