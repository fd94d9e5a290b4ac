// CARMEN text-log reader (.log / .clf, plain or gzip-compressed): the events of
// carmen_messages.cpp turned into frames (odometry, truth and their sources decided per log).
//
// Rules chosen here (documented for users in frame_source.hpp and in notes()):
// - Scan time = ipc_timestamp; file order is kept even when times repeat or go backwards.
// - TRUEPOS gives the truth of the laser message with the same timestamp (|dt| <= 1 us): the
//   latest laser message before it, else the next laser message after it. A TRUEPOS matching
//   neither is ignored and counted in a warning.
// - Odometry from ODOM lines: interpolated at the scan time between the last ODOM line before the
//   laser message and the first one after it (file order). When their times do not bracket the
//   scan time, the one closer in time is used (ties: the earlier one); with only one of them, that
//   one. Scans wait in a look-ahead buffer (at most kMaxPending) for the next ODOM line.
// - CarmenPoses::kAuto without TRUEPOS: the first kPrescanScans laser messages are read once to
//   compare the relative motion between consecutive laser poses with that of the ODOM lines
//   interpolated at the same times. Median disagreement above kAgreeTransM or kAgreeRotRad means
//   the laser poses were corrected by a SLAM system (Radish corrected logs: 4-7 cm median
//   disagreement); then they are truth and odometry comes from the ODOM lines. Otherwise (or
//   without ODOM lines) the laser message's odometry triple is odometry and there is no truth.

#include <algorithm>
#include <cctype>
#include <cmath>
#include <deque>
#include <fmt/format.h>
#include <map>
#include <numbers>
#include <optional>
#include <string>
#include <vector>

#include "lidar2d/core/error.hpp"
#include "src/io/internal/carmen_messages.hpp"
#include "src/io/internal/readers.hpp"

namespace lidar2d::io::internal {
namespace {

using carmen::Event;
using carmen::EventReader;
using carmen::LaserKind;
using carmen::LaserMsg;
using carmen::LaserType;
using carmen::OdomSample;

constexpr std::size_t kPrescanScans = 300;         // laser messages read to decide kAuto
constexpr std::size_t kMaxPending = 1000;          // look-ahead bound (scans waiting for an ODOM line)
constexpr double kAgreeTransM = 0.02;              // [m] median relative-motion disagreement bound
constexpr double kAgreeRotRad = 1.0 * std::numbers::pi / 180.0;  // [rad] same, rotation
constexpr double kSameTimeS = 1e-6;                // [s] TRUEPOS / writer ODOM time match

// Odometry at time t from the ODOM lines before (prev) and after (next) a scan in file order.
// Sets `bracketed` to false when the times did not bracket t and the closer line was taken.
std::optional<SE2> odomAt(const std::optional<OdomSample>& prev, const std::optional<OdomSample>& next, double t,
                          bool& bracketed) {
  bracketed = true;
  if (!prev && !next) return std::nullopt;
  if (!prev) return next->pose;  // before the first ODOM line
  if (!next) return prev->pose;  // after the last one
  if (prev->time <= t && t <= next->time) {
    const double dt = next->time - prev->time;
    return dt > 0 ? interpolate(prev->pose, next->pose, (t - prev->time) / dt) : prev->pose;
  }
  bracketed = false;
  return std::abs(next->time - t) < std::abs(prev->time - t) ? next->pose : prev->pose;
}

enum class OdomFrom { kNone, kLaserOdom, kOdomLines, kWriterOdomLine };
enum class TruthFrom { kNone, kLaserPose, kTruepos };

struct Decision {
  const LaserType* type = nullptr;
  OdomFrom odom = OdomFrom::kNone;
  TruthFrom truth = TruthFrom::kNone;
  std::string odom_source, truth_source;
  // The laser's readings contradict the log's range max (`declared_range_max`, of the first scan):
  // the scans that carry it are read with `range_max`, and `range_note` says why.
  std::optional<double> declared_range_max, range_max;
  std::string range_note;
};

// The range max from the laser's own readings, when they contradict the log's. A CARMEN log's
// range max is a setting of the program that wrote it (PARAM robot_front_laser_max is a parameter
// of CARMEN's robot module; FLASER carries none and gets 80 m): edmonton's declares 10 m while its
// SICK reads walls to 45 m and writes 51.15 m for no return, and the declared 10 m dropped 29% of
// the beams, half the building (SLAM with perfect odometry 0.99 m ATE against 0.35 m read to the
// no-return code: BENCHMARK.md, SLAM). Replaced only when the first scans prove it: at least
// BeyondRangeMax::kShare of their beams read beyond it, and a no-return code lies above every such
// reading (the range max then sits just under the code). Otherwise openLog's warning remains.
void decideRangeMax(const BeyondRangeMax& beyond, std::size_t scans, Decision& d) {
  if (!d.declared_range_max || !beyond.contradicted() || !beyond.codeAboveReturns()) return;
  const double code = *beyond.code();
  const double range_max = code * (1.0 - BeyondRangeMax::kCodeTolerance);
  if (!(range_max > *d.declared_range_max)) return;
  d.range_max = range_max;
  d.range_note = fmt::format(
      "the log's range max ({:.2f} m) is below what its laser measured: {:.1f}% of the beams of its first {} scans "
      "read beyond it, under the no-return reading {:.2f} m; read with the range max {:.2f} m (--laser-range-max "
      "{:g} keeps the log's)",
      *d.declared_range_max, 100.0 * static_cast<double>(beyond.returns()) / static_cast<double>(beyond.beams()),
      scans, code, range_max, *d.declared_range_max);
}

double median(std::vector<double> v) {
  if (v.empty()) return 0.0;
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2), v.end());
  return v[v.size() / 2];
}

