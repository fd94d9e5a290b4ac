#pragma once
// Factories of the concrete readers; only open_log.cpp and the tests call them directly.

#include <cstddef>
#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "lidar2d/core/error.hpp"
#include "lidar2d/core/laser_mount.hpp"
#include "lidar2d/core/laser_scan.hpp"
#include "lidar2d/io/frame_source.hpp"

namespace lidar2d::io::internal {

std::unique_ptr<FrameSource> openCarmen(const std::string& path, const ReaderOptions& options);
std::unique_ptr<FrameSource> openRosbag1(const std::string& path, const ReaderOptions& options);
std::unique_ptr<FrameSource> openRosbag2(const std::string& path, const ReaderOptions& options);
/// A range table: `files` (ReaderOptions::range_table, or the three files of a folder).
std::unique_ptr<FrameSource> openRangeTable(const RangeTableFiles& files);
/// The three files of a range table folder (poses.txt, angles.txt, ranges.txt).
RangeTableFiles rangeTableFolder(const std::string& dir);

/// Two or more lasers (options.lasers) merged into one scan per frame (io/laser_merge.hpp): each laser
/// read by `open` with the options of that laser alone (scan_topic and carmen_laser its name, its
/// laser_mounts entry as laser_mount, require_laser_mount set). Throws lidar2d::Error naming `path`
/// for a laser listed twice or a range table, kInvalidArgument for a tolerance that is not > 0, a
/// count of mountings other than the lasers', or a single laser_mount; `open`'s errors (an unknown topic) pass through.
std::unique_ptr<FrameSource> openMergedLasers(const std::string& path, const ReaderOptions& options,
                                              const std::function<std::unique_ptr<FrameSource>(const ReaderOptions&)>& open);

/// The mounting frames get from `mount` (described as `what`, e.g. "base_link -> laser from
/// /tf_static") under ReaderOptions' tilt rule: level within `options.max_laser_tilt_deg` (tilt
/// dropped); beyond it projected when `options.allow_tilted_laser`, with a note in `warnings`;
/// else a kBadInput error at `where`. Also refuses tilts beyond LaserMount::kMaxProjectableTilt.
LaserMount applyTiltRule(const LaserMount& mount, const ReaderOptions& options, const ErrorLocation& where,
                         const std::string& what, std::vector<std::string>& warnings);
/// Fills the informational mounting fields of `frame` and its scan from `mount` (the result of
/// applyTiltRule): the scan projected, T_robot_laser, laser_upside_down and laser_tilt_rad.
void mountFrame(Frame& frame, const LaserMount& mount);

/// `scan` with another range max: validity recomputed from its raw readings (which scans keep).
/// Throws what LaserScan::create throws (a range max not above range_min).
LaserScan withRangeMax(const LaserScan& scan, double range_max);

/// The readings of a log's scans at or beyond their range max, counted by value. The most frequent
/// is the log's no-return code (a laser writes one value for "no return": 51.15 m in edmonton's log,
/// 81.91 m in freiburg-079's); readings more than kCodeTolerance (relative) from it are returns that
/// the range max drops (edmonton declares 10 m and reads walls to 45 m). Used by the CARMEN reader
/// to decide its range max and by openLog to warn; bounded memory on any log.
class BeyondRangeMax {
 public:
  static constexpr double kCodeTolerance = 0.01;  ///< relative distance to the code still read as it
  static constexpr double kShare = 0.01;          ///< share of the beams that contradicts a range max

  void add(const LaserScan& scan);
  std::size_t beams() const { return beams_; }
  /// The no-return code: the most frequent reading at or beyond the range max (none: no such reading).
  std::optional<double> code() const;
  /// Readings at or beyond the range max that are not the code: returns the range max drops.
  std::size_t returns() const;
  /// True when returns() are at least kShare of beams(): the range max is below what the laser measures.
  bool contradicted() const;
  /// True when every reading that is not the code lies below it and the code is at least kShare of
  /// beams(): a no-return value above every return (not merely the commonest of spread-out returns),
  /// so a range max just under it (code x (1 - kCodeTolerance)) keeps every return.
  bool codeAboveReturns() const;

 private:
  // Distinct values kept (a code is one value; returns beyond a declared maximum spread over many).
  static constexpr std::size_t kMaxValues = 100000;
  std::map<double, std::size_t> over_;
  std::size_t beams_ = 0;
};

}  // namespace lidar2d::io::internal
