#include "lidar2d/localization/lines.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <numbers>

#include "lidar2d/core/error.hpp"
#include "lidar2d/core/se2.hpp"
#include "lidar2d/geometry/line_fit.hpp"

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

std::vector<Line> extractLines(const Points2& points, const LineExtractionOptions& options) {
  options.validate();
  Points2 pts;
  pts.reserve(points.size());
  for (const auto& p : points)
    if (p.allFinite()) pts.push_back(p);
  std::vector<Line> lines;
  if (pts.size() < options.min_points) return lines;

  // 1. Runs of consecutive points closer than max_gap; 2. each run split at its farthest point from
  // the chord (Douglas-Peucker) and every piece refitted by total least squares.
  geometry::LineSplitOptions split;
  split.rule = geometry::SplitRule::kChordDistance;
  split.threshold_m = options.split_threshold_m;
  split.min_points = options.min_points;
  split.fit = {geometry::LineNormal::kPrincipalAngle, geometry::LineResidual::kFromPoints,
               geometry::LineEnds::kFirstAndLast, /*normal_from_origin=*/true};
  std::vector<geometry::LinePiece> pieces;
  std::size_t run_start = 0;
  for (std::size_t i = 1; i <= pts.size(); ++i) {
    if (i == pts.size() || (pts[i] - pts[i - 1]).norm() > options.max_gap_m) {
      if (i - 1 > run_start) geometry::splitIntoLines(pts, run_start, i, split, &pieces);
      run_start = i;
    }
  }

  // 3. Keep the long, straight pieces (the normal of a piece on one spot is arbitrary).
  std::vector<Line> raw;
  for (const geometry::LinePiece& piece : pieces) {
    const geometry::LineFit& fit = piece.fit;
    if (piece.kind != geometry::LinePiece::Kind::kLine || fit.scatter_m2 <= 1e-12 || fit.rms_m > options.max_rms_m)
      continue;
    if (fit.offset_m < options.min_distance_m) continue;
    const double length = std::abs(fit.direction.dot(fit.b - fit.a));
    if (length < options.min_length_m) continue;
    Line l;
    l.normal_angle = std::atan2(fit.normal.y(), fit.normal.x());
    l.distance = fit.offset_m;
    l.length = length;
    l.a = fit.a;
    l.b = fit.b;
    l.num_points = fit.num_points;
    l.rms_m = fit.rms_m;
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