const LaserType* requestedType(const std::string& name) {
  if (name.empty()) return nullptr;
  std::string upper = name;
  std::transform(upper.begin(), upper.end(), upper.begin(), [](unsigned char c) { return std::toupper(c); });
  const LaserType* t = carmen::laserType(upper);
  if (!t)
    throw invalidArgument(fmt::format("unknown CARMEN laser message '{}' (expected FLASER, RLASER, ROBOTLASER1, "
                                      "ROBOTLASER2 or RAWLASER1-4)",
                                      name));
  return t;
}

// Reads the start of the log once to pick the laser message type and the meaning of its poses.
Decision decide(const std::string& path, const ReaderOptions& options) {
  EventReader reader(path, requestedType(options.carmen_laser));
  bool marker = false, any_laser = false, odom_lines = false, truepos = false;
  struct Seen {
    double time;
    SE2 pose;
    std::optional<OdomSample> prev, next;
  };
  std::vector<Seen> seen;
  std::optional<OdomSample> last_odom;
  std::size_t lasers = 0;
  std::optional<double> first_range_max;
  BeyondRangeMax beyond;
  Event ev;
  while (lasers < kPrescanScans && reader.next(ev)) {
    switch (ev.kind) {
      case Event::kMarker:
        if (!any_laser) marker = true;
        break;
      case Event::kLaser:
        any_laser = true;
        ++lasers;
        if (ev.laser.pose) seen.push_back({ev.laser.time, *ev.laser.pose, last_odom, std::nullopt});
        if (!first_range_max) first_range_max = ev.laser.scan.rangeMax();
        if (ev.laser.scan.rangeMax() == *first_range_max) beyond.add(ev.laser.scan);
        break;
      case Event::kOtherLaser:
        any_laser = true;
        break;
      case Event::kOdom:
        odom_lines = true;
        for (auto it = seen.rbegin(); it != seen.rend() && !it->next; ++it) it->next = ev.sample;
        last_odom = ev.sample;
        break;
      case Event::kTruth:
        truepos = true;
        break;
      case Event::kNone:
        break;
    }
  }
  Decision d;
  d.type = reader.selected();
  if (!d.type) return d;  // no laser message: next() reports it
  if (!options.laser_range_max) {  // a range max the user gives replaces the log's anyway
    d.declared_range_max = first_range_max;
    decideRangeMax(beyond, lasers, d);
  }
  const std::string name(d.type->name);
  const bool has_pose = carmen::hasPoseFields(*d.type);
  const bool robot = d.type->kind == LaserKind::kRobot;
  const std::string odom_triple = robot ? name + " robot pose" : name + " odometry fields";
  auto odometryMode = [&](const std::string& why) {
    if (has_pose) {
      d.odom = OdomFrom::kLaserOdom;
      d.odom_source = odom_triple + why;
    } else if (odom_lines) {
      d.odom = OdomFrom::kOdomLines;
      d.odom_source = "ODOM lines (interpolated)";
    }
    if (truepos) {
      d.truth = TruthFrom::kTruepos;
      d.truth_source = "TRUEPOS";
    }
  };
  auto truthMode = [&](const std::string& why) {
    if (has_pose) {
      d.truth = TruthFrom::kLaserPose;
      d.truth_source = (robot ? name + " robot pose" : name + " pose less the laser mounting") + why;
    } else if (truepos) {
      d.truth = TruthFrom::kTruepos;
      d.truth_source = "TRUEPOS";
    }
    if (odom_lines) {
      d.odom = OdomFrom::kOdomLines;
      d.odom_source = "ODOM lines (interpolated)";
    }
  };
  switch (options.carmen_poses) {
    case CarmenPoses::kOdometry:
      odometryMode(" (--carmen-poses odometry)");
      return d;
    case CarmenPoses::kTruth:
      truthMode(" (--carmen-poses truth)");
      return d;
    case CarmenPoses::kAuto:
      break;
  }
  if (marker) {
    d.odom = OdomFrom::kWriterOdomLine;
    d.odom_source = name + " robot pose (lidar2d log: scans followed by an ODOM line)";
    d.truth = TruthFrom::kTruepos;
    d.truth_source = "TRUEPOS";
    return d;
  }
  if (truepos || !has_pose) {
    odometryMode("");
    return d;
  }
  if (!odom_lines) {
    odometryMode(" (no ODOM lines)");
    return d;
  }
  // Compare relative motions of consecutive laser poses with the ODOM lines at the same times.
  std::vector<double> dtrans, drot;
  std::optional<SE2> prev_pose, prev_odom;
  for (const auto& s : seen) {
    bool bracketed;
    const std::optional<SE2> o = odomAt(s.prev, s.next, s.time, bracketed);
    if (prev_pose && prev_odom && o) {
      const SE2 d_laser = prev_pose->inverse() * s.pose;
      const SE2 d_odom = prev_odom->inverse() * *o;
      dtrans.push_back(std::hypot(d_laser.x() - d_odom.x(), d_laser.y() - d_odom.y()));
      drot.push_back(std::abs(angleDiff(d_laser.theta(), d_odom.theta())));
    }
    prev_pose = s.pose;
    prev_odom = o;
  }
  const double mt = median(dtrans), mr = median(drot);
  if (mt > kAgreeTransM || mr > kAgreeRotRad) {
    truthMode(fmt::format(" (corrected log: its motion differs from the ODOM lines by {:.3f} m, {:.2f} deg median)",
                          mt, mr * 180.0 / std::numbers::pi));
  } else {
    odometryMode(fmt::format(" (agrees with the ODOM lines: {:.3f} m, {:.2f} deg median)", mt,
                             mr * 180.0 / std::numbers::pi));
  }
  return d;
}

