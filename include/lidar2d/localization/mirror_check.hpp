#pragma once
/// @file
/// Tells scans and a map that are mirror images of each other from a map that lacks the place.
///
/// A laser mounted upside down but read as upright (or the other way round) records the mirror image
/// of the room; so does an upright laser in a map image stored with its rows reversed (an array
/// written as it is indexed, row 0 at the lowest y, where map_server's first row is the top). Either
/// way every scan is declined and nothing says why. `MirrorCheck` keeps an even sample of the scans a
/// localizer could not place and localizes their mirror images (beam angles negated, as
/// LaserMount::project mirrors an upside-down laser's scan): a mirror image of a scan is congruent to
/// the scan mirrored about any other line, so one test covers both causes. Where the mirror images
/// are placed and the scans were not, the caller says so (`lidar2d localize`, `lidar2d track`).

#include <cstddef>
#include <optional>
#include <vector>

#include "lidar2d/core/laser_scan.hpp"
#include "lidar2d/core/se2.hpp"
#include "lidar2d/localization/localizer.hpp"

namespace lidar2d::localization {

/// What the mirror images of the sampled scans gave.
struct MirrorCheckResult {
  std::size_t tried = 0;   ///< sampled scans localized as their mirror image
  std::size_t placed = 0;  ///< of them, answered (not declined) by the localizer
  /// At least `MirrorCheck::kMinTried` tried and at least two thirds of them placed. (A scan from a
  /// place the map lacks is answered, wrongly, a third of the time at most on the benchmark's half
  /// maps; a mirror image of a mapped place is answered like the scan itself, 95-100%.)
  bool mirrored() const { return tried >= kMinTried && 3 * placed >= 2 * tried; }
  static constexpr std::size_t kMinTried = 4;
};

/// An even sample, over the whole log, of the scans a localizer could not place; then their mirror
/// images localized. Memory: at most 2 x `max_samples` scans, whatever the log's length.
class MirrorCheck {
 public:
  /// `max_samples` >= 1: scans localized by `run` (it takes up to 40 ms each).
  explicit MirrorCheck(std::size_t max_samples = 12);

  /// One scan the localizer could not place, with its mounting (the frame's T_robot_laser; the scan
  /// as the frame holds it, already mirrored for a laser known to be upside down). Every
  /// `stride`-th is kept; when the sample is full, every other one is dropped and the stride doubles.
  void add(const LaserScan& scan, const SE2& T_robot_laser);
  /// Scans given to `add`.
  std::size_t added() const { return added_; }

  /// Localizes the mirror image of up to `max_samples` of the kept scans, spread evenly. Thread-safe
  /// as Localizer::localize is.
  MirrorCheckResult run(const Localizer& localizer) const;
  /// `run`, for a log of `scans` scans of which every one not placed was given to `add`, when fewer
  /// than `kCheckBelow` of them were placed and at least MirrorCheckResult::kMinTried were not
  /// (a log most of whose scans are placed is neither mirrored nor worth a dozen more queries);
  /// otherwise std::nullopt.
  std::optional<MirrorCheckResult> runIfFewPlaced(const Localizer& localizer, std::size_t scans) const;
  static constexpr double kCheckBelow = 0.2;  ///< share of the scans placed

 private:
  struct Sample {
    LaserScan scan;
    SE2 T_robot_laser;
  };
  std::size_t max_samples_;
  std::size_t added_ = 0;
  std::size_t stride_ = 1;
  std::vector<Sample> kept_;
};

}  // namespace lidar2d::localization
