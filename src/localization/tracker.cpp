#include "lidar2d/localization/tracker.hpp"

#include <fmt/format.h>

#include <Eigen/Core>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <deque>
#include <functional>
#include <limits>
#include <memory>
#include <optional>
#include <utility>
#include <vector>

#include "lidar2d/core/error.hpp"
#include "lidar2d/degeneracy/degeneracy.hpp"
#include "lidar2d/registration/icp.hpp"
#include "src/localization/internal/database_index.hpp"

namespace lidar2d::localization {

using internal::badOption;

void TrackerOptions::validate() const {
  localizer.validate();
  database.validate();
  field.validate();
  if (max_points < 10) throw badOption("max_points", static_cast<double>(max_points));
  if (!(min_track_score >= 0 && min_track_score <= 1)) throw badOption("min_track_score", min_track_score);
  if (!(max_correction_m > 0) || !std::isfinite(max_correction_m)) throw badOption("max_correction_m", max_correction_m);
  if (!(max_correction_rad > 0) || !std::isfinite(max_correction_rad))
    throw badOption("max_correction_rad", max_correction_rad);
  if (!(min_global_score >= 0 && min_global_score <= 1)) throw badOption("min_global_score", min_global_score);
  if (!(correction_score_slope >= 0 && correction_score_slope <= 1))
    throw badOption("correction_score_slope", correction_score_slope);
  if (!(slide_score_margin >= 0 && slide_score_margin <= 1)) throw badOption("slide_score_margin", slide_score_margin);
  if (!(prior_score_margin >= 0 && prior_score_margin <= 1)) throw badOption("prior_score_margin", prior_score_margin);
  if (confirm_fixes < 1) throw badOption("confirm_fixes", static_cast<double>(confirm_fixes));
  if (confirm_fixes_against_odometry < 1)
    throw badOption("confirm_fixes_against_odometry", static_cast<double>(confirm_fixes_against_odometry));
  if (!(dead_reckoning_drift_per_m >= 0) || !std::isfinite(dead_reckoning_drift_per_m))
    throw badOption("dead_reckoning_drift_per_m", dead_reckoning_drift_per_m);
  if (!(dead_reckoning_drift_rad_per_m >= 0) || !std::isfinite(dead_reckoning_drift_rad_per_m))
    throw badOption("dead_reckoning_drift_rad_per_m", dead_reckoning_drift_rad_per_m);
  if (!(sure_fix_score >= 0) || std::isnan(sure_fix_score)) throw badOption("sure_fix_score", sure_fix_score);
  if (max_lost_scans < 1) throw badOption("max_lost_scans", static_cast<double>(max_lost_scans));
  if (!(max_speed_m_per_s > 0) || !std::isfinite(max_speed_m_per_s))
    throw badOption("max_speed_m_per_s", max_speed_m_per_s);
  if (!(max_beyond_map_m > 0) || !std::isfinite(max_beyond_map_m))
    throw badOption("max_beyond_map_m", max_beyond_map_m);
  if (!(max_degenerate_path_m >= 0) || std::isnan(max_degenerate_path_m))
    throw badOption("max_degenerate_path_m", max_degenerate_path_m);
}

const char* toString(TrackStatus status) {
  switch (status) {
    case TrackStatus::kGlobal: return "global";
    case TrackStatus::kTracking: return "tracking";
    case TrackStatus::kLost: return "lost";
  }
  return "lost";
}

namespace {

using Clock = std::chrono::steady_clock;
double msSince(Clock::time_point t0) { return std::chrono::duration<double, std::milli>(Clock::now() - t0).count(); }

SE2 nanPose() {
  const double n = std::numeric_limits<double>::quiet_NaN();
  return {n, n, n};
}

// At most `n` of `points`, evenly spaced in scan order (the scan's shape is kept; the match and
// score cost grow with the points, and a few hundred constrain a pose as well as a thousand).
Points2 subsample(const Points2& points, std::size_t n) {
  if (points.size() <= n) return points;
  Points2 out;
  out.reserve(n);
  for (std::size_t k = 0; k < n; ++k) out.push_back(points[k * points.size() / n]);
  return out;
}

}  // namespace

struct Tracker::State {
  State(const OccupancyImage& map, std::optional<Database> db, const TrackerOptions& options)
      : o((options.validate(), options)),
        loc(db ? std::make_unique<Localizer>(map, std::move(*db), options.localizer)
               : std::make_unique<Localizer>(map, options.localizer, options.database)),
        field(registration::LikelihoodField::fromMap(map, options.field)) {}
  const TrackerOptions o;
  std::unique_ptr<Localizer> loc;
  registration::LikelihoodField field;
  std::optional<SE2> pose;  ///< last checked pose, or the prior carried over lost scans
  std::optional<SE2> last_odom;  ///< the odometry of the previous scan, when it was used
  /// Frozen odometry: the previous scan's reading (used or not), the checked pose of the first scan
  /// that read the current one, and whether it is taken as frozen (noteStill).
  std::optional<SE2> last_reading;
  std::optional<SE2> still_from;
  bool odometry_frozen = false;
  std::optional<SE2> step;  ///< last per-scan motion between checked poses (constant velocity)
  std::optional<SE2> candidate;   ///< last global answer not yet confirmed
  std::size_t confirmations = 0;  ///< global answers in a row agreeing with it
  /// How far the agreeing answers moved from the first of them (the sums of their steps' distances
  /// and turns): what their views differ by [m, rad].
  double confirm_path_m = 0.0, confirm_turn_rad = 0.0;
  std::size_t lost = 0;     ///< failed scans in a row since the last checked pose
  double placed_time = std::numeric_limits<double>::quiet_NaN();  ///< the last checked pose's scan time
  bool fixed_once = false;
  /// Dead reckoning: the last checked pose moved by every odometry step since, and the odometry
  /// path since [m]; none before the first fix or after a scan without odometry.
  std::optional<SE2> dead_reckoned;
  double dead_reckoned_path_m = 0.0;
  /// The last recent_scans placed scans (pose, points in the robot frame), oldest first, and their
  /// ICP target in the world frame, built only when a scan the map does not explain needs it.
  std::deque<std::pair<SE2, Points2>> recent;
  std::unique_ptr<registration::IcpTarget> recent_target;
  /// Odometry path since the map alone last explained a scan (a fix or a map match) [m].
  double beyond_map_path_m = 0.0;
  /// Odometry path since the map last pinned the position in every direction: over degenerate
  /// scans tracked in a row (their position along the corridor from odometry alone) and, once that
  /// passed max_degenerate_path_m, until a scan's match agrees with global localization [m].
  double unpinned_path_m = 0.0;
  /// The odometry's distance scale: the map matches' metres and the odometry's on chords along runs
  /// of scans the map pinned in every direction, each sum fading with kScaleMemoryM of odometry path;
  /// and whether the last scan was pinned so.
  double scale_matched_m = 0.0, scale_odometry_m = 0.0;
  bool pinned = false;
  /// The start of the current run of pinned scans (its pose and odometry) and the odometry path
  /// since: each kScaleChordM of it, the matched chord is compared with the odometry's.
  std::optional<SE2> chord_pose, chord_odom;
  double chord_path_m = 0.0;
  static constexpr double kScaleMemoryM = 100.0;
  static constexpr double kScaleMinEvidenceM = 5.0;
  static constexpr double kScaleMaxDeviation = 0.1;
  // A chord this long: a scan's step of a few centimetres (a laser at 10-40 Hz) is no longer than a
  // match's noise, which would lengthen every matched step [m].
  static constexpr double kScaleChordM = 0.5;
  // A chord at least this share of the odometry's path along it (not a turn doubling back).
  static constexpr double kScaleChordStraight = 0.8;

