#pragma once
/// @file
/// Localization in a known map, scan by scan, without an initial pose (`lidar2d track`).
///
/// The first scans are placed by global localization (Localizer, one scan each); once a scan is
/// placed, every next scan is tracked: its prior is the last pose moved by the odometry's step
/// (or, without odometry, by the last step: constant velocity), the scan is matched to the map's
/// likelihood field from that prior (registration::matchLikelihoodField, Gauss-Newton with line
/// search) and the match is accepted only when the map explains it (Localizer::score at least
/// `min_track_score`: points on obstacles minus beams through obstacles; with odometry more, the
/// further the match moved from the prior: `correction_score_slope`) and the correction from the
/// prior stays plausible. A scan that fails is tried at once by global localization (a robot
/// carried elsewhere, "kidnapped", is found again); a global answer is taken only when it scores
/// `min_global_score` and `confirm_fixes` answers in a row agree with the odometry between them, or
/// at once when it scores `sure_fix_score`; an answer that contradicts dead reckoning from the last
/// placed scan (odometry) needs `confirm_fixes_against_odometry` answers.
/// Until then, or when global localization declines, the scan is
/// `lost` and the prior is kept for the next scans, up to `max_lost_scans`, after which only global
/// localization runs until it answers. A pose is never reported as `tracking` unless its match
/// passed the checks: an unchecked pose is `lost` (with a NaN pose).
///
/// With odometry, where the map cannot tell a match from the prior's position (with the match's
/// heading), that pose is taken (`prior_score_margin`), and a degenerate scan (a corridor) keeps
/// the odometry's position along the corridor, reported `lost` after `max_degenerate_path_m` of such
/// path until global localization confirms a match.
///
/// With odometry, where the map explains too little of a scan (a place the map lacks, its edge),
/// the scan is matched against the last few placed scans too (`recent_scans`) and tracked when the
/// map and those scans together explain it, for up to `max_beyond_map_m` of path since the map
/// alone last explained a scan (TrackResult::beyond_map).
///
/// Memory is constant over any log length: the tracker keeps the map's field, the localizer, the
/// last pose, odometry and step, and the points of the last `recent_scans` placed scans.
///
/// Frames: `T_world_robot` in the map's world frame; odometry `T_odom_robot` in any frame (only
/// its steps are used).

#include <cstddef>
#include <memory>
#include <numbers>
#include <optional>
#include <string>

#include "lidar2d/core/frame.hpp"
#include "lidar2d/core/occupancy_image.hpp"
#include "lidar2d/core/se2.hpp"
#include "lidar2d/localization/localizer.hpp"
#include "lidar2d/registration/likelihood_field.hpp"