// ---------------------------------------------------------------------------------------------

class CarmenSource final : public FrameSource {
 public:
  CarmenSource(std::string path, const ReaderOptions& options)
      : path_(std::move(path)), decision_(decide(path_, options)), reader_(path_, decision_.type) {
    requested_ = requestedType(options.carmen_laser);
  }

  std::optional<Frame> next() override {
    for (;;) {
      if (!pending_.empty() && (eof_ || ready(pending_.front()))) return emit();
      if (eof_) {
        if (emitted_ == 0) throw noScans();
        return std::nullopt;
      }
      pump();
    }
  }
  LogFormat format() const override { return LogFormat::kCarmen; }
  const std::string& path() const override { return path_; }
  SourceNotes notes() const override {
    SourceNotes n;
    if (decision_.range_max) n.warnings.push_back(decision_.range_note);
    if (decision_.type) {
      n.scan_source = std::string(decision_.type->name);
      n.lasers.push_back(fmt::format("{} ({} messages)", decision_.type->name, emitted_));
    }
    for (const auto& [name, count] : other_lasers_) n.lasers.push_back(fmt::format("{} ({} messages)", name, count));
    n.odom_source = decision_.odom_source;
    n.truth_source = decision_.truth_source;
    if (repeats_ || backwards_)
      n.warnings.push_back(fmt::format("timestamps repeat {} times; go backwards {} times", repeats_, backwards_));
    if (wrapped_)
      n.warnings.push_back(fmt::format("{} scans have timestamps near 2^32 s (e.g. 4294967296): negative times written "
                                       "as unsigned 32-bit numbers; time spans and gaps between them are meaningless",
                                       wrapped_));
    if (unbracketed_)
      n.warnings.push_back(fmt::format("odometry of {} scans taken from the nearer ODOM line, whose times do not "
                                       "bracket the scan time",
                                       unbracketed_));
    if (unmatched_truth_)
      n.warnings.push_back(fmt::format("{} TRUEPOS lines matched no laser message by timestamp", unmatched_truth_));
    if (forced_)
      n.warnings.push_back(fmt::format("{} scans had no ODOM line within the next {} scans", forced_, kMaxPending));
    if (!other_lasers_.empty()) {
      std::string others;
      for (const auto& [name, count] : other_lasers_) others += fmt::format("{}{} {}", others.empty() ? "" : ", ", count, name);
      n.warnings.push_back(fmt::format("skipped other laser messages: {}", others));
    }
    return n;
  }

