#include <fmt/format.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <numbers>
#include <string_view>
#include <vector>

#include "lidar2d/core/error.hpp"
#include "lidar2d/io/frame_source.hpp"
#include "src/io/internal/decompress.hpp"
#include "src/io/internal/readers.hpp"

namespace lidar2d::io {

const char* toString(LogFormat f) {
  switch (f) {
    case LogFormat::kCarmen:
      return "carmen";
    case LogFormat::kRosbag1:
      return "rosbag1";
    case LogFormat::kRosbag2:
      return "rosbag2";
    case LogFormat::kRangeTable:
      return "range-table";
  }
  return "unknown";
}

LogFormat detectFormat(const std::string& path) {
  namespace fs = std::filesystem;
  std::error_code ec;
  if (!fs::exists(path, ec)) throw ioError("no such file", {path});
  if (fs::is_directory(path, ec)) {
    if (fs::exists(fs::path(path) / "metadata.yaml", ec)) return LogFormat::kRosbag2;
    const RangeTableFiles t = internal::rangeTableFolder(path);
    const bool has[3] = {fs::exists(t.poses, ec), fs::exists(t.angles, ec), fs::exists(t.ranges, ec)};
    if (has[0] && has[1] && has[2]) return LogFormat::kRangeTable;
    if (has[0] || has[1] || has[2])
      throw badInput(fmt::format("a range table folder needs poses.txt, angles.txt and ranges.txt; {} is missing",
                                 !has[0] ? "poses.txt" : (!has[1] ? "angles.txt" : "ranges.txt")),
                     {path});
    throw badInput(
        "is a directory, not a log file (a ROS2 bag folder would hold metadata.yaml, a range table folder "
        "poses.txt, angles.txt and ranges.txt)",
        {path});
  }
  std::ifstream in(path, std::ios::binary);
  if (!in) throw ioError(std::string("cannot open: ") + std::strerror(errno), {path});
  char head[16] = {};
  in.read(head, sizeof head);
  const auto n = static_cast<std::size_t>(in.gcount());
  if (n == 0) throw badInput("file is empty", {path});
  const std::string h(head, n);
  const char* magic = internal::compressionMagic({reinterpret_cast<const unsigned char*>(head), n});
  const std::string_view compressed = magic ? magic : "";
  if (compressed == "gzip") return LogFormat::kCarmen;  // only CARMEN text logs are read compressed
  if (h.rfind("#ROSBAG V", 0) == 0 || h.rfind("#ROSRECORD V", 0) == 0) return LogFormat::kRosbag1;  // 2.0 | 1.2
  if (h.rfind("SQLite format 3", 0) == 0) return LogFormat::kRosbag2;
  if (h.rfind("\x89MCAP", 0) == 0) return LogFormat::kRosbag2;  // rosbag2's MCAP storage
  // A zstd file is most likely one file of a zstd-compressed rosbag2 bag.
  if (compressed == "zstd")
    throw badInput("zstd-compressed file: give the rosbag2 bag folder (its metadata.yaml says how it was compressed), "
                   "or decompress it first",
                   {path});
  return LogFormat::kCarmen;  // text; the CARMEN reader reports other compressions and content it cannot parse
}

namespace {

// ReaderOptions::laser_mount: the same mounting on every frame. The readers leave the frames
// unmounted (identity, scan as recorded) when the options give one, so it is applied here once.
class MountOverride final : public FrameSource {
 public:
  MountOverride(std::unique_ptr<FrameSource> inner, const LaserMount& mount, std::vector<std::string> warnings)
      : inner_(std::move(inner)), mount_(mount), warnings_(std::move(warnings)) {}
  std::optional<Frame> next() override {
    std::optional<Frame> f = inner_->next();
    if (f) internal::mountFrame(*f, mount_);  // cannot throw: applyTiltRule accepted the tilt
    return f;
  }
  LogFormat format() const override { return inner_->format(); }
  const std::string& path() const override { return inner_->path(); }
  SourceNotes notes() const override {
    SourceNotes n = inner_->notes();
    n.scan_source += mount_.upsideDown() ? " (laser mounting given by the options, upside down, not the log)"
                                         : " (laser mounting given by the options, not the log)";
    n.warnings.insert(n.warnings.end(), warnings_.begin(), warnings_.end());
    return n;
  }
  std::optional<std::size_t> sizeHint() const override { return inner_->sizeHint(); }

