#include "lidar2d/core/laser_scan.hpp"

#include <cmath>
#include <numbers>
#include <string>

#include "lidar2d/core/error.hpp"

namespace lidar2d {

LaserScan LaserScan::create(LaserScanFields fields) {
  auto fail = [](const std::string& field, const std::string& msg) {
    return badInput(msg, ErrorLocation("", 0, field));
  };
  if (fields.ranges.empty()) throw fail("ranges", "scan has no beams");
  if (fields.ranges.size() > kMaxBeams)
    throw fail("ranges", "scan has " + std::to_string(fields.ranges.size()) + " beams, more than the limit of " +
                             std::to_string(kMaxBeams));
  if (!std::isfinite(fields.time)) throw fail("time", "timestamp is not finite");
  if (!std::isfinite(fields.angle_min)) throw fail("angle_min", "not finite");
  if (!std::isfinite(fields.angle_increment) || fields.angle_increment == 0.0)
    throw fail("angle_increment", "must be finite and non-zero");
  const double span = std::abs(fields.angle_increment) * static_cast<double>(fields.ranges.size() - 1);
  if (span > 2.0 * std::numbers::pi + std::abs(fields.angle_increment) + 1e-9)
    throw fail("angle_increment", "beams span " + std::to_string(span) + " rad, more than a full turn");
  if (!std::isfinite(fields.range_min) || fields.range_min < 0.0) throw fail("range_min", "must be finite and >= 0");
  if (!std::isfinite(fields.range_max) || fields.range_max <= fields.range_min)
    throw fail("range_max", "must be finite and greater than range_min");
  if (!fields.intensities.empty() && fields.intensities.size() != fields.ranges.size())
    throw fail("intensities", "has " + std::to_string(fields.intensities.size()) + " values for " +
                                  std::to_string(fields.ranges.size()) + " beams");
  LaserScan scan;
  scan.f_ = std::move(fields);
  scan.valid_.resize(scan.f_.ranges.size());
  for (std::size_t i = 0; i < scan.f_.ranges.size(); ++i) {
    const double r = scan.f_.ranges[i];
    const bool ok = std::isfinite(r) && r > scan.f_.range_min && r < scan.f_.range_max;
    scan.valid_[i] = ok ? 1 : 0;
    scan.num_valid_ += ok ? 1 : 0;
  }
  return scan;
}

double LaserScan::fieldOfView() const {
  return std::abs(f_.angle_increment) * static_cast<double>(size());
}

Points2 LaserScan::toPoints() const {
  Points2 pts;
  pts.reserve(num_valid_);
  for (std::size_t i = 0; i < size(); ++i) {
    if (!valid_[i]) continue;
    const double a = angle(i);
    pts.emplace_back(f_.ranges[i] * std::cos(a), f_.ranges[i] * std::sin(a));
  }
  return pts;
}

Points2 LaserScan::toPoints(const SE2& T_robot_laser) const {
  Points2 pts = toPoints();
  for (auto& p : pts) p = T_robot_laser * p;
  return pts;
}

std::vector<std::size_t> LaserScan::validIndices() const {
  std::vector<std::size_t> idx;
  idx.reserve(num_valid_);
  for (std::size_t i = 0; i < size(); ++i)
    if (valid_[i]) idx.push_back(i);
  return idx;
}

}  // namespace lidar2d