 private:
  struct Pending {
    Frame frame;
    std::optional<SE2> pose, odom;
    std::optional<OdomSample> prev_odom, next_odom;
    bool next_laser_seen = false;
    bool writer_odom = false;
  };

  Error noScans() const {
    if (reader_.lineNo() == 0) return badInput("no laser scans found: the file is empty", {path_});
    if (requested_)
      return badInput(fmt::format("no {} scans found", requested_->name), {path_, reader_.lineNo()});
    return badInput("no laser scans found (looked for FLASER, RLASER, ROBOTLASER1, ROBOTLASER2, RAWLASER1-4)",
                    {path_, reader_.lineNo()});
  }

  bool ready(const Pending& p) const {
    if (pending_.size() > kMaxPending) return true;
    if (!p.next_laser_seen) return false;  // a TRUEPOS for it may still follow
    return decision_.odom != OdomFrom::kOdomLines || p.next_odom.has_value();
  }

  void pump() {
    if (!reader_.next(ev_)) {
      eof_ = true;
      if (held_truth_) ++unmatched_truth_;
      held_truth_.reset();
      return;
    }
    switch (ev_.kind) {
      case Event::kLaser:
        onLaser();
        break;
      case Event::kOdom:
        for (auto it = pending_.rbegin(); it != pending_.rend() && !it->next_odom; ++it) it->next_odom = ev_.sample;
        if (decision_.odom == OdomFrom::kWriterOdomLine && !pending_.empty() &&
            std::abs(pending_.back().frame.time - ev_.sample.time) <= kSameTimeS)
          pending_.back().writer_odom = true;
        last_odom_ = ev_.sample;
        break;
      case Event::kTruth:
        if (decision_.truth != TruthFrom::kTruepos) break;
        if (!pending_.empty() && !pending_.back().frame.T_world_robot &&
            std::abs(pending_.back().frame.time - ev_.sample.time) <= kSameTimeS) {
          pending_.back().frame.T_world_robot = ev_.sample.pose;
        } else {
          if (held_truth_) ++unmatched_truth_;
          held_truth_ = ev_.sample;
        }
        break;
      case Event::kOtherLaser:
        ++other_lasers_[std::string(ev_.laser_type->name)];
        break;
      case Event::kMarker:
      case Event::kNone:
        break;
    }
  }