 private:
  std::unique_ptr<FrameSource> inner_;
  LaserMount mount_;
  std::vector<std::string> warnings_;
};

/// `ReaderOptions::laser_range_max`: every scan rebuilt with that range max (validity recomputed
/// from the raw readings, which the readers keep).
class RangeMaxOverride final : public FrameSource {
 public:
  RangeMaxOverride(std::unique_ptr<FrameSource> inner, double range_max)
      : inner_(std::move(inner)), range_max_(range_max) {}
  std::optional<Frame> next() override {
    std::optional<Frame> f = inner_->next();
    if (!f) return f;
    if (!(range_max_ > f->scan.rangeMin()))
      throw invalidArgument(fmt::format("the laser range max {:g} m is not above the log's range min {:g} m",
                                        range_max_, f->scan.rangeMin()),
                            {"ReaderOptions", 0, "laser_range_max"});
    f->scan = internal::withRangeMax(f->scan, range_max_);
    return f;
  }
  LogFormat format() const override { return inner_->format(); }
  const std::string& path() const override { return inner_->path(); }
  SourceNotes notes() const override {
    SourceNotes n = inner_->notes();
    n.scan_source += fmt::format(" (range max {:g} m given by the options, not the log)", range_max_);
    return n;
  }
  std::optional<std::size_t> sizeHint() const override { return inner_->sizeHint(); }

 private:
  std::unique_ptr<FrameSource> inner_;
  double range_max_;
};

/// What every log's frames say about the log, whatever its format: readings beyond the range max
/// that are not its no-return code (a declared range max below what the laser measures: edmonton's
/// PARAM robot_front_laser_max 10 while its SICK reads walls at 45 m, silently dropping real
/// returns), and timestamps that repeat or go backwards. Added to the notes' warnings (complete once
/// the stream is exhausted), so that every command can tell the user, not only `info`.
class LogWatch final : public FrameSource {
 public:
  explicit LogWatch(std::unique_ptr<FrameSource> inner) : inner_(std::move(inner)) {}
  std::optional<Frame> next() override {
    std::optional<Frame> f = inner_->next();
    if (!f) return f;
    if (frames_ == 0) range_max_ = f->scan.rangeMax();
    if (frames_ > 0 && f->time == prev_time_) ++time_repeats_;
    if (frames_ > 0 && f->time < prev_time_) ++time_backwards_;
    prev_time_ = f->time;
    ++frames_;
    beyond_.add(f->scan);
    return f;
  }
  LogFormat format() const override { return inner_->format(); }
  const std::string& path() const override { return inner_->path(); }
  SourceNotes notes() const override {
    SourceNotes n = inner_->notes();
    // Readers that already reported timestamp problems keep their wording.
    const bool told = std::any_of(n.warnings.begin(), n.warnings.end(),
                                  [](const std::string& w) { return w.find("timestamp") != std::string::npos; });
    if (!told && time_repeats_)
      n.warnings.push_back(fmt::format("{} scans repeat the previous scan's timestamp", time_repeats_));
    if (!told && time_backwards_)
      n.warnings.push_back(fmt::format("{} scans have a timestamp earlier than the previous scan's", time_backwards_));
    n.beams_beyond_range_max = beyond_.returns();
    if (beyond_.contradicted()) {
      const double code = *beyond_.code();
      n.warnings.push_back(fmt::format(
          "{:.1f}% of the beams read beyond the range max ({:.2f} m of the first scan) and are not the log's "
          "no-return reading ({:.2f} m, the most frequent there): they count as no return; the laser may measure "
          "farther than its declared range max (CARMEN: PARAM robot_front_laser_max, laser_front_laser_max_range); "
          "--laser-range-max R, R below {:.2f}, reads them as returns",
          100.0 * static_cast<double>(n.beams_beyond_range_max) / static_cast<double>(beyond_.beams()), range_max_,
          code, code));
    }
    return n;
  }
  std::optional<std::size_t> sizeHint() const override { return inner_->sizeHint(); }

