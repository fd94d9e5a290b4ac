// CARMEN text-log messages (.log / .clf, plain or gzip-compressed): the lines of a log parsed into
// events for carmen_reader.cpp.
//
// Message layouts (CARMEN 0.7 logger, carmen/src/logger/writelog.c, and the Radish logs):
//   FLASER n r1..rn x y theta odom_x odom_y odom_theta ipc_timestamp host logger_timestamp
//   RLASER  (same as FLASER, rear laser)
//   ROBOTLASER1|2 laser_type start_angle field_of_view angular_resolution maximum_range accuracy
//       remission_mode n r1..rn m e1..em laser_x laser_y laser_theta robot_x robot_y robot_theta
//       tv rv forward_safety_dist side_safety_dist turn_axis ipc_timestamp host logger_timestamp
//   RAWLASER1..4 laser_type start_angle field_of_view angular_resolution maximum_range accuracy
//       remission_mode n r1..rn m e1..em ipc_timestamp host logger_timestamp
//   ODOM x y theta tv rv accel ipc_timestamp host logger_timestamp
//   TRUEPOS true_x true_y true_theta odom_x odom_y odom_theta ipc_timestamp host logger_timestamp
//   PARAM name value [ipc_timestamp host logger_timestamp]
// Lines starting with '#' are comments; any other message (NEFF, SYNC, ...) is skipped. Fields
// after ipc_timestamp (host, logger_timestamp) are optional here: some converters drop them.
//
// Rules chosen here (documented for users in frame_source.hpp and in notes()):
// - Beam angles of FLASER/RLASER: beam i at -90 deg + i*d, d = 180/n (n even) or 180/(n-1)
//   (n odd), i.e. the SICK LMS's 1 and 0.5 degree modes; PARAM laser_{front,rear}_laser_resolution
//   [deg] and/or laser_{front,rear}_laser_fov [deg] override (beams centred on the x axis).
// - range_max of FLASER/RLASER (which have no max-range field): 80 m, the SICK LMS's specified
//   maximum range. Its "no return" codes (81.91 m in mit-csail and freiburg-079, 81.83 m in intel)
//   lie above and become invalid, while the longest real returns in the Radish logs (about 51 m in
//   infinite-corridor) stay valid. PARAM robot_{front,rear}_laser_max or
//   laser_{front,rear}_laser_max_range overrides.
// - Mounting: FLASER at (robot_frontlaser_offset, robot_frontlaser_side_offset,
//   robot_frontlaser_angular_offset); RLASER at the rear equivalents, turned by pi (mounted
//   backwards). ROBOTLASER: T_robot_laser = robot_pose^-1 * laser_pose. RAWLASER1 uses the front
//   mounting, RAWLASER2 the rear one, RAWLASER3/4 identity.
// - FLASER/RLASER's x y theta is the laser's pose, odom_x odom_y odom_theta the robot's odometry
//   (writelog.c writes laser_pose, then robot_pose); the robot's pose is x y theta * T_robot_laser^-1.
//   Radish's corrected logs write one corrected pose, the laser's, into both triples
//   (docs/file-formats.md, CARMEN poses).

#include "src/io/internal/carmen_messages.hpp"

#include <zlib.h>

#include <algorithm>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fmt/format.h>
#include <numbers>

#include "lidar2d/core/error.hpp"
#include "src/io/internal/carmen_format.hpp"
#include "src/io/internal/text_lines.hpp"

