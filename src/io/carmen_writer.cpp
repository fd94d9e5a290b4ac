// CARMEN text-log writer. Line layouts are those read by carmen_messages.cpp:
//   ROBOTLASER1 laser_type start_angle field_of_view angular_resolution maximum_range accuracy
//       remission_mode n r1..rn m e1..em laser_x laser_y laser_theta robot_x robot_y robot_theta
//       tv rv forward_safety_dist side_safety_dist turn_axis timestamp host logger_timestamp
//   ODOM x y theta tv rv accel timestamp host logger_timestamp
//   TRUEPOS true_x true_y true_theta odom_x odom_y odom_theta timestamp host logger_timestamp
// Times, angles and poses are written in the shortest form that reads back to the same double;
// ranges with 0.1 mm resolution (enough for any scanner, and compact).

#include "lidar2d/io/carmen_writer.hpp"

#include <fmt/format.h>

#include <cmath>
#include <iterator>
#include <string>

#include "lidar2d/core/error.hpp"
#include "lidar2d/io/atomic_file.hpp"
#include "src/io/internal/carmen_format.hpp"

namespace lidar2d::io {
namespace {

// Appends a range with 4 decimals, trailing zeros dropped ("1.5", "81.91", "2").
void appendRange(std::string& out, double r, bool valid, double range_max) {
  char buf[64];
  auto res = fmt::format_to_n(buf, sizeof buf - 1, "{:.4f}", r);
  std::size_t n = res.size < sizeof buf ? res.size : sizeof buf - 1;
  std::string_view s(buf, n);
  if (s.find('.') != std::string_view::npos) {
    while (!s.empty() && s.back() == '0') s.remove_suffix(1);
    if (!s.empty() && s.back() == '.') s.remove_suffix(1);
  }
  double back = 0.0;
  // A valid beam must stay valid (strictly inside (0, range_max)) after rounding: write it exactly.
  if (valid) {
    back = std::stod(std::string(s));
    if (!(back > 0.0 && back < range_max)) {
      fmt::format_to(std::back_inserter(out), " {}", r);
      return;
    }
  }
  out.push_back(' ');
  out.append(s);
}

}  // namespace

struct CarmenWriter::Impl {
  explicit Impl(const std::string& path) : file(path) {}
  AtomicFile file;
  std::string line;
};

CarmenWriter::CarmenWriter(const std::string& path) : impl_(std::make_unique<Impl>(path)) {
  auto& o = impl_->file.stream();
  o << internal::kCarmenWriterMarker << " (written by lidar2d)\n";
  o << "# ROBOTLASER1 robot pose = odometry, only for scans followed by an ODOM line; TRUEPOS = truth\n";
  o << "# message formats: ROBOTLASER1 laser_type start_angle field_of_view angular_resolution maximum_range "
       "accuracy remission_mode num_readings [ranges] num_remissions [remissions] laser_pose_x laser_pose_y "
       "laser_pose_theta robot_pose_x robot_pose_y robot_pose_theta laser_tv laser_rv forward_safety_dist "
       "side_safty_dist turn_axis timestamp host logger_timestamp\n";
  o << "# ODOM x y theta tv rv accel timestamp host logger_timestamp\n";
  o << "# TRUEPOS true_x true_y true_theta odom_x odom_y odom_theta timestamp host logger_timestamp\n";
}

CarmenWriter::~CarmenWriter() = default;

void CarmenWriter::comment(const std::string& text) {
  // One "# " line per line of text, so that a newline in the text cannot start a message line.
  std::size_t start = 0;
  auto& o = impl_->file.stream();
  for (;;) {
    const std::size_t nl = text.find('\n', start);
    o << "# " << text.substr(start, nl == std::string::npos ? std::string::npos : nl - start) << "\n";
    if (nl == std::string::npos) break;
    start = nl + 1;
  }
}

void CarmenWriter::write(const Frame& frame) {
  const LaserScan& scan = frame.scan;
  if (scan.empty()) throw invalidArgument("CarmenWriter: frame has no scan", {impl_->file.path()});
  // CARMEN readers (ours included) reject NaN/inf times and poses, so never write them.
  if (!std::isfinite(frame.time)) throw invalidArgument("CarmenWriter: frame time is not finite", {impl_->file.path()});
  if ((frame.T_odom_robot && !frame.T_odom_robot->isFinite()) ||
      (frame.T_world_robot && !frame.T_world_robot->isFinite()) || !frame.T_robot_laser.isFinite())
    throw invalidArgument("CarmenWriter: frame pose is not finite", {impl_->file.path()});
  std::string& l = impl_->line;
  l.clear();
  auto out = std::back_inserter(l);
  const double rmax = scan.rangeMax();
  const double t = frame.time;
  const std::size_t n = scan.size();
  const double fov = static_cast<double>(n) * std::abs(scan.angleIncrement());
  // laser_type 0 (unknown to CARMEN's enum, as in converted logs), accuracy 0, remission_mode 0.
  fmt::format_to(out, "ROBOTLASER1 0 {} {} {} {} 0 0 {}", scan.angleMin(), fov, scan.angleIncrement(), rmax, n);
  for (std::size_t i = 0; i < n; ++i) {
    const double r = scan.ranges()[i];
    const bool valid = scan.isValid(i);
    // CARMEN has one "no return" value, range_max; an error reading (a lost echo: 0, below
    // range_min, NaN) is written as 0, which reads back invalid too but is not "nothing there":
    // mapping clears along no-return beams only (docs/mapping.md).
    appendRange(l, valid ? r : (r >= rmax ? rmax : 0.0), valid, rmax);
  }
  fmt::format_to(out, " {}", scan.intensities().size());
  for (double e : scan.intensities()) fmt::format_to(out, " {}", std::isfinite(e) ? e : 0.0);
  const SE2 T_odom_robot = frame.T_odom_robot.value_or(SE2());
  const SE2 T_odom_laser = T_odom_robot * frame.T_robot_laser;
  const char* host = internal::kCarmenWriterHost;
  fmt::format_to(out, " {} {} {} {} {} {} 0 0 0 0 0 {} {} {}\n", T_odom_laser.x(), T_odom_laser.y(),
                 T_odom_laser.theta(), T_odom_robot.x(), T_odom_robot.y(), T_odom_robot.theta(), t, host, t);
  if (frame.T_odom_robot) {
    const SE2& o = *frame.T_odom_robot;
    fmt::format_to(out, "ODOM {} {} {} 0 0 0 {} {} {}\n", o.x(), o.y(), o.theta(), t, host, t);
  }
  if (frame.T_world_robot) {
    const SE2& w = *frame.T_world_robot;
    const SE2 o = frame.T_odom_robot.value_or(w);
    fmt::format_to(out, "TRUEPOS {} {} {} {} {} {} {} {} {}\n", w.x(), w.y(), w.theta(), o.x(), o.y(), o.theta(), t,
                   host, t);
  }
  impl_->file.stream().write(l.data(), static_cast<std::streamsize>(l.size()));
}

void CarmenWriter::commit() { impl_->file.commit(); }

}  // namespace lidar2d::io
