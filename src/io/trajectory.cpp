// Trajectory, relations and relative-pose files (see include/lidar2d/io/trajectory.hpp).

#include "lidar2d/io/trajectory.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <array>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <optional>
#include <string_view>
#include <system_error>

#include "lidar2d/core/error.hpp"
#include "lidar2d/io/atomic_file.hpp"
#include "src/io/internal/read_file.hpp"

namespace lidar2d::io {
namespace {

constexpr std::array<const char*, 4> kPlainFields{"timestamp", "x", "y", "theta"};
constexpr std::array<const char*, 8> kTumFields{"timestamp", "tx", "ty", "tz", "qx", "qy", "qz", "qw"};
constexpr std::array<const char*, 8> kRelationFields{"t1", "t2", "dx", "dy", "dz", "droll", "dpitch", "dyaw"};
constexpr std::array<const char*, 7> kPairFields{"t_prev", "t_cur", "dx", "dy", "dtheta", "converged", "iterations"};

// How far a TUM quaternion's norm may be from 1: files print 4 to 9 decimals, so a rounded unit
// quaternion is within ~1e-4 of 1, while a wrong column order or a non-rotation is far off.
constexpr double kQuatNormTol = 1e-3;

bool isSpace(char c) { return c == ' ' || c == '\t' || c == '\r' || c == '\v' || c == '\f'; }

/// Splits a line on runs of whitespace. Returns an empty list for blank and `#` comment lines.
std::vector<std::string_view> splitFields(std::string_view line) {
  std::vector<std::string_view> out;
  std::size_t i = 0;
  while (i < line.size() && isSpace(line[i])) ++i;
  if (i == line.size() || line[i] == '#') return out;
  while (i < line.size()) {
    const std::size_t start = i;
    while (i < line.size() && !isSpace(line[i])) ++i;
    out.push_back(line.substr(start, i - start));
    while (i < line.size() && isSpace(line[i])) ++i;
  }
  return out;
}

/// Parses a whole token as a double; std::nullopt when it is not entirely a number.
std::optional<double> toDouble(std::string_view s, std::errc* ec_out = nullptr) {
  if (!s.empty() && s.front() == '+') s.remove_prefix(1);  // from_chars rejects a leading '+'
  double v = 0.0;
  const auto [ptr, ec] = std::from_chars(s.data(), s.data() + s.size(), v);
  if (ec_out) *ec_out = ec;
  if (ec != std::errc() || ptr != s.data() + s.size() || s.empty()) return std::nullopt;
  return v;
}

/// A line-by-line reader that knows where it is, for error messages.
class LineReader {
 public:
  explicit LineReader(const std::string& path) : path_(path), in_(path, std::ios::binary) {
    if (!in_) throw ioError(std::string("cannot open: ") + std::strerror(errno), {path});
    // (A directory opens; a device such as /dev/zero would make std::getline read without end.)
    internal::checkInputFile(path, "text file");
  }
  /// Next data line split into fields (comments and blank lines skipped); false at the end.
  bool next(std::vector<std::string_view>& fields) {
    while (std::getline(in_, line_)) {
      ++line_no_;
      fields = splitFields(line_);
      if (!fields.empty()) return true;
    }
    if (in_.bad()) throw ioError("read error", {path_, line_no_});
    return false;
  }
  std::size_t line() const { return line_no_; }
  const std::string& path() const { return path_; }

  /// A finite number from field `i` (0-based) named `name`, or an error naming it.
  double number(const std::vector<std::string_view>& fields, std::size_t i, const char* name) const {
    std::errc ec{};
    const auto v = toDouble(fields[i], &ec);
    const ErrorLocation where{path_, line_no_, fmt::format("field {} ({})", i + 1, name)};
    if (!v) {
      if (ec == std::errc::result_out_of_range) throw badInput(fmt::format("number out of range: '{}'", fields[i]), where);
      throw badInput(fmt::format("not a number: '{}'", fields[i]), where);
    }
    if (!std::isfinite(*v)) throw badInput(fmt::format("not a finite number: '{}'", fields[i]), where);
    return *v;
  }

  [[noreturn]] void fieldCount(std::size_t found, const std::string& expected) const {
    throw badInput(fmt::format("expected {}, found {} field{}", expected, found, found == 1 ? "" : "s"),
                   {path_, line_no_});
  }