namespace lidar2d::localization {

/// Options of the tracker. `validate()` throws `lidar2d::Error` (kInvalidArgument) naming the
/// first field out of its domain.
struct TrackerOptions {
  LocalizerOptions localizer;  ///< global localization (first fix, recovery)
  DatabaseOptions database;    ///< database built when none is given
  /// Likelihood field of the map for tracking; fromMap's defaults with the line search on.
  registration::LikelihoodFieldOptions field = trackingField();
  std::size_t max_points = 240;  ///< scan points (evenly subsampled) used to match and score a tracked scan, >= 10
  double min_track_score = 0.5;  ///< a tracked match explaining less of the scan than this (Localizer::score) fails, in [0, 1]
  /// With odometry, a tracked match must also explain min_track_score + this x its correction (the
  /// larger of the distance and the turn from the prior, each as a share of max_correction_m /
  /// max_correction_rad): a match that moved far from a good prior needs more evidence, in [0, 1]
  double correction_score_slope = 0.3;
  /// Without odometry, a tracked match must have no rival along its weakest direction (the smallest
  /// eigenvector of the match's translational information): matched again from the pose moved 0.5
  /// or 1 m either way along it, a result 0.25 m or more from the match that scores within this of
  /// it fails the match ("slides"), and the scan goes to global localization. A keyframe log's prior
  /// after a fix is the fix itself, a metre behind, and along a corridor with a few doors the match
  /// settles there. In [0, 1]; 0: off
  double slide_score_margin = 0.05;
  /// With odometry, a tracked match whose position moved more than twice the localizer's
  /// hit_distance_m from the prior is compared with the pose at the prior's position with the
  /// match's heading: when that pose explains the scan
  /// (Localizer::score) within this of the match, the map cannot tell them apart and it is taken
  /// instead. Along a corridor with look-alike doors, small slides of the match each pass the other
  /// checks and add up, since the next prior starts from the last. In [0, 1]; 0: off
  double prior_score_margin = 0.05;
  /// A global fix scoring below this is not taken (the scan stays `lost`): stricter than the
  /// localizer's own min_score, because the scans after a fix are tracked from it, and a wrong fix
  /// in a part of the building the map lacks (a room like a mapped one) would be tracked on, in [0, 1]
  double min_global_score = 0.7;
  /// Global answers in a row, each consistent with the previous moved by the prior's step (within
  /// max_correction_m / max_correction_rad, doubled), needed before a fix is taken; the scans before it are
  /// `lost`. One wrong answer in a place the map lacks is common; the same wrong place found again
  /// and again in agreement with odometry is not. >= 1
  std::size_t confirm_fixes = 3;
  /// A global answer scoring at least this is taken at once, without confirmation (a scan the map
  /// explains this well is rarely placed wrong; the first fix then needs no second scan), in
  /// [0, 1]; above 1: off
  double sure_fix_score = 0.9;
  /// A global answer that contradicts dead reckoning (the last checked pose moved by the odometry
  /// since, within twice max_correction_m / max_correction_rad plus `dead_reckoning_drift_per_m`
  /// and `dead_reckoning_drift_rad_per_m` per metre of odometry path) needs this many agreeing
  /// answers in a row, and is never taken at once on its score: a place the map lacks that looks
  /// like a mapped one tens of metres away gave three consistent answers on freiburg-079, while a
  /// robot really carried elsewhere (kidnapped) goes on giving them. Without odometry every answer
  /// needs this many (no dead reckoning vouches for it; one scoring sure_fix_score is still taken at
  /// once); with odometry before the first fix, confirm_fixes applies; never fewer than
  /// confirm_fixes. >= 1
  std::size_t confirm_fixes_against_odometry = 6;
  double dead_reckoning_drift_per_m = 0.2;                                 ///< [m/m], >= 0
  double dead_reckoning_drift_rad_per_m = 5.0 * std::numbers::pi / 180.0;  ///< [rad/m], >= 0
  /// A match moving the pose farther than this from its prior fails (the prior, from odometry or
  /// constant velocity, is not that wrong between two scans; a larger jump is a wrong minimum) [m], > 0
  double max_correction_m = 0.5;
  double max_correction_rad = 15.0 * std::numbers::pi / 180.0;  ///< the same for the heading [rad], > 0
  /// Failed scans in a row after which the prior is dropped and only global localization runs, >= 1
  std::size_t max_lost_scans = 5;
  /// Without odometry, the fastest the robot may have moved since its last checked pose: a global
  /// answer farther from the prior carried since than this speed over the time since (plus twice
  /// max_correction_m) is not a fix on its score alone (sure_fix_score) until the prior is dropped;
  /// it needs confirm_fixes_against_odometry agreeing answers. Unused where the scans' times do not
  /// increase. [m/s], > 0 (the same bound as slam's max_speed_m_per_s)
  double max_speed_m_per_s = 5.0;
  /// With odometry, a scan whose map match fails (the map explains too little of it: a room the map
  /// lacks, the map's edge, a turn in place facing unmapped ground) is matched against the last this
  /// many placed scans (ICP from the prior), and tracked when the map and those scans together
  /// explain enough of it (Localizer::score, a point near a recent scan's point counting as
  /// explained; the same min_track_score and correction_score_slope) and the map contradicts it
  /// nowhere more than the score allows (beams through the map's walls). 0: off (such scans are lost)
  std::size_t recent_scans = 10;
  /// Path [m] (odometry) since the map alone last explained a scan, beyond which a scan the map does
  /// not explain is no longer tracked on the recent scans (they drift by about 1-2% of the path),
  /// > 0
  double max_beyond_map_m = 10.0;
  /// With odometry, a degenerate scan (degeneracy::analyze: a corridor) keeps its prior's position
  /// along the corridor (degeneracy::constrainMatch); the map places it across. After this much
  /// odometry path over such scans in a row [m], the position along the corridor is the odometry's
  /// alone and the scans are reported `lost` (the pose goes on, and the first scan the map pins again
  /// is tracked from it). The default allows the odometry 5% of drift before a pose 0.5 m off would be
  /// reported. >= 0; 0: off (the map match places degenerate scans along the corridor too)
  double max_degenerate_path_m = 10.0;
  /// With odometry, the odometry's steps are scaled by the metres the map matches measured per
  /// metre of odometry (Tracker::odometryScale): on chords of 0.5 m of odometry path along runs of
  /// scans the map pinned in every direction (tracked, not degenerate, not on the recent scans), the
  /// last ~100 m of them weighing most; once 5 m of chords are measured, within 0.9-1.1. Along a
  /// corridor the position is the odometry's alone (max_degenerate_path_m), and a wheel radius 2%
  /// off puts it 2 cm per metre behind or ahead. false: the odometry's distances as read (nothing
  /// measured)
  bool learn_odometry_scale = true;
  void validate() const;
  static registration::LikelihoodFieldOptions trackingField() {
    registration::LikelihoodFieldOptions o;
    o.line_search = true;
    return o;
  }
};

/// What placed a scan.
enum class TrackStatus {
  kGlobal,    ///< global localization (first fix or a recovery)
  kTracking,  ///< scan-to-map match from the prior, checked
  kLost,      ///< no checked pose (T_world_robot is NaN)
};

/// "global", "tracking" or "lost".
const char* toString(TrackStatus status);

/// The answer for one scan.
struct TrackResult {
  TrackStatus status = TrackStatus::kLost;
  SE2 T_world_robot;     ///< pose in the map's world frame; NaN when lost
  /// Localizer::score of the pose (0 when lost; beyond_map: the map and the recent scans together), in [0, 1]
  double score = 0.0;
  bool relocalized = false;  ///< a global fix after an earlier fix (a recovery, not the first fix)
  /// The odometry keeps reading one pose while the robot moves (Tracker::add): not used, as if the
  /// scan had none, until it reads another pose
  bool odometry_frozen = false;
  /// `tracking` on the recent scans where the map explains too little (TrackerOptions::recent_scans):
  /// the pose chains from the last scan the map placed, and drifts
  bool beyond_map = false;
  std::string reason;    ///< why a scan was not tracked ("no fix yet", "low score", "jump", "not converged", ...)
  int iterations = 0;    ///< likelihood-field iterations of the tracking match (0 if none)
  double track_ms = 0.0;   ///< time of the tracking match and its score [ms]
  double global_ms = 0.0;  ///< time of global localization on this scan (0 if it did not run) [ms]
};

/// Tracks one robot in one map. Non-copyable; `add` is not thread-safe (one tracker per robot).
class Tracker {
 public:
  /// Builds the localizer (with `database`, or a database built in memory from
  /// `options.database`) and the tracking field of `map`. Throws `lidar2d::Error`: kInvalidArgument
  /// for bad options; kBadInput when the map has no free space or the database belongs to another
  /// map (field "map checksum").
  explicit Tracker(const OccupancyImage& map, std::optional<Database> database = std::nullopt,
                   const TrackerOptions& options = {});
  ~Tracker();
  Tracker(const Tracker&) = delete;
  Tracker& operator=(const Tracker&) = delete;

  /// Places the next scan of the robot (`frame.scan` through `frame.T_robot_laser`; its
  /// `T_odom_robot`, when present on this and the previous frame, gives the prior's step; its
  /// truth is ignored). Never throws for bad data: a scan without valid beams is `lost`.
  TrackResult add(const Frame& frame);
  /// Forgets the pose (the next scan is placed by global localization).
  void reset();

  const Localizer& localizer() const;
  const TrackerOptions& options() const;
  /// The factor the odometry's distances are scaled by (TrackerOptions::learn_odometry_scale): 1
  /// until 5 m of chords between pinned scans are measured, or when the option is off.
  double odometryScale() const;
  /// Metres of odometry chords the scale is measured over (fading with ~100 m).
  double odometryScaleEvidenceM() const;

 private:
  struct State;
  std::unique_ptr<State> s_;
};

}  // namespace lidar2d::localization