namespace lidar2d::io::internal::carmen {
namespace {

constexpr double kDefaultRangeMax = 80.0;          // [m] SICK LMS specified maximum range

double deg2rad(double d) { return d * std::numbers::pi / 180.0; }

constexpr LaserType kLaserTypes[] = {
    {"FLASER", LaserKind::kFront, 1},      {"RLASER", LaserKind::kRear, 2},
    {"ROBOTLASER1", LaserKind::kRobot, 1}, {"ROBOTLASER2", LaserKind::kRobot, 2},
    {"RAWLASER1", LaserKind::kRaw, 1},     {"RAWLASER2", LaserKind::kRaw, 2},
    {"RAWLASER3", LaserKind::kRaw, 3},     {"RAWLASER4", LaserKind::kRaw, 4},
};

}  // namespace

const LaserType* laserType(std::string_view tag) {
  for (const auto& t : kLaserTypes)
    if (t.name == tag) return &t;
  return nullptr;
}

namespace {

// Splits a line at blanks into `out` (reused to avoid allocations).
void split(std::string_view line, std::vector<std::string_view>& out) {
  out.clear();
  std::size_t i = 0;
  const std::size_t n = line.size();
  while (i < n) {
    while (i < n && (line[i] == ' ' || line[i] == '\t' || line[i] == '\f' || line[i] == '\v' || line[i] == '\r')) ++i;
    if (i >= n) break;
    const std::size_t s = i;
    while (i < n && !(line[i] == ' ' || line[i] == '\t' || line[i] == '\f' || line[i] == '\v' || line[i] == '\r')) ++i;
    out.emplace_back(line.data() + s, i - s);
  }
}

bool parseDouble(std::string_view tok, double& v) {
  const char* b = tok.data();
  const char* e = b + tok.size();
  if (b != e && *b == '+') ++b;  // from_chars rejects a leading '+', strtod accepts it
  if (b == e) return false;
  const auto r = std::from_chars(b, e, v);
  return r.ec == std::errc() && r.ptr == e;
}

std::string quoted(std::string_view tok) {
  constexpr std::size_t kShown = 40;
  if (tok.size() <= kShown) return fmt::format("'{}'", tok);
  return fmt::format("'{}...'", tok.substr(0, kShown));
}

// Parses the fields of one line; every error names the file, line and field.
class LineParser {
 public:
  LineParser(const std::string& path, std::size_t line, const std::vector<std::string_view>& f)
      : path_(path), line_(line), f_(f) {}

  [[noreturn]] void fail(const std::string& field, const std::string& msg) const {
    throw badInput(msg, {path_, line_, field});
  }
  ErrorLocation where(const std::string& field = {}) const { return {path_, line_, field}; }

  void need(std::size_t i, const char* field) const {
    if (i >= f_.size())
      fail(fmt::format("{} {}", f_[0], field),
           fmt::format("missing field (the line ends after {} fields)", f_.size()));
  }
  // Any number (may be non-finite).
  double anyNumber(std::size_t i, const char* field) const {
    need(i, field);
    double v;
    if (!parseDouble(f_[i], v)) fail(fmt::format("{} {}", f_[0], field), fmt::format("{} is not a number", quoted(f_[i])));
    return v;
  }
  double finite(std::size_t i, const char* field) const {
    const double v = anyNumber(i, field);
    if (!std::isfinite(v)) fail(fmt::format("{} {}", f_[0], field), fmt::format("{} is not finite", quoted(f_[i])));
    return v;
  }
  SE2 pose(std::size_t i, const char* x, const char* y, const char* theta) const {
    const double px = finite(i, x), py = finite(i + 1, y), pt = finite(i + 2, theta);
    return {px, py, pt};
  }
  // A count of following values, checked against the fields that remain on the line before
  // anything is allocated. `after` = fields that must still follow the counted values.
  std::size_t count(std::size_t i, const char* field, std::size_t after) const {
    need(i, field);
    const std::string name = fmt::format("{} {}", f_[0], field);
    double v;
    if (!parseDouble(f_[i], v)) fail(name, fmt::format("{} is not a number", quoted(f_[i])));
    if (!std::isfinite(v) || v != std::floor(v)) fail(name, fmt::format("{} is not a whole number", quoted(f_[i])));
    if (v < 0) fail(name, fmt::format("negative count {}", f_[i]));
    if (v > static_cast<double>(LaserScan::kMaxBeams))
      fail(name, fmt::format("{} values is more than the limit of {}", f_[i], LaserScan::kMaxBeams));
    const auto n = static_cast<std::size_t>(v);
    const std::size_t remaining = f_.size() - i - 1;
    if (n + after > remaining)
      fail(name, fmt::format("announces {} values but the line has only {} fields after it ({} needed)", n, remaining,
                             n + after));
    return n;
  }
  // n ranges starting at field i: finite and >= 0 (CARMEN never writes NaN, inf or negatives).
  void ranges(std::size_t i, std::size_t n, std::vector<double>& out) const {
    out.resize(n);
    for (std::size_t k = 0; k < n; ++k) {
      double v;
      const std::string_view tok = f_[i + k];
      if (!parseDouble(tok, v)) fail(fmt::format("{} range {}", f_[0], k), fmt::format("{} is not a number", quoted(tok)));
      if (!std::isfinite(v) || v < 0.0)
        fail(fmt::format("{} range {}", f_[0], k),
             fmt::format("{} is {}", quoted(tok), std::isfinite(v) ? "negative" : "not finite"));
      out[k] = v;
    }
  }
  void numbers(std::size_t i, std::size_t n, const char* what, std::vector<double>& out) const {
    out.resize(n);
    for (std::size_t k = 0; k < n; ++k) {
      double v;
      if (!parseDouble(f_[i + k], v) || !std::isfinite(v))
        fail(fmt::format("{} {} {}", f_[0], what, k), fmt::format("{} is not a finite number", quoted(f_[i + k])));
      out[k] = v;
    }
  }
  LaserScan makeScan(LaserScanFields fields) const {
    try {
      return LaserScan::create(std::move(fields));
    } catch (const Error& e) {
      throw badInput(e.message(), {path_, line_, fmt::format("{} {}", f_[0], e.where().field)});
    }
  }
  std::size_t size() const { return f_.size(); }

