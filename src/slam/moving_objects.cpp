#include "src/slam/internal/moving_objects.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <optional>
#include <utility>

#include "src/geometry/kdtree2.hpp"
#include "src/slam/internal/points.hpp"

namespace lidar2d::slam::internal {

std::optional<MovingObjectFilter::View> MovingObjectFilter::inView(const Past& base, const Eigen::Vector2d& p_base,
                                                                   double heading_rad) const {
  const Eigen::Vector2d q = base.T_robot_laser.inverse() * p_base;
  View v;
  v.range_m = q.norm();
  const LaserScan& s = base.scan;
  if (!(v.range_m > kThroughMarginM) || !(v.range_m < std::min(s.rangeMax(), opt_.max_range_m) - kThroughMarginM))
    return std::nullopt;
  // The beam index of its bearing (fractional, counted from the first beam the way the beams turn),
  // and the beams within the odometry's heading error (or kThroughAcrossM across at this range) of
  // it; beyond either end of the field of view nothing was seen.
  const double half = std::max(heading_rad, std::atan2(kThroughAcrossM, v.range_m));
  const double inc = s.angleIncrement();
  const double two_pi = 2.0 * std::numbers::pi;
  double rel = std::remainder(std::atan2(q.y(), q.x()) - s.angleMin(), two_pi);
  if (rel / inc < 0.0) rel += inc > 0.0 ? two_pi : -two_pi;
  const double c = rel / inc, w = half / std::abs(inc);
  const long long lo = std::llround(c - w), hi = std::llround(c + w);
  if (lo < 0 || hi >= static_cast<long long>(s.size())) return std::nullopt;
  v.first_beam = static_cast<std::size_t>(lo);
  v.last_beam = static_cast<std::size_t>(hi);
  return v;
}

bool MovingObjectFilter::seenThrough(const Past& base, const Eigen::Vector2d& p_base, double heading_rad) const {
  const std::optional<View> v = inView(base, p_base, heading_rad);
  if (!v) return false;
  const LaserScan& s = base.scan;
  for (std::size_t i = v->first_beam; i <= v->last_beam; ++i) {
    const double ri = s.ranges()[i];
    const bool no_return = ri >= s.rangeMax();
    if (!(no_return || (s.isValid(i) && ri > v->range_m + kThroughMarginM))) return false;
  }
  return true;
}

std::size_t MovingObjectFilter::filter(const Frame& f, Frame& out) {
  // Across a gap in the log, or time going backwards, the odometry may not know where the robot
  // went (a robot carried), and everything would seem to have moved: the comparison starts again.
  const bool gap = last_time_ && !(f.time - *last_time_ >= 0.0 && f.time - *last_time_ <= opt_.time_gap_s);
  last_time_ = f.time;
  const bool odometry = opt_.use_odometry && f.T_odom_robot && f.T_odom_robot->isFinite();
  if (!odometry || gap) past_.clear();
  if (!odometry) return 0;
  const LaserScan& scan = f.scan;
  std::vector<std::size_t> beams;
  Points2 pts = scanPoints(f, opt_.max_range_m, &beams);
  const SE2 T_odom = *f.T_odom_robot;
  // The baseline: the latest earlier scan at least kBaselineM behind by the odometry (the oldest
  // kept; those before it are dropped as soon as a later one qualifies).
  auto behind = [&](const Past& p) { return (p.T_odom_robot.translation() - T_odom.translation()).norm(); };
  while (past_.size() >= 2 && behind(past_[1]) >= kBaselineM) past_.pop_front();
  std::vector<std::size_t> drop;
  const auto usable = [&](const Past& p) {
    const double d = behind(p);
    return d >= kBaselineM && d <= kMaxBaselineM &&
           std::abs((p.T_odom_robot.inverse() * T_odom).theta()) <= kMaxTurnRad;
  };
  if (!past_.empty() && usable(past_.front()) && !pts.empty()) {
    const Past& base = past_.front();
    const geometry::KdTree2 tree(base.points);
    const auto near = [&](const Eigen::Vector2d& p, double d) {
      double d2 = 0.0;
      return tree.nearest(p, &d2) < base.points.size() && d2 <= d * d;
    };
    // Where a standing object at p (this robot frame) lay in the baseline's robot frame.
    const SE2 T_base_now = base.T_odom_robot.inverse() * T_odom;
    // What the odometry's heading may be off by over the baseline.
    const double heading_rad = kHeadingRad + kHeadingRadPerM * T_base_now.translation().norm() +
                               kHeadingPerTurn * std::abs(T_base_now.theta());
    const double step = std::abs(scan.angleIncrement());
    std::size_t first = 0;
    for (std::size_t k = 1; k <= pts.size(); ++k) {
      // Across beams that read nothing usable too (a dark patch of a wall is no object's end), by
      // the angle between the two returns; not across a beam that went out to its range max (free
      // space between them).
      bool cut = k == pts.size();
      if (!cut) {
        for (std::size_t b = beams[k - 1] + 1; b < beams[k] && !cut; ++b) cut = scan.ranges()[b] >= scan.rangeMax();
        const double spacings = kGapBeams * step * static_cast<double>(beams[k] - beams[k - 1]);
        cut = cut || (pts[k] - pts[k - 1]).norm() > kGapM + spacings * scan.ranges()[beams[k]];
      }
      if (!cut) continue;
      // Object [first, k): its extent, whether it stayed in the robot's frame, where it would be.
      Eigen::Vector2d lo = pts[first], hi = pts[first], sum = Eigen::Vector2d::Zero();
      for (std::size_t j = first; j < k; ++j) {
        lo = lo.cwiseMin(pts[j]);
        hi = hi.cwiseMax(pts[j]);
        sum += pts[j];
      }
      const std::size_t n = k - first;
      const Eigen::Vector2d centre = sum / static_cast<double>(n);
      // Cut off by the field of view's ends, or by a nearer object in front of either end: how far
      // it goes on is unknown (a wall's stretch seen between two pillars is no small object).
      const auto occluded = [&](std::size_t beam, const Eigen::Vector2d& end) {
        return scan.isValid(beam) && scan.ranges()[beam] < end.norm() - kGapM;
      };
      const bool cut_off = beams[first] == 0 || beams[k - 1] + 1 == scan.size() ||
                           occluded(beams[first] - 1, pts[first]) || occluded(beams[k - 1] + 1, pts[k - 1]);
      // Where a standing object would be is known to within kStaticM plus the heading error's arc.
      const double static_m = kStaticM + heading_rad * centre.norm();
      if ((hi - lo).norm() <= kMaxObjectM && n >= kMinReturns && !cut_off &&
          (T_base_now * centre - centre).norm() >= static_m + kSameM) {
        std::size_t same = 0, standing = 0, through = 0;
        for (std::size_t j = first; j < k; ++j) {
          const Eigen::Vector2d at_base = T_base_now * pts[j];
          if (near(pts[j], kSameM)) ++same;
          if (near(at_base, static_m)) ++standing;
          if (seenThrough(base, at_base, heading_rad)) ++through;
        }
        // Where it would stand, that scan could have seen it (in its range and field of view): a
        // standing object coming into range matches something else there as often as not.
        const bool with_robot = 4 * same >= 3 * n && inView(base, T_base_now * centre, heading_rad).has_value();
        // Only an object kMinWalkerM across or more walks in: a thin edge (a door frame, a table
        // leg) misplaced by the odometry read a little late seems to stand where that scan saw past
        // it.
        const bool walked_in = 2 * through > n && (hi - lo).norm() >= kMinWalkerM;
        if (2 * standing < n && (with_robot || walked_in))
          for (std::size_t j = first; j < k; ++j) drop.push_back(beams[j]);
      }
      first = k;
    }
  }
  // One kept scan per kBaselineM / 10 of motion: the baseline lies 0.5-0.55 m behind, and a robot
  // standing still keeps one scan, not every scan it takes.
  if (past_.empty() || behind(past_.back()) >= 0.1 * kBaselineM)
    past_.push_back({T_odom, std::move(pts), f.scan, f.T_robot_laser});
  // A robot going to and fro within the baseline would keep every scan: the oldest go.
  while (past_.size() > kMaxKept) past_.pop_front();
  if (drop.empty()) return 0;
  LaserScanFields fields = scan.fields();
  for (const std::size_t i : drop) fields.ranges[i] = std::numeric_limits<double>::quiet_NaN();
  out = f;
  out.scan = LaserScan::create(std::move(fields));
  return drop.size();
}

}  // namespace lidar2d::slam::internal
