#include "lidar2d/localization/lines.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <numbers>

#include "lidar2d/core/error.hpp"
#include "lidar2d/core/se2.hpp"

namespace lidar2d::localization {

void LineExtractionOptions::validate() const {
  auto bad = [](const char* field, double v) {
    return invalidArgument(fmt::format("line extraction option {} = {} is out of its domain", field, v),
                           ErrorLocation({}, 0, field));
  };
  if (!(split_threshold_m > 0) || !std::isfinite(split_threshold_m)) throw bad("split_threshold_m", split_threshold_m);
  if (!(max_gap_m > 0) || !std::isfinite(max_gap_m)) throw bad("max_gap_m", max_gap_m);
  if (min_points < 2) throw bad("min_points", static_cast<double>(min_points));
  if (!(min_length_m >= 0) || !std::isfinite(min_length_m)) throw bad("min_length_m", min_length_m);
  if (!(max_rms_m > 0) || !std::isfinite(max_rms_m)) throw bad("max_rms_m", max_rms_m);
  if (!(min_distance_m >= 0) || !std::isfinite(min_distance_m)) throw bad("min_distance_m", min_distance_m);
  if (!(merge_angle_rad >= 0) || !std::isfinite(merge_angle_rad)) throw bad("merge_angle_rad", merge_angle_rad);
  if (!(merge_distance_m >= 0) || !std::isfinite(merge_distance_m)) throw bad("merge_distance_m", merge_distance_m);
}

Eigen::Vector2d Line::foot() const {
  return distance * Eigen::Vector2d(std::cos(normal_angle), std::sin(normal_angle));
}

namespace {

// Total least-squares line through pts[first, last]: returns false when degenerate.
struct Fit {
  Eigen::Vector2d normal;
  double c = 0;  // n . p = c
  double rms = 0;
};

bool fitLine(const Points2& pts, std::size_t first, std::size_t last, Fit* fit) {
  const std::size_t n = last - first + 1;
  Eigen::Vector2d mean = Eigen::Vector2d::Zero();
  for (std::size_t i = first; i <= last; ++i) mean += pts[i];
  mean /= static_cast<double>(n);
  double sxx = 0, sxy = 0, syy = 0;
  for (std::size_t i = first; i <= last; ++i) {
    const Eigen::Vector2d d = pts[i] - mean;
    sxx += d.x() * d.x();
    sxy += d.x() * d.y();
    syy += d.y() * d.y();
  }
  // Direction of the principal axis; the normal is perpendicular to it.
  const double angle = 0.5 * std::atan2(2.0 * sxy, sxx - syy);
  const Eigen::Vector2d dir(std::cos(angle), std::sin(angle));
  if (sxx + syy <= 1e-12) return false;
  fit->normal = Eigen::Vector2d(-dir.y(), dir.x());
  fit->c = fit->normal.dot(mean);
  double ss = 0;
  for (std::size_t i = first; i <= last; ++i) {
    const double r = fit->normal.dot(pts[i]) - fit->c;
    ss += r * r;
  }
  fit->rms = std::sqrt(ss / static_cast<double>(n));
  return true;
}

// Recursive split of pts[first, last] (iterative with a stack): segments whose points all lie within
// the threshold of their chord.
void split(const Points2& pts, std::size_t first, std::size_t last, double threshold,
           std::vector<std::pair<std::size_t, std::size_t>>* out) {
  std::vector<std::pair<std::size_t, std::size_t>> stack{{first, last}};
  while (!stack.empty()) {
    const auto [a, b] = stack.back();
    stack.pop_back();
    if (b <= a + 1) {
      out->push_back({a, b});
      continue;
    }
    const Eigen::Vector2d chord = pts[b] - pts[a];
    const double len = chord.norm();
    std::size_t worst = a;
    double worst_d = 0;
    for (std::size_t i = a + 1; i < b; ++i) {
      const Eigen::Vector2d v = pts[i] - pts[a];
      const double d = len > 1e-9 ? std::abs(chord.x() * v.y() - chord.y() * v.x()) / len : v.norm();
      if (d > worst_d) {
        worst_d = d;
        worst = i;
      }
    }
    if (worst_d > threshold) {
      // Right part pushed first so that segments come out in scan order.
      stack.push_back({worst, b});
      stack.push_back({a, worst});
    } else {
      out->push_back({a, b});
    }
  }
}

}  // namespace

std::vector<Line> extractLines(const Points2& points, const LineExtractionOptions& options) {
  options.validate();
  Points2 pts;
  pts.reserve(points.size());
  for (const auto& p : points)
    if (p.allFinite()) pts.push_back(p);
  std::vector<Line> lines;
  if (pts.size() < options.min_points) return lines;

  // 1. Runs of consecutive points closer than max_gap; 2. split each run at its farthest point.
  std::vector<std::pair<std::size_t, std::size_t>> segments;
  std::size_t run_start = 0;
  for (std::size_t i = 1; i <= pts.size(); ++i) {
    if (i == pts.size() || (pts[i] - pts[i - 1]).norm() > options.max_gap_m) {
      if (i - 1 > run_start) split(pts, run_start, i - 1, options.split_threshold_m, &segments);
      run_start = i;
    }
  }

  // 3. Refit each segment by total least squares; keep the long, straight ones.
  std::vector<Line> raw;
  for (const auto& [a, b] : segments) {
    if (b - a + 1 < options.min_points) continue;
    Fit fit;
    if (!fitLine(pts, a, b, &fit) || fit.rms > options.max_rms_m) continue;
    Eigen::Vector2d n = fit.normal;
    double c = fit.c;
    if (c < 0) {
      n = -n;
      c = -c;
    }
    if (c < options.min_distance_m) continue;
    const Eigen::Vector2d dir(-n.y(), n.x());
    const Eigen::Vector2d pa = pts[a] - (n.dot(pts[a]) - c) * n;
    const Eigen::Vector2d pb = pts[b] - (n.dot(pts[b]) - c) * n;
    const double length = std::abs(dir.dot(pb - pa));
    if (length < options.min_length_m) continue;
    Line l;
    l.normal_angle = std::atan2(n.y(), n.x());
    l.distance = c;
    l.length = length;
    l.a = pa;
    l.b = pb;
    l.num_points = b - a + 1;
    l.rms_m = fit.rms;
    raw.push_back(l);
  }

  // 4. Merge segments of the same infinite line (a wall interrupted by an obstacle or a gap): the
  // longest keeps its parameters (length-weighted average of phi and d), lengths add up.
  std::sort(raw.begin(), raw.end(), [](const Line& x, const Line& y) { return x.length > y.length; });
  for (const Line& l : raw) {
    bool merged = false;
    for (Line& m : lines) {
      if (std::abs(angleDiff(l.normal_angle, m.normal_angle)) <= options.merge_angle_rad &&
          std::abs(l.distance - m.distance) <= options.merge_distance_m) {
        const double w = l.length / (l.length + m.length);
        m.normal_angle = wrapAngle(m.normal_angle + w * angleDiff(l.normal_angle, m.normal_angle));
        m.distance += w * (l.distance - m.distance);
        m.rms_m = std::sqrt((m.rms_m * m.rms_m * static_cast<double>(m.num_points) +
                             l.rms_m * l.rms_m * static_cast<double>(l.num_points)) /
                            static_cast<double>(m.num_points + l.num_points));
        m.length += l.length;
        m.num_points += l.num_points;
        merged = true;
        break;
      }
    }
    if (!merged) lines.push_back(l);
  }
  std::sort(lines.begin(), lines.end(), [](const Line& x, const Line& y) { return x.length > y.length; });
  return lines;
}

}  // namespace lidar2d::localization