 private:
  const std::string& path_;
  std::size_t line_;
  const std::vector<std::string_view>& f_;
};

LaserMsg parseOldLaser(const LineParser& p, const LaserType& type, const Params& params) {
  const int side = type.kind == LaserKind::kRear ? 1 : 0;
  const std::size_t n = p.count(1, "num_readings", 7);  // 6 pose fields + ipc_timestamp
  if (n == 0) p.fail("FLASER num_readings", "a scan needs at least one beam");
  LaserScanFields fields;
  p.ranges(2, n, fields.ranges);
  LaserMsg m;
  const SE2 laser_pose = p.pose(2 + n, "x", "y", "theta");
  m.odom = p.pose(5 + n, "odom_x", "odom_y", "odom_theta");
  m.time = p.finite(8 + n, "ipc_timestamp");
  // Beam angles: see the file comment.
  const double nd = static_cast<double>(n);
  const double span_beams = (n % 2 == 0) ? nd : nd - 1.0;  // increments across the field of view
  double d_deg, min_deg;
  if (params.resolution_deg[side]) {
    d_deg = *params.resolution_deg[side];
    min_deg = params.fov_deg[side] ? -*params.fov_deg[side] / 2.0 : -span_beams * d_deg / 2.0;
  } else {
    const double fov = params.fov_deg[side].value_or(180.0);
    d_deg = span_beams > 0 ? fov / span_beams : 1.0;
    min_deg = n > 1 ? -fov / 2.0 : 0.0;
  }
  fields.time = m.time;
  fields.angle_min = deg2rad(min_deg);
  fields.angle_increment = deg2rad(d_deg);
  fields.range_min = 0.0;
  fields.range_max = params.max_range[side].value_or(kDefaultRangeMax);
  m.scan = p.makeScan(std::move(fields));
  m.T_robot_laser = SE2(params.offset_x[side], params.offset_y[side],
                        params.offset_theta[side] + (side == 1 ? std::numbers::pi : 0.0));
  // The first pose triple is the laser's (CARMEN's robot module adds the mounting to the robot's
  // pose); the robot's pose is that less the mounting, as ROBOTLASER states it outright.
  m.pose = laser_pose * m.T_robot_laser.inverse();
  return m;
}

LaserMsg parseNewLaser(const LineParser& p, const LaserType& type, const Params& params) {
  const bool robot = type.kind == LaserKind::kRobot;
  const double start = p.finite(2, "start_angle");
  const double fov = p.finite(3, "field_of_view");
  const double res = p.finite(4, "angular_resolution");
  const double max_range = p.finite(5, "maximum_range");
  p.finite(6, "accuracy");
  p.finite(7, "remission_mode");
  const std::size_t n = p.count(8, "num_readings", 1);  // at least num_remissions follows
  if (n == 0) p.fail(fmt::format("{} num_readings", type.name), "a scan needs at least one beam");
  const std::string name(type.name);
  if (fov <= 0.0 || fov > 2.0 * std::numbers::pi + std::abs(res) + 1e-6)
    p.fail(name + " field_of_view", fmt::format("{} rad is not in (0, 2 pi]", fov));
  if (res == 0.0) p.fail(name + " angular_resolution", "must be non-zero");
  if (static_cast<double>(n - 1) * std::abs(res) > fov * (1.0 + 1e-6) + 1e-9)
    p.fail(name + " angular_resolution",
           fmt::format("{} beams at {} rad span {} rad, more than the field of view of {} rad", n, res,
                       static_cast<double>(n - 1) * std::abs(res), fov));
  if (max_range <= 0.0) p.fail(name + " maximum_range", fmt::format("{} m must be positive", max_range));
  LaserScanFields fields;
  p.ranges(9, n, fields.ranges);
  const std::size_t after = robot ? 12 : 1;  // fields after the remissions, through the timestamp
  const std::size_t m_rem = p.count(9 + n, "num_remissions", after);
  std::vector<double> rem;
  p.numbers(10 + n, m_rem, "remission", rem);
  if (m_rem == n) fields.intensities = std::move(rem);  // other counts: remissions are not per beam
  const std::size_t k = 10 + n + m_rem;
  LaserMsg m;
  if (robot) {
    const SE2 laser_pose = p.pose(k, "laser_pose_x", "laser_pose_y", "laser_pose_theta");
    const SE2 robot_pose = p.pose(k + 3, "robot_pose_x", "robot_pose_y", "robot_pose_theta");
    for (std::size_t j = 6; j < 11; ++j) p.anyNumber(k + j, "velocity/safety field");
    m.time = p.finite(k + 11, "timestamp");
    m.pose = robot_pose;
    m.odom = robot_pose;
    m.T_robot_laser = robot_pose.inverse() * laser_pose;
  } else {
    m.time = p.finite(k, "timestamp");
    const int side = type.number == 2 ? 1 : 0;
    if (type.number <= 2)
      m.T_robot_laser = SE2(params.offset_x[side], params.offset_y[side],
                            params.offset_theta[side] + (side == 1 ? std::numbers::pi : 0.0));
  }
  fields.time = m.time;
  fields.angle_min = start;
  fields.angle_increment = res;
  fields.range_min = 0.0;
  fields.range_max = max_range;
  m.scan = p.makeScan(std::move(fields));
  return m;
}

void applyParam(const LineParser& p, const std::vector<std::string_view>& f, Params& params) {
  if (f.size() < 2) return;
  const std::string_view name = f[1];
  struct Known {
    std::string_view name;
    int side;
    int what;  // 0 x [m], 1 y [m], 2 theta [rad], 3 resolution [deg], 4 fov [deg], 5 max range [m]
  };
  static constexpr Known kKnown[] = {
      {"robot_frontlaser_offset", 0, 0},         {"robot_frontlaser_side_offset", 0, 1},
      {"robot_frontlaser_angular_offset", 0, 2}, {"laser_front_laser_resolution", 0, 3},
      {"laser_front_laser_fov", 0, 4},           {"robot_front_laser_max", 0, 5},
      {"laser_front_laser_max_range", 0, 5},     {"robot_rearlaser_offset", 1, 0},
      {"robot_rearlaser_side_offset", 1, 1},     {"robot_rearlaser_angular_offset", 1, 2},
      {"laser_rear_laser_resolution", 1, 3},     {"laser_rear_laser_fov", 1, 4},
      {"robot_rear_laser_max", 1, 5},            {"laser_rear_laser_max_range", 1, 5},
  };
  for (const auto& k : kKnown) {
    if (k.name != name) continue;
    const std::string field = fmt::format("PARAM {}", name);
    if (f.size() < 3) p.fail(field, "missing value");
    double v;
    if (!parseDouble(f[2], v) || !std::isfinite(v)) p.fail(field, fmt::format("{} is not a finite number", quoted(f[2])));
    switch (k.what) {
      case 0: params.offset_x[k.side] = v; break;
      case 1: params.offset_y[k.side] = v; break;
      case 2: params.offset_theta[k.side] = v; break;
      case 3:
        if (v <= 0.0 || v > 360.0) p.fail(field, fmt::format("{} deg is not in (0, 360]", v));
        params.resolution_deg[k.side] = v;
        break;
      case 4:
        if (v <= 0.0 || v > 360.0) p.fail(field, fmt::format("{} deg is not in (0, 360]", v));
        params.fov_deg[k.side] = v;
        break;
      default:
        if (v <= 0.0) p.fail(field, fmt::format("{} m must be positive", v));
        params.max_range[k.side] = v;
        break;
    }
    return;
  }
}

}  // namespace

EventReader::EventReader(const std::string& path, const LaserType* selected)
    : path_(path), in_(std::make_unique<TextLineReader>(path, TextKind{"CARMEN log", "log", "CARMEN text log"})), selected_(selected) {
  fields_.reserve(1024);
}

EventReader::~EventReader() = default;

std::size_t EventReader::lineNo() const { return in_->lineNo(); }

bool EventReader::next(Event& ev) {
  std::string_view line;
  while (in_->next(line)) {
    ev.kind = Event::kNone;
    ev.line = in_->lineNo();
    if (classify(line, ev)) return true;
  }
  return false;
}

bool EventReader::classify(std::string_view line, Event& ev) {
  std::size_t s = 0;
  while (s < line.size() && (line[s] == ' ' || line[s] == '\t')) ++s;
  if (s == line.size()) return false;
  if (line[s] == '#') {
    if (line.substr(s).rfind(kCarmenWriterMarker, 0) == 0) {
      ev.kind = Event::kMarker;
      return true;
    }
    return false;
  }
  // Tag first, so that skipped messages (NEFF, other lasers) cost no field parsing.
  std::size_t e = s;
  while (e < line.size() && line[e] != ' ' && line[e] != '\t') ++e;
  const std::string_view tag = line.substr(s, e - s);
  const LaserType* lt = laserType(tag);
  if (lt) {
    if (!selected_) selected_ = lt;
    if (lt != selected_) {
      ev.kind = Event::kOtherLaser;
      ev.laser_type = lt;
      return true;
    }
  } else if (tag != "ODOM" && tag != "TRUEPOS" && tag != "PARAM") {
    return false;
  }
  split(line, fields_);
  const LineParser p(path_, in_->lineNo(), fields_);
  if (lt) {
    ev.kind = Event::kLaser;
    ev.laser_type = lt;
    ev.laser = (lt->kind == LaserKind::kFront || lt->kind == LaserKind::kRear) ? parseOldLaser(p, *lt, params_)
                                                                               : parseNewLaser(p, *lt, params_);
    return true;
  }
  if (tag == "ODOM") {
    ev.kind = Event::kOdom;
    ev.sample.pose = p.pose(1, "x", "y", "theta");
    for (std::size_t j = 4; j < 7; ++j) p.anyNumber(j, j == 4 ? "tv" : j == 5 ? "rv" : "accel");
    ev.sample.time = p.finite(7, "ipc_timestamp");
    return true;
  }
  if (tag == "TRUEPOS") {
    ev.kind = Event::kTruth;
    ev.sample.pose = p.pose(1, "true_x", "true_y", "true_theta");
    p.pose(4, "odom_x", "odom_y", "odom_theta");
    ev.sample.time = p.finite(7, "ipc_timestamp");
    return true;
  }
  applyParam(p, fields_, params_);  // PARAM
  return false;
}

}  // namespace lidar2d::io::internal::carmen