  void onLaser() {
    if (!pending_.empty()) pending_.back().next_laser_seen = true;
    Pending p;
    LaserMsg& m = ev_.laser;
    if (count_ > 0) {
      if (m.time == prev_time_) ++repeats_;
      if (m.time < prev_time_) ++backwards_;
    }
    // Some converters wrote negative times through an unsigned 32-bit number: -2 s becomes
    // 2^32 - 2 s (infinite-corridor: 1937 scans at 4.29497e+09). No robot logged in 2106, and the
    // true value is lost to the 6 significant digits such logs print, so it is reported, not undone.
    if (std::abs(m.time - kTwoTo32) < kWrapWindow) ++wrapped_;
    prev_time_ = m.time;
    p.frame.index = count_++;
    p.frame.time = m.time;
    if (decision_.range_max && m.scan.rangeMax() == *decision_.declared_range_max)
      m.scan = withRangeMax(m.scan, *decision_.range_max);
    p.frame.scan = std::move(m.scan);
    p.frame.T_robot_laser = m.T_robot_laser;
    p.pose = m.pose;
    p.odom = m.odom;
    p.prev_odom = last_odom_;
    if (held_truth_) {
      if (std::abs(held_truth_->time - m.time) <= kSameTimeS)
        p.frame.T_world_robot = held_truth_->pose;
      else
        ++unmatched_truth_;
      held_truth_.reset();
    }
    pending_.push_back(std::move(p));
  }

  Frame emit() {
    Pending& p = pending_.front();
    if (decision_.odom == OdomFrom::kOdomLines && !p.next_odom && !eof_ && last_odom_) ++forced_;
    switch (decision_.odom) {
      case OdomFrom::kNone:
        break;
      case OdomFrom::kLaserOdom:
        p.frame.T_odom_robot = p.odom;
        break;
      case OdomFrom::kOdomLines: {
        bool bracketed;
        p.frame.T_odom_robot = odomAt(p.prev_odom, p.next_odom, p.frame.time, bracketed);
        if (!bracketed) {
          // Count only when the chosen ODOM line is not at the scan time itself.
          const double tp = p.prev_odom->time, tn = p.next_odom->time, t = p.frame.time;
          if (std::min(std::abs(tp - t), std::abs(tn - t)) > kSameTimeS) ++unbracketed_;
        }
        break;
      }
      case OdomFrom::kWriterOdomLine:
        if (p.writer_odom) p.frame.T_odom_robot = p.pose;
        break;
    }
    if (decision_.truth == TruthFrom::kLaserPose) p.frame.T_world_robot = p.pose;
    Frame f = std::move(p.frame);
    pending_.pop_front();
    ++emitted_;
    return f;
  }

  std::string path_;
  Decision decision_;
  EventReader reader_;
  const LaserType* requested_ = nullptr;
  Event ev_;
  std::deque<Pending> pending_;
  std::optional<OdomSample> last_odom_, held_truth_;
  std::map<std::string, std::size_t> other_lasers_;
  bool eof_ = false;
  std::size_t count_ = 0, emitted_ = 0;
  double prev_time_ = 0.0;
  static constexpr double kTwoTo32 = 4294967296.0;  ///< 2^32 [s]
  static constexpr double kWrapWindow = 1048576.0;  ///< 2^20 s (12 days) either side of 2^32
  std::size_t wrapped_ = 0;
  std::size_t repeats_ = 0, backwards_ = 0, unbracketed_ = 0, unmatched_truth_ = 0, forced_ = 0;
};

}  // namespace

std::unique_ptr<FrameSource> openCarmen(const std::string& path, const ReaderOptions& options) {
  return std::make_unique<CarmenSource>(path, options);
}

}  // namespace lidar2d::io::internal
