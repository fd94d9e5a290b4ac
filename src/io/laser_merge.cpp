// Merging lasers: the scan resampling (mergeScans) and the FrameSource that pairs the lasers' scans
// in time (openMergedLasers). Why resample rather than keep uneven beams: include/lidar2d/io/laser_merge.hpp.

#include "lidar2d/io/laser_merge.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <deque>
#include <limits>
#include <numbers>

#include "lidar2d/core/error.hpp"
#include "src/io/internal/readers.hpp"

namespace lidar2d::io {

LaserScan mergeScans(const std::vector<PlacedScan>& inputs, double time) {
  constexpr double kTwoPi = 2.0 * std::numbers::pi;
  if (inputs.empty()) throw invalidArgument("no scans to merge", {"mergeScans", 0, "inputs"});
  double step = std::numeric_limits<double>::infinity();
  double range_max = 0.0;
  bool intensities = true;
  for (const PlacedScan& in : inputs) {
    if (!in.scan) throw invalidArgument("null scan", {"mergeScans", 0, "inputs"});
    step = std::min(step, std::abs(in.scan->angleIncrement()));
    range_max = std::max(range_max, in.scan->rangeMax() + in.T_robot_laser.translation().norm());
    intensities = intensities && in.scan->hasIntensities();
  }
  // The tolerance absorbs a step stored as a float (pi/180 in a LaserScan message: 2 pi / step is
  // 360.000004).
  const double n_real = std::ceil(kTwoPi / step - 1e-3);
  if (!(n_real <= static_cast<double>(LaserScan::kMaxBeams)))
    throw invalidArgument(fmt::format("merged scan would have {:.0f} beams (angle step {} rad)", n_real, step),
                          {"mergeScans", 0, "angle_increment"});
  const auto n = static_cast<std::size_t>(std::max(1.0, n_real));
  const double inc = kTwoPi / static_cast<double>(n);

  LaserScanFields f;
  f.time = time;
  f.angle_min = -std::numbers::pi;
  f.angle_increment = inc;
  f.range_min = 0.0;
  f.range_max = range_max;
  f.ranges.assign(n, std::numeric_limits<double>::quiet_NaN());
  if (intensities) f.intensities.assign(n, 0.0);
  // The beam whose angle is nearest the bearing of p (robot frame).
  auto beamOf = [&](const Eigen::Vector2d& p) {
    const double k = std::round((std::atan2(p.y(), p.x()) + std::numbers::pi) / inc);
    return static_cast<std::size_t>(k) % n;  // k = n is the bearing +pi, beam 0
  };
  for (const PlacedScan& in : inputs) {
    const LaserScan& s = *in.scan;
    const SE2& T = in.T_robot_laser;
    for (std::size_t i = 0; i < s.size(); ++i) {
      const double a = s.angle(i);
      const Eigen::Vector2d dir(std::cos(a), std::sin(a));
      if (s.isValid(i)) {
        const Eigen::Vector2d p = T * (s.ranges()[i] * dir);
        const double r = p.norm();
        const std::size_t k = beamOf(p);
        // A return beats "no return" and NaN; the nearest return wins (it occludes the others).
        if (!(f.ranges[k] < range_max) || r < f.ranges[k]) {
          f.ranges[k] = r;
          if (intensities) f.intensities[k] = s.intensities()[i];
        }
      } else if (s.ranges()[i] >= s.rangeMax()) {
        // No return: free up to range_max along the beam; its far end gives the merged beam.
        const std::size_t k = beamOf(T * (s.rangeMax() * dir));
        if (std::isnan(f.ranges[k])) f.ranges[k] = range_max;
      }
    }
  }
  return LaserScan::create(std::move(f));
}

namespace internal {
namespace {

// The first laser's frames, each with the nearest-in-time scan of every other laser merged in.
// Each laser is read by its own reader over the same log (the log is read once per laser, in step).
class MergedLasers final : public FrameSource {
 public:
  MergedLasers(const std::string& path, std::vector<std::unique_ptr<FrameSource>> lasers,
               std::vector<std::string> names, double tolerance_s)
      : path_(path), names_(std::move(names)), tolerance_s_(tolerance_s), lasers_(std::move(lasers)),
        buffers_(lasers_.size()), exhausted_(lasers_.size(), false), unpaired_(lasers_.size(), 0) {}

  std::optional<Frame> next() override {
    while (std::optional<Frame> first = lasers_[0]->next()) {
      ++first_read_;
      std::vector<Frame> partners;
      bool all = true;
      for (std::size_t j = 1; j < lasers_.size() && all; ++j) {
        std::optional<Frame> p = nearest(j, first->time);
        if (!p) {
          ++unpaired_[j];
          all = false;
        } else {
          partners.push_back(std::move(*p));
        }
      }
      if (!all) continue;
      return merge(std::move(*first), partners);
    }
    return std::nullopt;
  }