  double odometryScale() const {
    if (!o.learn_odometry_scale || scale_odometry_m < kScaleMinEvidenceM) return 1.0;
    return std::clamp(scale_matched_m / scale_odometry_m, 1.0 - kScaleMaxDeviation, 1.0 + kScaleMaxDeviation);
  }
  void observeScale(double matched_m, double odometry_m) {
    const double keep = std::exp(-odometry_m / kScaleMemoryM);
    scale_matched_m = keep * scale_matched_m + matched_m;
    scale_odometry_m = keep * scale_odometry_m + odometry_m;
  }

  /// Remembers the points (robot frame) of a scan placed at `T`.
  void remember(Points2 points, const SE2& T) {
    if (o.recent_scans == 0) return;
    recent.emplace_back(T, std::move(points));
    while (recent.size() > o.recent_scans) recent.pop_front();
    recent_target.reset();
  }
  const registration::IcpTarget& recentTarget() {
    if (!recent_target) {
      Points2 all;
      for (const auto& [T, pts] : recent)
        for (const auto& p : pts) all.push_back(T * p);
      recent_target = std::make_unique<registration::IcpTarget>(all, recentIcp());
    }
    return *recent_target;
  }
  /// ICP against the recent scans: a k-d tree, since the points of several scans in the world
  /// frame, far from its origin, are no scan for the bearing walk.
  static registration::IcpOptions recentIcp() {
    registration::IcpOptions icp;
    icp.neighbor_search = registration::NeighborSearch::kKdTree;
    return icp;
  }
  void forgetRecent() {
    recent.clear();
    recent_target.reset();
    beyond_map_path_m = 0.0;
    unpinned_path_m = 0.0;
  }

