// Plain range tables: a poses file (x y theta per line), one line of beam angles, one line of ranges
// per scan, no times (the layout of the UPenn data set a course on occupancy mapping uses, 3701
// scans x 1081 beams). The layout and its rules are in frame_source.hpp (RangeTableFiles) and
// docs/file-formats.md. The poses and ranges are read line by line side by side, so memory does not
// grow with the table's length.

#include <fmt/format.h>

#include <charconv>
#include <cmath>
#include <cstdio>
#include <memory>
#include <numbers>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "lidar2d/core/error.hpp"
#include "lidar2d/io/frame_source.hpp"
#include "src/io/internal/readers.hpp"
#include "src/io/internal/text_lines.hpp"

namespace lidar2d::io::internal {
namespace {

constexpr TextKind kTableText{"range table", "file", "range table file"};
// Beam angles may deviate from even spacing by this much (tables print 4-6 decimals) [rad].
constexpr double kAngleTolerance = 1e-4;

// Numbers of a line separated by commas and/or blanks. A comma with no number before it (",,",
// a leading comma) is an empty field: an error, as is anything that is not a number.
class NumberLine {
 public:
  NumberLine(const std::string& path, std::size_t line, std::string_view what) : path_(path), line_(line), what_(what) {}

  void parse(std::string_view s, std::vector<double>& out) const {
    out.clear();
    std::size_t i = 0;
    bool after_comma = true;  // a field is expected (start of line, or after a comma)
    while (true) {
      while (i < s.size() && isBlank(s[i])) ++i;
      if (i >= s.size()) {
        if (after_comma && !out.empty()) fail(out.size() + 1, "empty field after a comma");
        return;
      }
      if (s[i] == ',') {
        if (after_comma) fail(out.size() + 1, "empty field before a comma");
        after_comma = true;
        ++i;
        continue;
      }
      std::size_t e = i;
      while (e < s.size() && !isBlank(s[e]) && s[e] != ',') ++e;
      const std::string_view tok = s.substr(i, e - i);
      double v = 0.0;
      const char* b = tok.data();
      if (!tok.empty() && tok.front() == '+') ++b;  // from_chars rejects a leading '+'
      const auto r = std::from_chars(b, tok.data() + tok.size(), v);
      if (r.ec != std::errc() || r.ptr != tok.data() + tok.size())
        fail(out.size() + 1, fmt::format("'{}' is not a number", tok.substr(0, 40)));
      if (out.size() >= LaserScan::kMaxBeams)
        fail(out.size() + 1, fmt::format("more than {} values on one line", LaserScan::kMaxBeams));
      out.push_back(v);
      after_comma = false;
      i = e;
    }
  }
  [[noreturn]] void fail(std::size_t field, const std::string& msg) const {
    throw badInput(msg, {path_, line_, fmt::format("{} {}", what_, field)});
  }

 private:
  static bool isBlank(char c) { return c == ' ' || c == '\t' || c == '\r' || c == '\f' || c == '\v'; }
  const std::string& path_;
  std::size_t line_;
  std::string_view what_;
};

bool skipped(std::string_view line) {
  for (char c : line) {
    if (c == '#') return true;
    if (c != ' ' && c != '\t' && c != '\r') return false;
  }
  return true;  // blank
}

// The next line that is not blank or a comment, parsed into numbers; false at the end.
bool nextNumbers(TextLineReader& in, const std::string& path, std::string_view what, std::vector<double>& out) {
  std::string_view line;
  while (in.next(line))
    if (!skipped(line)) {
      NumberLine(path, in.lineNo(), what).parse(line, out);
      return true;
    }
  return false;
}

class RangeTableSource final : public FrameSource {
 public:
  explicit RangeTableSource(const RangeTableFiles& files) : f_(files) {
    if (!(f_.rate_hz > 0) || !std::isfinite(f_.rate_hz))
      throw invalidArgument(fmt::format("must be finite and > 0, got {}", f_.rate_hz), {"RangeTableFiles", 0, "rate_hz"});
    if (!(f_.range_max_m > 0) || !std::isfinite(f_.range_max_m))
      throw invalidArgument(fmt::format("must be finite and > 0, got {}", f_.range_max_m),
                            {"RangeTableFiles", 0, "range_max_m"});
    readAngles();
    poses_ = std::make_unique<TextLineReader>(f_.poses, kTableText);
    ranges_ = std::make_unique<TextLineReader>(f_.ranges, kTableText);
    size_hint_ = countPoses();
  }