 private:
  std::string path_;
  std::ifstream in_;
  std::string line_;
  std::size_t line_no_ = 0;
};

double yawFromQuaternion(double qx, double qy, double qz, double qw) {
  // Yaw of the rotation (ZYX convention); equals 2*atan2(qz, qw) for a rotation about z only.
  return std::atan2(2.0 * (qw * qz + qx * qy), 1.0 - 2.0 * (qy * qy + qz * qz));
}

}  // namespace

Trajectory readTrajectory(const std::string& path) {
  LineReader r(path);
  Trajectory out;
  std::vector<std::string_view> f;
  std::size_t n_fields = 0;
  std::size_t first_line = 0;
  while (r.next(f)) {
    if (n_fields == 0) {
      if (f.size() != 4 && f.size() != 8)
        r.fieldCount(f.size(), "4 fields (timestamp x y theta) or 8 (TUM: timestamp tx ty tz qx qy qz qw)");
      n_fields = f.size();
      first_line = r.line();
    } else if (f.size() != n_fields) {
      r.fieldCount(f.size(), fmt::format("{} fields as on line {}", n_fields, first_line));
    }
    StampedPose p;
    if (n_fields == 4) {
      p.time = r.number(f, 0, kPlainFields[0]);
      p.pose = SE2(r.number(f, 1, kPlainFields[1]), r.number(f, 2, kPlainFields[2]), r.number(f, 3, kPlainFields[3]));
    } else {
      std::array<double, 8> v{};
      for (std::size_t i = 0; i < 8; ++i) v[i] = r.number(f, i, kTumFields[i]);
      const double norm = std::sqrt(v[4] * v[4] + v[5] * v[5] + v[6] * v[6] + v[7] * v[7]);
      if (std::abs(norm - 1.0) > kQuatNormTol)
        throw badInput(fmt::format("quaternion (qx qy qz qw) has norm {:.6f}, expected 1", norm),
                       {path, r.line(), "fields 5-8 (qx qy qz qw)"});
      p.time = v[0];
      p.pose = SE2(v[1], v[2], yawFromQuaternion(v[4] / norm, v[5] / norm, v[6] / norm, v[7] / norm));
    }
    out.push_back(p);
  }
  if (out.empty()) throw badInput("holds no poses (expected lines 'timestamp x y theta')", {path});
  return out;
}

void writeTrajectory(const std::string& path, const Trajectory& trajectory, TrajectoryFormat format) {
  AtomicFile file(path);
  std::ostream& o = file.stream();
  // 9 decimals: a Unix time of ~1e9 s then has 19 significant digits, more than the 17 a double
  // needs to read back bit-identical.
  if (format == TrajectoryFormat::kPlain) {
    o << "# timestamp[s] x[m] y[m] theta[rad]\n";
    for (const auto& p : trajectory)
      o << fmt::format("{:.9f} {:.9f} {:.9f} {:.9f}\n", p.time, p.pose.x(), p.pose.y(), p.pose.theta());
  } else {
    o << "# timestamp tx ty tz qx qy qz qw\n";
    for (const auto& p : trajectory) {
      const double h = 0.5 * p.pose.theta();
      o << fmt::format("{:.9f} {:.9f} {:.9f} 0 0 0 {:.12f} {:.12f}\n", p.time, p.pose.x(), p.pose.y(), std::sin(h),
                       std::cos(h));
    }
  }
  file.commit();
}

Relations readRelations(const std::string& path) {
  LineReader r(path);
  Relations out;
  std::vector<std::string_view> f;
  while (r.next(f)) {
    if (f.size() != 8) r.fieldCount(f.size(), "8 fields (t1 t2 dx dy dz droll dpitch dyaw)");
    std::array<double, 8> v{};
    for (std::size_t i = 0; i < 8; ++i) v[i] = r.number(f, i, kRelationFields[i]);
    out.push_back(Relation{v[0], v[1], SE2(v[2], v[3], v[7])});
  }
  if (out.empty()) throw badInput("holds no relations (expected lines 't1 t2 dx dy dz droll dpitch dyaw')", {path});
  return out;
}

std::vector<RelativePose> readRelativePoses(const std::string& path) {
  LineReader r(path);
  std::vector<RelativePose> out;
  std::vector<std::string_view> f;
  std::size_t n_fields = 0;
  std::size_t first_line = 0;
  while (r.next(f)) {
    if (n_fields == 0) {
      if (f.size() != 5 && f.size() != 7)
        r.fieldCount(f.size(), "7 fields (t_prev t_cur dx dy dtheta converged iterations) or 5 (without the last two)");
      n_fields = f.size();
      first_line = r.line();
    } else if (f.size() != n_fields) {
      r.fieldCount(f.size(), fmt::format("{} fields as on line {}", n_fields, first_line));
    }
    RelativePose p;
    p.t_prev = r.number(f, 0, kPairFields[0]);
    p.t_cur = r.number(f, 1, kPairFields[1]);
    p.T_prev_cur = SE2(r.number(f, 2, kPairFields[2]), r.number(f, 3, kPairFields[3]), r.number(f, 4, kPairFields[4]));
    if (n_fields == 7) {
      const double c = r.number(f, 5, kPairFields[5]);
      if (c != 0.0 && c != 1.0)
        throw badInput(fmt::format("expected 0 or 1, found '{}'", f[5]), {path, r.line(), "field 6 (converged)"});
      const double it = r.number(f, 6, kPairFields[6]);
      if (it < 0 || it != std::floor(it) || it > 1e9)
        throw badInput(fmt::format("expected a non-negative integer, found '{}'", f[6]),
                       {path, r.line(), "field 7 (iterations)"});
      p.converged = c == 1.0;
      p.iterations = static_cast<int>(it);
    }
    out.push_back(p);
  }
  if (out.empty())
    throw badInput("holds no pairs (expected lines 't_prev t_cur dx dy dtheta converged iterations')", {path});
  return out;
}

PoseFileKind detectPoseFile(const std::string& path) {
  namespace fs = std::filesystem;
  std::error_code ec;
  if (!fs::exists(path, ec)) throw ioError("no such file", {path});
  if (fs::is_directory(path, ec)) return PoseFileKind::kLog;  // a ROS2 bag folder, or openLog explains
  std::ifstream in(path, std::ios::binary);
  if (!in) throw ioError(std::string("cannot open: ") + std::strerror(errno), {path});
  char head[16] = {};
  in.read(head, sizeof head);
  const std::string h(head, static_cast<std::size_t>(in.gcount()));
  const auto byte = [&](std::size_t i) { return static_cast<unsigned char>(h[i]); };
  if (h.size() >= 2 && byte(0) == 0x1f && byte(1) == 0x8b) return PoseFileKind::kLog;  // gzip
  if (h.rfind("#ROSBAG V", 0) == 0 || h.rfind("SQLite format 3", 0) == 0) return PoseFileKind::kLog;
  for (char c : h)
    if (c == '\0') return PoseFileKind::kLog;  // binary: openLog names what it is
  if (fs::path(path).extension() == ".relations") return PoseFileKind::kRelations;

  in.clear();
  in.seekg(0);
  std::string line;
  while (std::getline(in, line)) {
    const auto f = splitFields(line);
    if (f.empty()) continue;
    if (!toDouble(f[0])) {
      // CARMEN lines start with an upper-case message name ("PARAM", "FLASER", "ROBOTLASER1"); any
      // other word is a malformed pose file, which the trajectory reader reports with line and field.
      const bool keyword = std::all_of(f[0].begin(), f[0].end(), [](char c) {
        return (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') || c == '_';
      });
      return keyword ? PoseFileKind::kLog : PoseFileKind::kTrajectory;
    }
    if (f.size() != 8) return PoseFileKind::kTrajectory;
    // 8 numbers: TUM when the last four are a unit quaternion. Only the first data line decides, so
    // that a TUM file with a bad quaternion further down is reported by the trajectory reader with
    // its line (a relations line's last four are (dz, droll, dpitch, dyaw) = (0, 0, 0, dyaw)).
    std::array<double, 8> v{};
    for (std::size_t i = 0; i < 8; ++i) {
      const auto d = toDouble(f[i]);
      if (!d) return PoseFileKind::kTrajectory;  // the reader names the bad field
      v[i] = *d;
    }
    const double norm = std::sqrt(v[4] * v[4] + v[5] * v[5] + v[6] * v[6] + v[7] * v[7]);
    return std::abs(norm - 1.0) <= kQuatNormTol ? PoseFileKind::kTrajectory : PoseFileKind::kRelations;
  }
  return PoseFileKind::kTrajectory;  // empty files too: readTrajectory reports them
}

}  // namespace lidar2d::io