  /// A checked pose at scan time `time`: the new pose and the new start of dead reckoning.
  void placed(const SE2& T, double time) {
    pose = T;
    placed_time = time;
    dead_reckoned = T;
    dead_reckoned_path_m = 0.0;
  }
  /// A scan checked at `T` whose odometry read the previous scan's pose (`still`) or not. Odometry
  /// that keeps reading one pose while the checked poses move away from where it started reading it
  /// by more than a match may correct a prior (max_correction_m, max_correction_rad) is frozen (a
  /// stalled driver, wheels that do not turn while the robot is pushed): until it reads another
  /// pose it is no odometry, and its first step after that (all the motion it missed) is none
  /// either. Predicted to stand still, the office run's scans turning 18 degrees each were lost and
  /// fixed again globally (17 relocalizations in 10 s of frozen odometry).
  void noteStill(bool still, const SE2& T) {
    if (!still || !still_from) {
      still_from = T;
      return;
    }
    const SE2 moved = still_from->inverse() * T;
    if (moved.translation().norm() > o.max_correction_m || std::abs(moved.theta()) > o.max_correction_rad)
      odometry_frozen = true;
  }
  /// Whether global localization, which ignores the prior, places the scan where a match put it at
  /// `T` (within twice the hit distance and a third of max_correction_rad).
  bool confirms(const LocalizationResult& g, const SE2& T) const {
    const SE2 e = g.T_world_robot.inverse() * T;
    return !g.declined && e.translation().norm() <= 2.0 * loc->options().hit_distance_m &&
           std::abs(e.theta()) <= o.max_correction_rad / 3.0;
  }
  /// Whether `T` is where dead reckoning allows (true when there is none).
  bool withinDeadReckoning(const SE2& T) const {
    if (!dead_reckoned) return true;
    const SE2 e = dead_reckoned->inverse() * T;
    return e.translation().norm() <= 2.0 * o.max_correction_m + o.dead_reckoning_drift_per_m * dead_reckoned_path_m &&
           std::abs(e.theta()) <= 2.0 * o.max_correction_rad + o.dead_reckoning_drift_rad_per_m * dead_reckoned_path_m;
  }
};

Tracker::Tracker(const OccupancyImage& map, std::optional<Database> database, const TrackerOptions& options)
    : s_(std::make_unique<State>(map, std::move(database), options)) {}
Tracker::~Tracker() = default;

const Localizer& Tracker::localizer() const { return *s_->loc; }
const TrackerOptions& Tracker::options() const { return s_->o; }
double Tracker::odometryScale() const { return s_->odometryScale(); }
double Tracker::odometryScaleEvidenceM() const { return s_->scale_odometry_m; }

void Tracker::reset() {
  s_->pose.reset();
  s_->candidate.reset();
  s_->confirmations = 0;
  s_->step.reset();
  s_->lost = 0;
  s_->dead_reckoned.reset();
  s_->still_from.reset();
  s_->odometry_frozen = false;
  s_->forgetRecent();
}

TrackResult Tracker::add(const Frame& frame) {
  State& s = *s_;
  const TrackerOptions& o = s.o;
  TrackResult r;
  r.T_world_robot = nanPose();

  // The prior's step: odometry when this and the previous frame have it, else the last step
  // between checked poses (constant velocity), else none.
  SE2 step;
  double odometry_step_m = 0.0;  // the odometry's own distance of this step, before its scale
  if (!s.pinned) s.chord_pose.reset();
  s.pinned = false;
  const bool reading = frame.T_odom_robot && frame.T_odom_robot->isFinite();
  const bool still = reading && s.last_reading && frame.T_odom_robot->isApprox(*s.last_reading, 0.0, 0.0);
  if (!still) {
    s.odometry_frozen = false;
    if (!reading) s.still_from.reset();
  }
  s.last_reading = reading ? frame.T_odom_robot : std::nullopt;
  r.odometry_frozen = s.odometry_frozen;
  const bool odom_ok = reading && !s.odometry_frozen;
  const bool had_odom = s.last_odom.has_value();
  if (odom_ok && s.last_odom) {
    const SE2 read = s.last_odom->inverse() * *frame.T_odom_robot;
    odometry_step_m = read.translation().norm();
    const double k = s.odometryScale();
    step = SE2(k * read.x(), k * read.y(), read.theta());
    s.beyond_map_path_m += step.translation().norm();
    if (s.dead_reckoned) {
      s.dead_reckoned = *s.dead_reckoned * step;
      s.dead_reckoned_path_m += step.translation().norm();
    }
  } else {
    s.dead_reckoned.reset();
    if (s.step) step = *s.step;
  }
  s.last_odom = odom_ok ? frame.T_odom_robot : std::nullopt;

  Points2 points;
  for (const auto& p : frame.scan.toPoints(frame.T_robot_laser))
    if (p.allFinite()) points.push_back(p);
  const Eigen::Vector2d sensor = frame.T_robot_laser.translation();
  const std::optional<SE2> prior = s.pose ? std::optional<SE2>(*s.pose * step) : std::nullopt;

  auto fail = [&](std::string reason) {
    r.reason = std::move(reason);
    if (prior && ++s.lost < o.max_lost_scans) {
      s.pose = prior;
    } else {
      s.pose.reset();
      s.step.reset();
      s.forgetRecent();
    }
    return r;
  };
  if (points.size() < o.field.min_points) return fail("no points");

  std::optional<LocalizationResult> cached;
  if (prior) {
    const auto t0 = Clock::now();
    const Points2 sub = subsample(points, o.max_points);
    // Without odometry the constant-velocity prior is wrong where the robot starts or stops
    // turning (20 degrees per scan on a tight arc); the last pose itself (zero velocity) is then
    // tried as a second prior. With odometry its step is trusted alone.
    std::vector<SE2> priors{*prior};
    const bool with_odometry = odom_ok && had_odom;
    if (!with_odometry && s.step) priors.push_back(*s.pose);
    registration::Result m;
    std::string why;
    // Without odometry the prior may be metres off along a direction the scan does not constrain
    // (a corridor: the match slides along it and still explains the scan), so a degenerate scan
    // (degeneracy::analyze) is not tracked; with odometry the prior holds that direction.
    const degeneracy::Result shape = degeneracy::analyze(points);
    const bool unconstrained = !with_odometry && shape.degenerate();
    // With odometry, along a degenerate scan's weak direction the map match has no say: the match
    // would drift to wherever the field's last few cells pull it (the simulator's corridor: held
    // back at its entrance while the robot drove 30 m on), so the prior's position is kept there.
    const bool along_prior = with_odometry && o.max_degenerate_path_m > 0.0 && shape.degenerate();
    // Without odometry a match the scan's own lines pin may still have a rival along the map (a
    // corridor with a few doors): matched again from the pose moved 0.5 or 1 m either way along the
    // match's weakest direction, it settles elsewhere and explains the scan nearly as well.
    auto slides = [&](const Points2& pts, const registration::Result& match, double score, const Eigen::Vector2d& at) {
      if (o.slide_score_margin <= 0.0 || !match.information.allFinite()) return false;
      const std::optional<Eigen::Vector2d> weakest = degeneracy::weakestDirection(
          match.information.topLeftCorner<2, 2>(), std::numeric_limits<double>::infinity());
      if (!weakest) return false;
      const Eigen::Vector2d dir = *weakest;
      const SE2& T = match.T_target_source;
      for (const double d : {-1.0, -0.5, 0.5, 1.0}) {
        const SE2 moved(T.x() + d * dir.x(), T.y() + d * dir.y(), T.theta());
        const registration::Result rival = registration::matchLikelihoodField(s.field, pts, moved, o.field);
        if (!rival.T_target_source.isFinite() || (rival.T_target_source.translation() - T.translation()).norm() < 0.25)
          continue;  // back to the match itself
        if (s.loc->score(pts, rival.T_target_source, at) >= score - o.slide_score_margin) return true;
      }
      return false;
    };
    bool took_prior_position = false;  // the map could not tell the match from the prior's position
    for (const SE2& init : priors) {
      took_prior_position = false;
      m = registration::matchLikelihoodField(s.field, sub, init, o.field);
      r.iterations += m.iterations;
      if (along_prior && m.T_target_source.isFinite())
        m.T_target_source = degeneracy::constrainMatch(m.T_target_source, init, shape);
      SE2 correction = init.inverse() * m.T_target_source;
      if (!m.T_target_source.isFinite() || m.num_inliers < o.field.min_points) {
        why = "no match";
      } else if (correction.translation().norm() > o.max_correction_m ||
                 std::abs(correction.theta()) > o.max_correction_rad) {
        why = "jump";
      } else if (unconstrained) {
        why = "unconstrained";
      } else {
        r.score = s.loc->score(sub, m.T_target_source, sensor);
        if (with_odometry) {
          // A map match may move a long way along a direction the map cannot tell (a corridor's
          // look-alike doors): the prior's position with the match's heading then explains the scan
          // as well, and is taken. The score cannot tell poses within its hit distance of each other
          // apart, so smaller corrections are the map's to make. Each slide is small enough to pass
          // the checks below, and the next prior starts from it: on the Infinite Corridor they added
          // up to a metre.
          const Eigen::Vector2d c = m.T_target_source.translation() - init.translation();
          if (o.prior_score_margin > 0.0 && c.norm() > 2.0 * s.loc->options().hit_distance_m) {
            const SE2 near(init.x(), init.y(), m.T_target_source.theta());
            const double near_score = s.loc->score(sub, near, sensor);
            if (near_score >= r.score - o.prior_score_margin) {
              took_prior_position = true;
              m.T_target_source = near;
              r.score = near_score;
              correction = init.inverse() * near;
            }
          }
        }
        // With odometry a large correction is itself unlikely: the further the match moved from
        // the prior, the more of the scan it must explain (min_track_score at no correction, up to
        // min_track_score + correction_score_slope at max_correction). On freiburg-079 a scan in a
        // turn in place slid 14 degrees from a prior right to 1 degree, explaining 68% where the
        // scans before had explained 93-96%.
        const double moved = std::max(correction.translation().norm() / o.max_correction_m,
                                      std::abs(correction.theta()) / o.max_correction_rad);
        const double needed = o.min_track_score + (with_odometry ? o.correction_score_slope * moved : 0.0);
        why = r.score < o.min_track_score ? "low score" : r.score < needed ? "low score for its correction" : "";
        if (why.empty() && !with_odometry && slides(sub, m, r.score, sensor)) why = "slides";
      }
      // Where the map explains too little, the map and the recent scans together, with odometry
      // (without it the prior may be metres off along a corridor, and the recent scans would hold
      // the match wherever it slid). Intel's half map: most lost scans were a robot turning in place
      // 1-3 m from mapped ground, facing a room the map lacks.
      if (!why.empty() && with_odometry && !s.recent.empty() && s.beyond_map_path_m <= o.max_beyond_map_m &&
          !shape.degenerate()) {
        const registration::IcpTarget& target = s.recentTarget();
        const registration::Result b = registration::alignIcp(target, sub, init, State::recentIcp());
        const SE2 c = init.inverse() * b.T_target_source;
        const bool ok =
            (b.status == registration::Status::kConverged || b.status == registration::Status::kMaxIterations) &&
            b.T_target_source.isFinite() && c.translation().norm() <= o.max_correction_m &&
            std::abs(c.theta()) <= o.max_correction_rad;
        if (ok) {
          const double hd2 = s.loc->options().hit_distance_m * s.loc->options().hit_distance_m;
          const std::function<bool(const Eigen::Vector2d&)> near_recent = [&](const Eigen::Vector2d& w) {
            double d2 = 0.0;
            return target.nearestWithin(w, hd2, &d2) < target.size();
          };
          const double score = s.loc->score(sub, b.T_target_source, sensor, near_recent);
          const double moved =
              std::max(c.translation().norm() / o.max_correction_m, std::abs(c.theta()) / o.max_correction_rad);
          if (score >= o.min_track_score + o.correction_score_slope * moved) {
            m = b;
            r.score = score;
            r.beyond_map = true;
            why.clear();
          }
        }
      }
      if (why.empty()) break;
    }
    r.track_ms = msSince(t0);
    // Without odometry a prior carried over failed scans is the last velocity extrapolated, no
    // evidence: the first match from it is tracked only when global localization, which ignores the
    // prior, agrees with it (its answer is reused below when it does not). freiburg-079's half map
    // without odometry: after four lost scans a match 0.47 m and 5 degrees off, explaining 52% of
    // the scan, was tracked, and eight scans after it.
    if (why.empty() && !with_odometry && s.lost > 0) {
      const auto tg = Clock::now();
      cached = s.loc->localize(points, sensor);
      r.global_ms = msSince(tg);
      if (!s.confirms(*cached, m.T_target_source))
        why = "after lost scans, global localization does not confirm the match";
    }
    if (why.empty()) {
      // The step is measured between checked poses only; carried priors are not evidence.
      if (s.lost == 0) s.step = s.pose->inverse() * m.T_target_source;
      // The odometry's scale from steps whose both ends the map placed in every direction: not along
      // a corridor (the position there is the odometry's), not on the recent scans, not where the
      // prior's position was kept.
      const bool pinned = o.learn_odometry_scale && with_odometry && !along_prior && !r.beyond_map &&
                          !took_prior_position && !(s.unpinned_path_m > o.max_degenerate_path_m);
      // A chord exists only from a scan tracked and pinned just before this one (reset otherwise at
      // the start of add).
      if (pinned && s.chord_pose) {
        s.chord_path_m += odometry_step_m;
        if (s.chord_path_m >= State::kScaleChordM) {
          const double odometry_m = (s.chord_odom->inverse() * *frame.T_odom_robot).translation().norm();
          if (odometry_m >= State::kScaleChordStraight * s.chord_path_m)
            s.observeScale((s.chord_pose->inverse() * m.T_target_source).translation().norm(), odometry_m);
          s.chord_pose.reset();
        }
      }
      if (pinned && !s.chord_pose) {
        s.chord_pose = m.T_target_source;
        s.chord_odom = frame.T_odom_robot;
        s.chord_path_m = 0.0;
      }
      if (!r.beyond_map) s.beyond_map_path_m = 0.0;
      s.lost = 0;
      s.candidate.reset();
      if (s.unpinned_path_m > o.max_degenerate_path_m && !along_prior) {
        // The first scans the map pins again after a long corridor: their prior may be off along it
        // by more than the match corrects (a few far points of the corridor's end hold it where it
        // is). The match is taken when global localization, which ignores the prior, agrees with it.
        const auto tg = Clock::now();
        const LocalizationResult g = s.loc->localize(points, sensor);
        r.global_ms = msSince(tg);
        if (s.confirms(g, m.T_target_source)) s.unpinned_path_m = 0.0;
      }
      if (along_prior || s.unpinned_path_m > o.max_degenerate_path_m)
        s.unpinned_path_m += step.translation().norm();
      else
        s.unpinned_path_m = 0.0;
      if (s.unpinned_path_m > o.max_degenerate_path_m) {
        // Too far along a corridor on odometry alone to vouch for the position along it: the pose
        // goes on (the map still holds the rest, and the corridor's end is matched from it), but it
        // is not reported.
        s.pose = m.T_target_source;
        r.status = TrackStatus::kLost;
        r.reason = fmt::format("{:.1f} m along a corridor on odometry alone{}", s.unpinned_path_m,
                               along_prior ? "" : ", global localization does not confirm the match");
        r.score = 0.0;
        return r;
      }
      s.remember(sub, m.T_target_source);
      s.placed(m.T_target_source, frame.time);
      s.noteStill(still, m.T_target_source);
      r.status = TrackStatus::kTracking;
      s.pinned = pinned;
      r.T_world_robot = m.T_target_source;
      return r;
    }
    r.reason = why;
    r.score = 0.0;
  }

  // Global localization: the first fix, or at once when tracking fails (a kidnapped robot is found
  // on the scan it is first seen on, not after the prior has run out).
  const auto t0 = Clock::now();
  const LocalizationResult g = cached ? *cached : s.loc->localize(points, sensor);
  r.global_ms += msSince(t0);
  const bool answered = !g.declined && g.score >= o.min_global_score;
  const std::optional<SE2> previous = s.candidate;
  if (answered) {
    const SE2 e = s.candidate ? (*s.candidate * step).inverse() * g.T_world_robot : SE2();
    const bool agrees = s.candidate && e.translation().norm() <= 2 * o.max_correction_m &&
                        std::abs(e.theta()) <= 2 * o.max_correction_rad;
    s.confirmations = agrees ? s.confirmations + 1 : 1;
    if (agrees) {
      const SE2 moved = previous->inverse() * g.T_world_robot;
      s.confirm_path_m += moved.translation().norm();
      s.confirm_turn_rad += std::abs(moved.theta());
    } else {
      s.confirm_path_m = s.confirm_turn_rad = 0.0;
    }
    s.candidate = g.T_world_robot;
  } else {
    s.candidate.reset();
    s.confirmations = 0;
  }
  // Without odometry no dead reckoning vouches for an answer: like one that contradicts it, it needs
  // confirm_fixes_against_odometry answers (freiburg-079's half map without odometry: three wrong
  // fixes in the half the map lacks, each found three times in a row, and 61 scans tracked from them),
  // and they must come from views that differ (the robot moved max_correction_m or turned
  // max_correction_rad over them): six scans of a room the map lacks, taken within 13 cm and 8
  // degrees of one another, are one view, and their six agreeing answers put freiburg-079's robot
  // 7.6 m and 89 degrees off, then 13 scans tracked from there.
  const bool expected = answered && odom_ok && s.withinDeadReckoning(g.T_world_robot);
  // Without odometry the prior carried since the last checked pose is the only dead reckoning: an
  // answer farther from it than the robot can have driven since (max_speed_m_per_s) is not sure on
  // its score alone until the prior is dropped (max_lost_scans). freiburg-079's half map: 0.6 s
  // after the last tracked scan, an answer scoring 0.95 put the robot 23 m and 176 degrees off, and
  // 47 scans were tracked from it. Where the times do not increase nothing bounds the motion.
  const double since_s = frame.time - s.placed_time;
  const bool near_prior = !prior || !(since_s > 0) ||
                          (g.T_world_robot.translation() - prior->translation()).norm() <=
                              o.max_speed_m_per_s * since_s + 2.0 * o.max_correction_m;
  const bool sure = answered && (expected || (!odom_ok && near_prior)) && g.score >= o.sure_fix_score;
  const std::size_t needed = expected ? o.confirm_fixes : std::max(o.confirm_fixes, o.confirm_fixes_against_odometry);
  const bool views_differ =
      odom_ok || s.confirm_path_m >= o.max_correction_m || s.confirm_turn_rad >= o.max_correction_rad;
  if (answered && ((s.confirmations >= needed && views_differ) || sure)) {
    r.status = TrackStatus::kGlobal;
    r.T_world_robot = g.T_world_robot;
    r.score = g.score;
    r.relocalized = s.fixed_once;
    r.reason.clear();
    s.fixed_once = true;
    const std::optional<SE2> checked_before = s.lost == 0 ? s.pose : std::nullopt;
    // The recent scans were placed before tracking failed, perhaps elsewhere (a kidnapping).
    s.forgetRecent();
    s.remember(subsample(points, o.max_points), g.T_world_robot);
    s.placed(g.T_world_robot, frame.time);
    s.noteStill(still, g.T_world_robot);
    // The constant-velocity prior of the next scan when there is no odometry (standing still would be
    // metres off on a log of keyframes): the step from the previous scan's checked pose (tracking
    // failed on this scan, but the one before was placed), else between the last two agreeing answers.
    // A fix at once (sure_fix_score) has no agreeing answers before it, so the checked pose is what
    // keeps the next scan from being fixed globally in turn.
    s.step = checked_before         ? std::optional<SE2>(checked_before->inverse() * g.T_world_robot)
             : s.confirmations >= 2 ? std::optional<SE2>(previous->inverse() * g.T_world_robot)
                                    : std::nullopt;
    s.lost = 0;
    s.candidate.reset();
    s.confirmations = 0;
    return r;
  }
  const std::string why = answered     ? (expected     ? "unconfirmed"
                                          : odom_ok    ? "unconfirmed, away from dead reckoning"
                                          : near_prior ? "unconfirmed, no odometry"
                                                       : "unconfirmed, no odometry, away from the last pose")
                          : g.declined ? g.reason
                                       : "low score";
  return fail(prior ? r.reason + ", global " + why : (s.fixed_once ? "global " : "no fix yet, global ") + why);
}

}  // namespace lidar2d::localization