  LogFormat format() const override { return lasers_[0]->format(); }
  const std::string& path() const override { return path_; }
  std::optional<std::size_t> sizeHint() const override { return lasers_[0]->sizeHint(); }
  SourceNotes notes() const override {
    SourceNotes n = lasers_[0]->notes();
    std::string sources;
    for (std::size_t j = 0; j < lasers_.size(); ++j) {
      const SourceNotes nj = j == 0 ? n : lasers_[j]->notes();
      sources += fmt::format("{}{}", j == 0 ? "" : " + ", nj.scan_source.empty() ? names_[j] : nj.scan_source);
      if (j > 0) n.warnings.insert(n.warnings.end(), nj.warnings.begin(), nj.warnings.end());
    }
    n.scan_source = fmt::format("{} lasers merged into one 360-degree scan at the robot's origin: {}", lasers_.size(),
                                sources);
    for (std::size_t j = 1; j < lasers_.size(); ++j)
      if (unpaired_[j] > 0)
        n.warnings.push_back(fmt::format("{} of {} scans of {} had no scan of {} within {} s: left out", unpaired_[j],
                                         first_read_, names_[0], names_[j], tolerance_s_));
    if (uncompensated_ > 0)
      n.warnings.push_back(fmt::format("{} merged scans without odometry on both sides: the other lasers' scans were "
                                       "not moved by the robot's motion between their times",
                                       uncompensated_));
    return n;
  }

 private:
  // The scan of laser j nearest in time to t within the tolerance. Reads ahead until a scan later
  // than t + tolerance (times increasing; a log whose times go back pairs fewer scans).
  std::optional<Frame> nearest(std::size_t j, double t) {
    std::deque<Frame>& buf = buffers_[j];
    while (!buf.empty() && buf.front().time < t - tolerance_s_) buf.pop_front();
    while (!exhausted_[j] && (buf.empty() || buf.back().time <= t + tolerance_s_)) {
      std::optional<Frame> f = lasers_[j]->next();
      if (!f) {
        exhausted_[j] = true;
        break;
      }
      if (f->time >= t - tolerance_s_) buf.push_back(std::move(*f));
    }
    const Frame* best = nullptr;
    for (const Frame& f : buf)
      if (std::abs(f.time - t) <= tolerance_s_ && (!best || std::abs(f.time - t) < std::abs(best->time - t))) best = &f;
    if (!best) return std::nullopt;
    return *best;
  }

  Frame merge(Frame first, const std::vector<Frame>& partners) {
    std::vector<PlacedScan> inputs{{&first.scan, first.T_robot_laser}};
    for (const Frame& p : partners) {
      // The partner's laser at the first scan's time: T_robot(t0)_robot(t1) * T_robot_laser, with the
      // robot's motion between the two times from odometry.
      SE2 T_r0_r1;
      if (first.T_odom_robot && p.T_odom_robot) {
        T_r0_r1 = first.T_odom_robot->inverse() * *p.T_odom_robot;
      } else if (p.time != first.time) {
        ++uncompensated_;
      }
      inputs.push_back({&p.scan, T_r0_r1 * p.T_robot_laser});
    }
    Frame out;
    out.index = emitted_++;
    out.time = first.time;
    try {
      out.scan = mergeScans(inputs, first.time);
    } catch (const Error& e) {
      throw badInput(e.message(), {path_, 0, e.where().field});
    }
    out.T_odom_robot = first.T_odom_robot;
    out.T_world_robot = first.T_world_robot;
    return out;  // T_robot_laser identity: the merged scan is at the robot's origin
  }

  std::string path_;
  std::vector<std::string> names_;
  double tolerance_s_;
  std::vector<std::unique_ptr<FrameSource>> lasers_;
  std::vector<std::deque<Frame>> buffers_;
  std::vector<bool> exhausted_;
  std::vector<std::size_t> unpaired_;
  std::size_t first_read_ = 0, emitted_ = 0, uncompensated_ = 0;
};

}  // namespace

std::unique_ptr<FrameSource> openMergedLasers(const std::string& path, const ReaderOptions& options,
                                              const std::function<std::unique_ptr<FrameSource>(const ReaderOptions&)>& open) {
  const ErrorLocation where(path, 0, "lasers");
  if (!(options.laser_sync_tolerance_s > 0.0 && std::isfinite(options.laser_sync_tolerance_s)))
    throw invalidArgument("the lasers' time tolerance must be a finite number > 0",
                          {"ReaderOptions", 0, "laser_sync_tolerance_s"});
  if (!options.laser_mounts.empty() && options.laser_mounts.size() != options.lasers.size())
    throw invalidArgument(fmt::format("{} laser mountings for {} lasers: give one per laser, or none to take them "
                                      "from the log",
                                      options.laser_mounts.size(), options.lasers.size()),
                          {"ReaderOptions", 0, "laser_mounts"});
  if (options.laser_mount)
    throw invalidArgument("one laser_mount for several lasers: give laser_mounts, one per laser",
                          {"ReaderOptions", 0, "laser_mount"});
  if (options.range_table) throw badInput("a range table holds one laser; there is nothing to merge", where);
  std::vector<std::unique_ptr<FrameSource>> sources;
  for (std::size_t j = 0; j < options.lasers.size(); ++j) {
    const std::string& name = options.lasers[j];
    for (std::size_t i = 0; i < j; ++i)
      if (options.lasers[i] == name) throw badInput(fmt::format("laser '{}' is listed twice", name), where);
    ReaderOptions o = options;
    o.lasers.clear();
    o.laser_mounts.clear();
    o.scan_topic = name;
    o.carmen_laser = name;
    o.laser_mount.reset();
    if (!options.laser_mounts.empty()) o.laser_mount = options.laser_mounts[j];
    o.require_laser_mount = true;
    sources.push_back(open(o));
    if (sources.back()->format() == LogFormat::kRangeTable)
      throw badInput("a range table holds one laser; there is nothing to merge", where);
  }
  return std::make_unique<MergedLasers>(path, std::move(sources), options.lasers, options.laser_sync_tolerance_s);
}

}  // namespace internal
}  // namespace lidar2d::io