  std::optional<Frame> next() override {
    if (done_) return std::nullopt;
    const bool have_ranges = nextNumbers(*ranges_, f_.ranges, "range", values_);
    const std::size_t ranges_line = ranges_->lineNo();
    const bool have_pose = nextNumbers(*poses_, f_.poses, "value", pose_);
    if (!have_ranges && !have_pose) {
      done_ = true;
      if (count_ == 0) throw badInput("holds no scans", {f_.ranges});
      return std::nullopt;
    }
    if (!have_ranges && count_ == 0) throw badInput("holds no scans", {f_.ranges});
    if (!have_ranges)
      throw badInput(fmt::format("holds {} scans, but {} has more poses (line {} is pose {})", count_, f_.poses,
                                 poses_->lineNo(), count_ + 1),
                     {f_.ranges});
    if (!have_pose)
      throw badInput(fmt::format("holds {} poses, but {} has more scans (line {} is scan {})", count_, f_.ranges,
                                 ranges_line, count_ + 1),
                     {f_.poses});
    // The pose: x y theta, finite.
    if (pose_.size() != 3)
      throw badInput(fmt::format("expected 3 values x y theta, got {}", pose_.size()), {f_.poses, poses_->lineNo()});
    for (std::size_t i = 0; i < 3; ++i)
      if (!std::isfinite(pose_[i]))
        throw badInput("must be finite", {f_.poses, poses_->lineNo(), i == 0 ? "x" : (i == 1 ? "y" : "theta")});
    // The ranges: finite, >= 0, one per angle.
    for (std::size_t i = 0; i < values_.size(); ++i)
      if (!std::isfinite(values_[i]) || values_[i] < 0)
        throw badInput(fmt::format("must be a finite range >= 0 [m], got {}", values_[i]),
                       {f_.ranges, ranges_line, fmt::format("range {}", i + 1)});
    if (values_.size() != num_beams_)
      throw badInput(fmt::format("{} ranges, but {} holds {} angles", values_.size(), f_.angles, num_beams_),
                     {f_.ranges, ranges_line});
    LaserScanFields s;
    s.time = static_cast<double>(count_) / f_.rate_hz;
    s.angle_min = angle_min_;
    s.angle_increment = angle_increment_;
    s.range_min = 0.0;
    s.range_max = f_.range_max_m;
    s.ranges = values_;
    Frame fr;
    fr.index = count_++;
    fr.time = s.time;
    fr.scan = LaserScan::create(std::move(s));
    fr.T_world_robot = SE2(pose_[0], pose_[1], pose_[2]);
    return fr;
  }

  LogFormat format() const override { return LogFormat::kRangeTable; }
  const std::string& path() const override { return f_.ranges; }
  SourceNotes notes() const override {
    SourceNotes n;
    n.scan_source = fmt::format("{} ({} beams per line, angles from {})", f_.ranges, num_beams_, f_.angles);
    n.truth_source = f_.poses;
    n.warnings.push_back(fmt::format("the table holds no times: scan k is at k / {:g} s", f_.rate_hz));
    return n;
  }
  std::optional<std::size_t> sizeHint() const override { return size_hint_; }

 private:
  void readAngles() {
    TextLineReader in(f_.angles, kTableText);
    std::vector<double> a;
    if (!nextNumbers(in, f_.angles, "angle", a)) throw badInput("holds no angles", {f_.angles});
    const std::size_t line = in.lineNo();
    std::vector<double> more;
    if (nextNumbers(in, f_.angles, "angle", more))
      throw badInput("expected one line of beam angles; this is a second one", {f_.angles, in.lineNo()});
    if (a.size() < 2) throw badInput("needs at least 2 beam angles", {f_.angles, line});
    for (std::size_t i = 0; i < a.size(); ++i)
      if (!std::isfinite(a[i]) || std::abs(a[i]) > 4 * std::numbers::pi)
        throw badInput(fmt::format("must be a finite angle within +-4 pi [rad], got {}", a[i]),
                       {f_.angles, line, fmt::format("angle {}", i + 1)});
    // LaserScan models beams as angle_min + i * increment: the table's angles must be evenly
    // spaced (to print precision) and increasing.
    angle_min_ = a.front();
    angle_increment_ = (a.back() - a.front()) / static_cast<double>(a.size() - 1);
    if (!(angle_increment_ > 0)) throw badInput("beam angles must increase", {f_.angles, line, "angle 2"});
    for (std::size_t i = 0; i < a.size(); ++i)
      if (std::abs(a[i] - (angle_min_ + static_cast<double>(i) * angle_increment_)) > kAngleTolerance)
        throw badInput(fmt::format("beam angles must be evenly spaced ({:.6f} rad apart); this one is off by {:.6f} rad",
                                   angle_increment_, a[i] - (angle_min_ + static_cast<double>(i) * angle_increment_)),
                       {f_.angles, line, fmt::format("angle {}", i + 1)});
    num_beams_ = a.size();
  }

  // The number of pose lines (for progress only: a short pass over the small poses file).
  std::optional<std::size_t> countPoses() const {
    try {
      TextLineReader in(f_.poses, kTableText);
      std::string_view line;
      std::size_t n = 0;
      while (in.next(line)) n += !skipped(line);
      return n;
    } catch (const Error&) {
      return std::nullopt;  // next() reports it at the line it reaches
    }
  }

  RangeTableFiles f_;
  std::unique_ptr<TextLineReader> poses_, ranges_;
  std::vector<double> values_, pose_;
  double angle_min_ = 0, angle_increment_ = 0;
  std::size_t num_beams_ = 0, count_ = 0;
  std::optional<std::size_t> size_hint_;
  bool done_ = false;
};

}  // namespace

RangeTableFiles rangeTableFolder(const std::string& dir) {
  RangeTableFiles t;
  const std::string base = dir.empty() || dir.back() == '/' ? dir : dir + "/";
  t.poses = base + "poses.txt";
  t.angles = base + "angles.txt";
  t.ranges = base + "ranges.txt";
  return t;
}

std::unique_ptr<FrameSource> openRangeTable(const RangeTableFiles& files) {
  return std::make_unique<RangeTableSource>(files);
}

}  // namespace lidar2d::io::internal