 private:
  std::unique_ptr<FrameSource> inner_;
  std::size_t frames_ = 0, time_repeats_ = 0, time_backwards_ = 0;
  double prev_time_ = 0.0, range_max_ = 0.0;
  internal::BeyondRangeMax beyond_;
};

std::unique_ptr<FrameSource> openFormat(const std::string& path, const ReaderOptions& options) {
  switch (detectFormat(path)) {
    case LogFormat::kCarmen:
      return internal::openCarmen(path, options);
    case LogFormat::kRosbag1:
      return internal::openRosbag1(path, options);
    case LogFormat::kRosbag2:
      return internal::openRosbag2(path, options);
    case LogFormat::kRangeTable:
      return internal::openRangeTable(internal::rangeTableFolder(path));
  }
  throw badInput("unknown log format", {path});
}

}  // namespace

namespace internal {

LaserScan withRangeMax(const LaserScan& scan, double range_max) {
  LaserScanFields fields = scan.fields();
  fields.range_max = range_max;
  return LaserScan::create(std::move(fields));
}

void BeyondRangeMax::add(const LaserScan& scan) {
  beams_ += scan.size();
  const double range_max = scan.rangeMax();
  for (const double r : scan.ranges())
    if (std::isfinite(r) && r >= range_max && (over_.size() < kMaxValues || over_.contains(r))) ++over_[r];
}

std::optional<double> BeyondRangeMax::code() const {
  if (over_.empty()) return std::nullopt;
  return std::max_element(over_.begin(), over_.end(), [](const auto& a, const auto& b) { return a.second < b.second; })
      ->first;
}

std::size_t BeyondRangeMax::returns() const {
  const std::optional<double> c = code();
  if (!c) return 0;
  std::size_t n = 0;
  for (const auto& [r, count] : over_)
    if (std::abs(r - *c) > kCodeTolerance * *c) n += count;
  return n;
}

bool BeyondRangeMax::contradicted() const {
  return beams_ > 0 && static_cast<double>(returns()) >= kShare * static_cast<double>(beams_);
}

bool BeyondRangeMax::codeAboveReturns() const {
  const std::optional<double> c = code();
  if (!c) return false;
  std::size_t at_code = 0;
  for (const auto& [r, count] : over_) {
    if (r > *c * (1.0 + kCodeTolerance)) return false;
    if (r >= *c * (1.0 - kCodeTolerance)) at_code += count;
  }
  return static_cast<double>(at_code) >= kShare * static_cast<double>(beams_);
}

LaserMount applyTiltRule(const LaserMount& mount, const ReaderOptions& options, const ErrorLocation& where,
                         const std::string& what, std::vector<std::string>& warnings) {
  constexpr double kDeg = std::numbers::pi / 180.0;
  if (mount.tilt() <= options.max_laser_tilt_deg * kDeg) return mount.levelled();
  const std::string tilted = fmt::format("the laser mounting {} is tilted by {:.1f} deg out of the robot's plane",
                                         what, mount.tilt() / kDeg);
  if (mount.tilt() > LaserMount::kMaxProjectableTilt)
    throw badInput(fmt::format("{}, more than the {:.0f} deg that can be projected onto it: the laser does not scan "
                               "the walls around the robot",
                               tilted, LaserMount::kMaxProjectableTilt / kDeg),
                   where);
  if (!options.allow_tilted_laser)
    throw badInput(fmt::format("{}, more than the tolerance of {:g} deg: its scans do not lie in the floor plane "
                               "(--allow-tilted projects them onto it, --max-tilt raises the tolerance)",
                               tilted, options.max_laser_tilt_deg),
                   where);
  warnings.push_back(fmt::format("{} (tolerance {:g} deg): its beams are projected onto the floor plane, each range "
                                 "shortened by the tilt",
                                 tilted, options.max_laser_tilt_deg));
  return mount;
}

void mountFrame(Frame& frame, const LaserMount& mount) {
  frame.scan = mount.project(std::move(frame.scan));
  frame.T_robot_laser = mount.T_robot_laser();
  frame.laser_upside_down = mount.upsideDown();
  frame.laser_tilt_rad = mount.tilt();
}

}  // namespace internal

std::unique_ptr<FrameSource> openLog(const std::string& path, const ReaderOptions& options) {
  if (options.lasers.size() >= 2)
    return internal::openMergedLasers(path, options, [&path](const ReaderOptions& o) { return openLog(path, o); });
  if (options.lasers.size() == 1) {
    ReaderOptions o = options;
    o.scan_topic = o.carmen_laser = o.lasers.front();
    o.lasers.clear();
    if (o.laser_mounts.size() == 1) o.laser_mount = o.laser_mounts.front();
    o.laser_mounts.clear();
    return openLog(path, o);
  }
  if (!(options.max_laser_tilt_deg >= 0.0 && options.max_laser_tilt_deg <= 45.0))
    throw invalidArgument("the tilt tolerance must be within [0, 45] deg", {"ReaderOptions", 0, "max_laser_tilt_deg"});
  std::vector<std::string> mount_warnings;
  std::optional<LaserMount> mount;
  if (options.laser_mount) {
    const Eigen::Vector3d& t = options.laser_mount->translation3();
    if (!laserMountOffsetOk(t.x(), t.y()) || !(std::abs(t.z()) <= kMaxLaserMountOffset))
      throw invalidArgument(fmt::format("laser mounting must be within +-{:g} m of the robot's centre",
                                        kMaxLaserMountOffset),
                            {"ReaderOptions", 0, "laser_mount"});
    mount = internal::applyTiltRule(*options.laser_mount, options, {"ReaderOptions", 0, "laser_mount"},
                                    "given by the options", mount_warnings);
  }
  if (options.laser_range_max && !(*options.laser_range_max > 0.0 && *options.laser_range_max <= kMaxLaserRangeMax))
    throw invalidArgument(fmt::format("the laser range max must be in (0, {:g}] m", kMaxLaserRangeMax),
                          {"ReaderOptions", 0, "laser_range_max"});
  std::unique_ptr<FrameSource> source =
      options.range_table ? internal::openRangeTable(*options.range_table) : openFormat(path, options);
  if (options.laser_range_max) source = std::make_unique<RangeMaxOverride>(std::move(source), *options.laser_range_max);
  if (mount) source = std::make_unique<MountOverride>(std::move(source), *mount, std::move(mount_warnings));
  return std::make_unique<LogWatch>(std::move(source));
}

}  // namespace lidar2d::io
