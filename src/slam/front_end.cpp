#include "src/slam/internal/front_end.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>

#include "lidar2d/degeneracy/degeneracy.hpp"
#include "src/slam/internal/points.hpp"

namespace lidar2d::slam::internal {

using registration::alignIcp;
using registration::CorrelativeGrid;
using registration::IcpTarget;

SE2 FrontEnd::firstPose(const Frame& f) const { return opt.use_odometry && f.T_odom_robot ? *f.T_odom_robot : SE2(); }

FrontEnd::Prediction FrontEnd::predict(const Frame& f) {
  return prior_.predict(f, [&](std::string what) { s_.event(f, std::move(what)); });
}

FrontEnd::Tracked FrontEnd::track(const Frame& f, const Points2& pts, const Prediction& p) {
  Tracked out;
  const SE2 T_pred = T_local_prev * p.delta;
  std::vector<SE2> alternatives;
  if (p.delta.translation().norm() > opt.alternative_start_m || std::abs(p.delta.theta()) > opt.alternative_start_rad) {
    alternatives.push_back(T_local_prev);
    if (p.source == PriorSource::kOdometry) alternatives.push_back(T_local_prev * last_step.value_or(SE2()));
  }
  if (p.implausible_odometry) alternatives.push_back(T_local_prev * *p.implausible_odometry);
  // Also the poses of a few earlier scans: a scan logged late (the Intel bag has runs of them,
  // up to a second old while the robot turns at 40 deg/s) was taken near one of them, tens of
  // degrees from the prediction (constant velocity, or odometry interpolated at its wrong
  // stamp); and the scan after it continues from the scan before it, not from its pose.
  std::vector<SE2> earlier;
  for (const std::size_t back : kEarlierBack) {
    if (recent_poses.size() < back) break;
    const SE2& T = recent_poses[recent_poses.size() - back];
    const SE2 d = T_pred.inverse() * T;
    if (d.translation().norm() > opt.alternative_start_m || std::abs(d.theta()) > opt.alternative_start_rad)
      earlier.push_back(T);
  }
  // Tried below 90% explained without odometry (the prediction is only a guess), below 80% with
  // it: on freiburg-079 the 80-90% band tried ICP thousands of times and never won, while on
  // Intel 0.7 to 0.8 held the result under changes of other parameters (0.5 did not).
  const double earlier_below = p.source == PriorSource::kOdometry ? kEarlierWithOdometry : kConfirmExplained;
  MatchOutcome m = frontEndMatch(pts, p, T_pred, alternatives, earlier, earlier_below);
  // From a gap until a scan matches, the prediction itself is in doubt (the robot may have been
  // carried while nothing was logged): a match against the prior is then a place found again, held
  // to a loop closure's bar, not a step the scan corrects.
  if (!p.time_ok) since_gap_unmatched = true;
  if (since_gap_unmatched && m.T && m.overrode_prior && m.explained < opt.loop_min_explained_fraction) {
    s_.event(f, fmt::format("after the gap a match against the prior explains only {:.0f}% of the scan: not trusted",
                            100.0 * m.explained));
    m.T.reset();
    m.overrode_prior = false;
  }
  if (m.T) since_gap_unmatched = false;
  if (m.used_fallback) ++s_.stats.correlative_fallbacks;
  out.T_local_robot = T_pred;
  out.degenerate = m.degenerate;
  out.dir = m.dir;
  if (m.overrode_prior) {
    ++s_.stats.prior_overridden;
    const SE2 d = p.delta.inverse() * (T_local_prev.inverse() * *m.T);
    prior_.overridden(p, d);
    s_.event(f, fmt::format("the scan overrides the {} prior by {:.2f} m / {:.1f} deg ({:.1f} sigmas): its match "
                            "explains {:.0f}% of the scan, the best within the prior {:.0f}%",
                            toString(p.source), d.translation().norm(), std::abs(d.theta()) / kDeg,
                            p.distance(T_local_prev.inverse() * *m.T), 100.0 * m.explained, 100.0 * m.explained_in_gate));
  }
  if (m.rejected && !m.T) {
    ++s_.stats.prior_kept;
    const SE2 d = p.delta.inverse() * (T_local_prev.inverse() * m.rejected->T);
    s_.event(f, fmt::format("a match {:.2f} m / {:.1f} deg ({:.1f} sigmas) from the {} prior explains only {:.0f}% "
                            "of the scan: the prior is kept",
                            d.translation().norm(), std::abs(d.theta()) / kDeg, m.rejected->sigmas,
                            toString(p.source), 100.0 * m.rejected->explained));
  }
  // A step the scans measured at both ends (matched, neither degenerate) under trusted odometry;
  // those not taken against the prior measure the odometry's distance scale.
  const bool measured = m.T && prev_matched && !m.degenerate && odometryTrusted(p);
  if (!(measured && !m.overrode_prior)) {
    prior_.interruptOdometryScale();
  } else {
    prior_.observeOdometryStep(p, T_local_prev.inverse() * *m.T);
    const OdometryScale& scale = prior_.odometryScale();
    s_.stats.odometry_scale = scale.factor();
    s_.stats.odometry_scale_evidence_m = scale.evidenceM();
    if (std::abs(scale.factor() - reported_scale) >= kReportScaleChange) {
      reported_scale = scale.factor();
      s_.event(f, fmt::format("the scans measure {:.3f} m per metre of odometry over the last {:.0f} m of steps they "
                              "pinned: {}",
                              scale.factor(), scale.evidenceM(),
                              opt.scale_odometry ? "odometry distances scaled by it from here"
                                                 : "odometry distances not scaled (scale_odometry)"));
    }
  }
  // What the odometry strayed by on such a step, an override included (MotionPrior's learnt noise:
  // a prior too narrow for the odometry widens again).
  if (measured) prior_.observeOdometryNoise(p, T_local_prev.inverse() * *m.T);
  prev_matched = m.T && !m.degenerate;
  if (m.T) {
    out.T_local_robot = *m.T;
    out.placement = Placement::kMatched;
    out.overrode_prior = m.overrode_prior;
    consecutive_failures = 0;
    ++s_.stats.matched;
    if (out.degenerate) ++s_.stats.degenerate;
  } else if (m.vouches != OdometryVouches::kNo) {
    // Unmatched, and nothing contradicts the odometry: a lost track would restart the local map and
    // leave a fragment tied only by the prediction, whose scans then match only each other. The
    // scan is placed by the odometry and extends the local map instead, in two cases:
    // - it sees only new ground: keyframes metres apart with a short-range laser overlap nothing of
    //   the local map after a turn (edmonton's keyframes, 10 m range: 0-11% of the scan within 0.5 m
    //   of it at the odometry's pose, for five scans in a row);
    // - the best match near the prediction, too weak to take, explains at least as much of the scan
    //   as any match farther away: clutter seen from new angles (orebro: five scans in a row whose best
    //   match near the odometry explained 19-28%, matches elsewhere 6-14%; the scans after them
    //   matched the local map from before at the odometry's poses, explaining 75-89%). A robot
    //   carried elsewhere while its odometry did not know gives no such match: near the prediction
    //   ICP finds nothing, or less than a look-alike elsewhere (the simulated office: nothing within
    //   the gate, 37-44% explained 7-10 sigmas away), and the track is lost as before.
    // Not after a gap (the robot may have been carried), nor when a match elsewhere was refused (the
    // scan contradicts the prior), nor without odometry (the prediction is only a guess).
    ++s_.stats.unmatched;
    consecutive_failures = 0;
    out.placement = Placement::kOdometry;
    // The odometry's pose, or the best match near it where that match is near enough and explains
    // enough of what overlaps to correct the odometry's heading (a sparse scan's overlap pins the
    // rotation before it pins the place).
    std::string at = "placed by odometry";
    if (m.refining) {
      const Candidate& r = *m.refining;
      const SE2 d = p.delta.inverse() * (T_local_prev.inverse() * r.T);
      // A degenerate match refines the heading and the direction it pins; where it turns the
      // odometry by less than refine_min_turn_sigmas of its own heading sigma (its covariance,
      // infinite where its information is singular), that turn is the match's noise, not the
      // odometry's error (a depth camera's scan of one wall 3 cm after the last: the odometry right
      // within hundredths of a degree, such matches tenths of a degree off).
      const double sigma_rad = std::sqrt(r.res.covariance(2, 2));
      if (r.degenerate && opt.refine_min_turn_sigmas > 0.0 &&
          !(std::abs(d.theta()) > opt.refine_min_turn_sigmas * sigma_rad)) {
        at = fmt::format(
            "placed by odometry, where the best match near it is degenerate and turns it by less than its own "
            "uncertainty ({:.2f} deg, the match's sigma {:.2f} deg)",
            std::abs(d.theta()) / kDeg, sigma_rad / kDeg);
      } else {
        out.T_local_robot = r.T;
        out.placement = Placement::kRefined;
        out.degenerate = r.degenerate;  // the graph's link then holds only what it pins
        out.dir = r.dir;
        at = fmt::format(
            "placed by odometry, refined by the best match near it ({:.2f} m / {:.1f} deg, {:.1f} sigmas; "
            "it explains {:.0f}% of the {:.0f}% of the scan that overlaps the local map{})",
            d.translation().norm(), std::abs(d.theta()) / kDeg, r.sigmas, 100.0 * r.overlap.explained_in_overlap,
            100.0 * r.overlap.overlap,
            r.degenerate ? "; degenerate: along its weak direction the place is the odometry's" : "");
      }
    }
    switch (m.vouches) {
      case OdometryVouches::kNewGround:
        s_.event(f, fmt::format("the scan sees only new ground (it overlaps almost nothing of the local map at the "
                                "odometry's pose): {}",
                                at));
        break;
      case OdometryVouches::kNearMatchRefines:
        s_.event(f, fmt::format("the scan does not match the local map, and a match farther away explains more of it "
                                "without outweighing the prior, but the best near the odometry's pose pins it: {}",
                                at));
        break;
      default:
        s_.event(f, fmt::format("the scan does not match the local map, but no match explains more of it than the "
                                "best near the odometry's pose ({:.0f}%): {}",
                                100.0 * m.explained_in_gate, at));
    }
  } else {
    ++s_.stats.unmatched;
    ++consecutive_failures;
    if (consecutive_failures == 1)
      s_.event(f, pts.size() < opt.min_points ? fmt::format("only {} valid points: pose predicted", pts.size())
                                              : std::string("scan does not match the local map: pose predicted"));
    if (consecutive_failures >= 5 && pts.size() >= opt.min_points) {
      s_.event(f, "lost track for 5 scans: local map restarted here (kidnapping?); loop closure may reconnect");
      out.restart = true;
      out.lost_before = static_cast<std::size_t>(consecutive_failures - 1);
      consecutive_failures = 0;
    }
  }
  return out;
}

bool FrontEnd::refinesPlacement(const Candidate& c) {
  // A degenerate match refines too: its translation along the weak direction is the prediction's
  // already (remapDegenerate), so what it corrects is the heading and the direction it pins.
  return c.sigmas <= kRefineSigmas && c.overlap.overlap >= kMinOverlap &&
         c.overlap.explained_in_overlap >= kRefineExplainedInOverlap;
}

bool FrontEnd::odometryTrusted(const Prediction& p) const {
  return p.source == PriorSource::kOdometry && p.time_ok && !since_gap_unmatched && !p.implausible_odometry;
}

bool FrontEnd::onlyNewGroundAt(const Points2& pts, const Prediction& p, const SE2& T_pred) const {
  if (!odometryTrusted(p) || pts.size() < opt.min_points) return false;
  // A local map of fewer points than a match needs (the first scan saw a few returns: a 12 m laser
  // in an open hall) holds nothing the scan could overlap.
  if (!local_target || local_target->size() < opt.min_points) return true;
  return overlapWith(*local_target, pts, T_pred, opt.match_inlier_distance_m, kOverlapM).overlap < kNewGroundOverlap;
}

void FrontEnd::addNode(const SE2& T_local, const Points2& pts, bool restart) {
  if (restart) local_nodes.clear();
  local_nodes.emplace_back(T_local, pts);
  while (static_cast<int>(local_nodes.size()) > opt.local_map_nodes) local_nodes.pop_front();
  rebuildLocalMap();
}

void FrontEnd::remember(const Frame& f, const Prediction& p, const SE2& T_local, bool first, bool pinned) {
  const SE2 step = first ? SE2() : T_local_prev.inverse() * T_local;
  prior_.remember(f, p, step, first, pinned);
  if (!first) {
    last_step = p.time_ok ? std::optional<SE2>(step) : std::nullopt;
    recent_poses.push_back(T_local);
    if (recent_poses.size() > kEarlierBack.back()) recent_poses.pop_front();
  }
  T_local_prev = T_local;
  have_prev = true;
}

void FrontEnd::rebuildLocalMap() {
  local_points.clear();
  for (const auto& [T, pts] : local_nodes)
    for (const auto& p : pts) local_points.push_back(T * p);
  local_points = voxelFilter(local_points, opt.map_voxel_m);
  local_target = std::make_unique<IcpTarget>(local_points, icp);
  if (opt.front_end_likelihood_field)
    local_field = std::make_unique<registration::LikelihoodField>(
        registration::LikelihoodField::fromPoints(local_points, local_lf));
  local_grid_built = false;
}

bool FrontEnd::replaces(const Candidate& c, const Candidate& best) {
  if (c.explained > best.explained + 0.05) return true;
  if (c.explained <= best.explained - 0.05) return false;
  const double prior_nats = 0.5 * (best.sigmas * best.sigmas - c.sigmas * c.sigmas);
  if (std::abs(prior_nats) > kPriorTieNats) return prior_nats > 0.0;
  if (c.degenerate != best.degenerate) return !c.degenerate;
  return c.res.final_cost < 0.8 * best.res.final_cost;
}

bool FrontEnd::priorVouchesFor(const Candidate& c, double min_explained) {
  return (c.sigmas <= kVouchSigmas || c.searched) && c.overlap.overlap >= kMinOverlap &&
         c.overlap.explained_in_overlap >= min_explained;
}

/// Front-end match of `pts` against the local map from `T_pred`, the prediction `p` after the
/// previous pose. `alternatives`: other starting points, tried when the prediction is not
/// confirmed. `earlier`: the poses of earlier scans, tried when the best match still explains
/// under `earlier_below`.
///
/// Every match is weighed against the prior: within `prior_gate_sigmas` of the prediction, the
/// match explaining the most points wins (or about as many with a clearly lower cost); a match
/// beyond the gate wins only when its log-posterior (`prior_nats_per_point` per explained point,
/// minus half its squared Mahalanobis distance) beats the best one within the gate.
FrontEnd::MatchOutcome FrontEnd::frontEndMatch(const Points2& pts, const Prediction& p, const SE2& T_pred,
                                               const std::vector<SE2>& alternatives, const std::vector<SE2>& earlier,
                                               double earlier_below) {
  MatchOutcome out;
  if (!local_target || local_target->size() < opt.min_points || pts.size() < opt.min_points) {
    if (onlyNewGroundAt(pts, p, T_pred)) out.vouches = OdometryVouches::kNewGround;
    return out;
  }
  auto tryFrom = [&](const SE2& init) {
    Candidate c;
    c.res = opt.front_end_likelihood_field ? registration::matchLikelihoodField(*local_field, pts, init, local_lf)
                                           : alignIcp(*local_target, pts, init, icp);
    const bool ok =
        c.res.status == registration::Status::kConverged || c.res.status == registration::Status::kMaxIterations;
    const bool finite = c.res.T_target_source.isFinite();
    c.T = c.res.T_target_source;
    if (finite) remapDegenerate(c, p, T_pred);
    // Weighed against the prior after remapping: along a corridor ICP slides anywhere, and that
    // slide says nothing against the prediction.
    c.sigmas = finite ? p.distance(T_local_prev.inverse() * c.T) : std::numeric_limits<double>::infinity();
    // The share explained: where ICP slid, but for a degenerate match beyond the gate, which is
    // weighed against the prior by what the scan explains at the pose it would take (the remapped
    // one): ICP may slide metres along the weak direction and turn on the way, and the remapped
    // pose keeps that turn at the prediction's place (edmonton's keyframes with a 5.6 m laser: 60%
    // explained where ICP slid, none at the remapped pose). Within the gate the slid match's share
    // stands (BENCHMARK.md, SLAM: rescored there, more runs ended further off).
    const SE2& scored = c.degenerate && c.sigmas > opt.prior_gate_sigmas ? c.T : c.res.T_target_source;
    if (ok && finite) c.overlap = overlapWith(*local_target, pts, scored, opt.match_inlier_distance_m, kOverlapM);
    c.explained = c.overlap.explained;
    return c;
  };
  std::optional<Candidate> in_gate, beyond_gate;
  // The log-posterior of a match, up to a constant: the scan's evidence (nats per explained point)
  // plus the Gaussian prior's log-density. A match beyond the gate outweighs the prior when its
  // log-posterior beats the best match near the prediction.
  const double nats = opt.prior_nats_per_point * static_cast<double>(pts.size());
  auto logPosterior = [&](const Candidate& c) { return nats * c.explained - 0.5 * c.sigmas * c.sigmas; };
  auto consider = [&](Candidate c) {
    if (c.sigmas <= opt.prior_gate_sigmas) {
      if (!in_gate || replaces(c, *in_gate)) in_gate = std::move(c);
    } else if (!beyond_gate || logPosterior(c) > logPosterior(*beyond_gate)) {
      beyond_gate = std::move(c);
    }
  };
  auto bestExplained = [&] { return in_gate ? in_gate->explained : 0.0; };
  consider(tryFrom(T_pred));
  // Other starting points (no motion, constant velocity) when the prediction may be wrong: wheel
  // odometry interpolated at badly stamped scans can be tens of degrees off, and ICP from there
  // settles in a wrong minimum that still explains much of the scan.
  // Only when the prediction was not confirmed: the match moved it or explains too little.
  bool confirmed = false;
  if (in_gate) {
    const SE2 correction = T_pred.inverse() * in_gate->res.T_target_source;
    confirmed = in_gate->explained >= kConfirmExplained && correction.translation().norm() <= 0.05 &&
                std::abs(correction.theta()) <= 2.0 * kDeg;
  }
  if (!confirmed) {
    for (const SE2& alt : alternatives) consider(tryFrom(alt));
    // Earlier scans' poses only while the match explains too little: where they won on Intel
    // (with odometry) the prediction's match explained a median 41% of the scan, a few up to 89%.
    if (bestExplained() < earlier_below)
      for (const SE2& start : earlier) consider(tryFrom(start));
  }
  // The correlative search (Olson) over a window of three sigmas of the prior (at least the
  // fallback window, at most the search cap), then ICP from its answer: when the matches so far
  // explain too little, or when the prior is wider than ICP's basin of convergence and nothing
  // confirmed a match yet.
  const bool wide = p.sigma_m > kIcpBasinM || p.sigma_rad > kIcpBasinRad;
  if (bestExplained() < opt.min_explained_fraction || (wide && bestExplained() < kConfirmExplained)) {
    if (!local_grid_built) {
      local_grid.rebuild(local_points, fallback);
      local_grid_built = true;
    }
    registration::CorrelativeOptions window = fallback;
    window.linear_window_m =
        std::clamp(3.0 * p.sigma_m, opt.fallback_linear_window_m, std::max(opt.fallback_linear_window_m,
                                                                           opt.search_max_linear_window_m));
    window.angular_window_rad =
        std::clamp(3.0 * p.sigma_rad, opt.fallback_angular_window_rad,
                   std::max(opt.fallback_angular_window_rad, opt.search_max_angular_window_rad));
    const auto cr = registration::matchCorrelative(local_grid, pts, T_pred, window);
    out.used_fallback = true;
    if (cr.T_search.isFinite()) {
      Candidate c = tryFrom(cr.T_search);
      c.searched = true;
      consider(std::move(c));
    }
  }
  out.explained_in_gate = bestExplained();
  if (opt.refine_odometry_placement && in_gate && refinesPlacement(*in_gate)) out.refining = in_gate;
  const Candidate* win = nullptr;
  // Within the gate of a prior narrower than ICP's basin, or of one drawn from the robot's own
  // recent steps (a keyframe log without odometry), the prior vouches for the match where the scan
  // sees new ground (keyframes metres apart): the share explained counts only the points that
  // overlap the local map, as long as enough of them do. Not under a prior that only time widened, nor
  // after a gap: there a partial match may be another place (a robot carried while nothing was
  // logged, whose odometry does not know, matched a look-alike part of the old place). Nor far from
  // the prediction (kVouchSigmas) unless the correlative search found it: a weak match out at the
  // gate's edge that ICP reached from a start is a wrong minimum of a sparse scan, while the search
  // weighed every pose of the window and is right where the odometry itself is wrong.
  const bool vouched =
      in_gate && (!wide || p.from_spread) && p.time_ok && priorVouchesFor(*in_gate, opt.min_explained_fraction);
  if (in_gate && (in_gate->explained >= opt.min_explained_fraction || vouched))
    win = &*in_gate;
  // A match beyond the gate wins when the evidence outweighs the prior: a higher log-posterior
  // than the best match within the gate (or than the prediction itself, explaining nothing).
  // Not where nothing within the gate matched and the scan at the prediction sees only new ground
  // (onlyNewGroundAt): nothing there contradicts the odometry, and the match beyond the gate is
  // a look-alike part of the local map (the simulator's identical rooms, a 4 m laser: 56% explained
  // 2.8 m and 10 sigmas from the odometry's pose), not evidence against it. Where the best match
  // near the prediction explains at least as much as any beyond the gate, the odometry vouches for
  // the prediction too (OdometryVouches::kBestMatchNearIt; no match beyond the gate can win there).
  // A tie counts for the odometry: a match elsewhere that explains no more of the scan than the
  // prediction is no evidence against it (a depth camera facing one wall is explained all over at
  // the odometry's pose and a few degrees round, where the local map's wall turned with each such
  // override before; docs/slam.md, step 4).
  const bool beyond_counts = beyond_gate && beyond_gate->explained >= opt.min_explained_fraction;
  const bool beyond_wins = beyond_counts && logPosterior(*beyond_gate) > (in_gate ? logPosterior(*in_gate) : 0.0);
  if (!win && (beyond_wins || !beyond_counts)) {
    if (onlyNewGroundAt(pts, p, T_pred))
      out.vouches = OdometryVouches::kNewGround;
    else if (odometryTrusted(p)) {
      // The prediction itself is a pose near the prediction: where ICP found too few pairs to move
      // from it (a narrow field of view turning onto a wall the local map holds a corner of), what
      // the scan explains there is the best near the odometry's pose.
      out.explained_in_gate =
          std::max(out.explained_in_gate, explainedFraction(*local_target, pts, T_pred, opt.match_inlier_distance_m));
      if (out.explained_in_gate > 0.0 && out.explained_in_gate >= (beyond_gate ? beyond_gate->explained : 0.0))
        out.vouches = OdometryVouches::kBestMatchNearIt;
    }
  }
  // A match near the prediction that refines a placement (refinesPlacement) vouches for the
  // odometry too where a weak match farther away explains more of the scan, or where a match beyond
  // the gate was refused: within a sigma of the odometry it pins what overlaps (the scans lost so
  // on sparse keyframes, left at the prediction and counted towards a lost track, turned the
  // estimate by up to 14 degrees).
  if (!win && out.vouches == OdometryVouches::kNo && !beyond_wins && out.refining && odometryTrusted(p))
    out.vouches = OdometryVouches::kNearMatchRefines;
  if (beyond_wins && (win || out.vouches == OdometryVouches::kNo)) {
    win = &*beyond_gate;
    out.overrode_prior = true;
  } else if (beyond_counts && !beyond_wins && !win) {
    out.rejected = beyond_gate;
  }
  if (!win) return out;
  out.explained = win->explained;
  out.degenerate = win->degenerate;
  out.dir = win->dir;
  out.T = win->T;
  return out;
}

/// Degeneracy (Zhang, Kaess & Singh 2016): the translational block of the information matrix per
/// matched point; a weak eigen-direction is not pinned by the scan, so the translation along it is
/// taken from the prediction (solution remapping) instead of whatever the solver slid to. Without
/// odometry the prediction's step is the robot's recent steps turning as this match does
/// (MotionPrior::stepTurning) when there are such steps.
void FrontEnd::remapDegenerate(Candidate& c, const Prediction& p, const SE2& T_pred) const {
  const registration::Result& res = c.res;
  if (res.num_inliers == 0) return;
  const std::optional<Eigen::Vector2d> dir = degeneracy::weakestDirection(
      res.information.topLeftCorner<2, 2>() / static_cast<double>(res.num_inliers), opt.degeneracy_threshold);
  if (!dir) return;
  c.degenerate = true;
  c.dir = *dir;
  SE2 from = T_pred;
  if (p.source == PriorSource::kConstantVelocity && p.time_ok)
    if (const std::optional<SE2> step = prior_.stepTurning(angleDiff(c.T.theta(), T_local_prev.theta())))
      from = T_local_prev * *step;
  c.T = degeneracy::remapPose(from, c.T, degeneracy::projectorRemovingDirection(std::atan2(c.dir.y(), c.dir.x())));
}

}  // namespace lidar2d::slam::internal
