#include "src/slam/internal/motion_prior.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <vector>

namespace lidar2d::slam::internal {
double upperMedian(std::vector<double> v) {
  const auto mid = v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2);
  std::nth_element(v.begin(), mid, v.end());
  return *mid;
}

const char* toString(PriorSource s) {
  switch (s) {
    case PriorSource::kNone:
      return "none";
    case PriorSource::kOdometry:
      return "odometry";
    case PriorSource::kConstantVelocity:
      return "constant velocity";
  }
  return "unknown";
}

double MotionPrediction::distance(const SE2& step) const {
  const SE2 r = delta.inverse() * step;
  const double a = r.translation().norm() / sigma_m;
  const double b = r.theta() / sigma_rad;
  return std::sqrt(a * a + b * b);
}

MotionPrediction odometryPrediction(const SlamOptions& opt, const SE2& odo, double dt) {
  MotionPrediction p;
  const double dist = odo.translation().norm(), turn = std::abs(odo.theta());
  p.delta = odo;
  p.source = PriorSource::kOdometry;
  p.dt = std::max(0.0, dt);
  p.sigma_m = opt.prior_odometry_sigma_m + opt.prior_odometry_sigma_per_m * dist + opt.prior_odometry_sigma_m_per_s * p.dt;
  p.sigma_rad =
      opt.prior_odometry_sigma_rad + opt.prior_odometry_sigma_per_turn * turn + opt.prior_odometry_sigma_rad_per_m * dist;
  return p;
}

void OdometryScale::observe(const SE2& odometry_step, const SE2& matched_step) {
  odometry_span_ = odometry_span_ * odometry_step;
  scan_span_ = scan_span_ * matched_step;
  const Eigen::Vector2d o = odometry_span_.translation();
  const double chord = o.norm();
  if (chord < kSpanM) return;
  // What the scans measured along the odometry's chord; a span the two read more than half apart
  // is a bad match or a wheel slipping, not the scale: bounded.
  const double measured = std::clamp(scan_span_.translation().dot(o) / chord, 0.5 * chord, 1.5 * chord);
  interrupt();
  const double keep = std::exp(-chord / kMemoryM);
  odometry_m_ = odometry_m_ * keep + chord;
  scan_m_ = scan_m_ * keep + measured;
  if (odometry_m_ >= kMinEvidenceM) factor_ = std::clamp(scan_m_ / odometry_m_, kMinFactor, kMaxFactor);
}

void OdometryNoise::observe(const SE2& residual, double model_m, double model_rad, double floor_m, double floor_rad) {
  if (!residual.isFinite()) return;
  // Only steps whose sigma is mostly the distance and turn terms: on the short steps the constant
  // terms dominate, and what strays there is the scan matching's own centimetres.
  auto add = [](std::deque<double>& z, double value, double& factor) {
    z.push_back(value);
    if (z.size() > kSteps) z.pop_front();
    if (z.size() < kMinSteps) return;
    std::vector<double> v(z.begin(), z.end());
    const auto k = static_cast<std::size_t>(kQuantile * static_cast<double>(v.size() - 1) + 0.5);
    std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(k), v.end());
    factor = std::clamp(v[k], kMinFactor, 1.0);
  };
  if (model_m >= 2.0 * floor_m) add(z_m_, residual.translation().norm() / model_m, factor_m_);
  if (model_rad >= 2.0 * floor_rad) add(z_rad_, std::abs(residual.theta()) / model_rad, factor_rad_);
}

void MotionPrior::observeOdometryNoise(const MotionPrediction& p, const SE2& matched_step) {
  if (p.source != PriorSource::kOdometry) return;
  const MotionPrediction model = odometryPrediction(opt_, p.delta, p.dt);
  noise_.observe(p.delta.inverse() * matched_step, model.sigma_m, model.sigma_rad, opt_.prior_odometry_sigma_m,
                 opt_.prior_odometry_sigma_rad);
}

void MotionPrior::narrowToOdometryNoise(MotionPrediction& p) const {
  if (!opt_.prior_odometry_learn_noise) return;
  p.sigma_m = std::max(opt_.prior_odometry_sigma_m, noise_.factorM() * p.sigma_m);
  p.sigma_rad = std::max(opt_.prior_odometry_sigma_rad, noise_.factorRad() * p.sigma_rad);
}

void MotionPrior::observeOdometryStep(const MotionPrediction& p, const SE2& matched_step) {
  if (p.source == PriorSource::kOdometry) scale_.observe(p.odometry_step, matched_step);
}

void MotionPrior::overridden(const MotionPrediction& p, const SE2& taken) {
  if (std::abs(taken.theta()) > opt_.prior_gate_sigmas * p.sigma_rad) heading_override_ = taken;
}

void MotionPrior::widenAfterOverride(MotionPrediction& p) {
  if (!heading_override_) return;
  p.sigma_m = std::max(p.sigma_m, 0.5 * heading_override_->translation().norm());
  p.sigma_rad = std::max(p.sigma_rad, 0.5 * std::abs(heading_override_->theta()));
  heading_override_.reset();
}

double MotionPrior::usualInterval() const {
  if (recent_intervals_.empty()) return 0.0;
  return upperMedian(std::vector<double>(recent_intervals_.begin(), recent_intervals_.end()));
}

/// Scans logged in bursts under one stamp (a driver that stamps a batch of scans when it sends
/// it) make the median interval 0, and every burst's first scan then came a "gap" after the last:
/// with bursts of three at 1 Hz, a gap every third scan, each one ending the odometry's trust
/// (orebro: 78 gaps, 2 fragments). There the time a scan took on average, the mean of the recent
/// intervals, is the reference (and a burst's time is shared by its scans: predictImpl); elsewhere
/// the median (one long pause must not hide the next).
double MotionPrior::intervalForGaps(double usual) const {
  if (usual > 0.0 || recent_intervals_.empty()) return usual;
  double sum = 0.0;
  for (const double dt : recent_intervals_) sum += dt;
  return sum / static_cast<double>(recent_intervals_.size());
}

MotionPrediction MotionPrior::predictImpl(const Frame& f) {
  MotionPrediction p;
  const bool odometry = opt_.use_odometry && f.T_odom_robot.has_value();
  odom_scaled_.reset();
  if (!have_prev_) {
    odometry_seen_ = odometry;
    if (odometry) odom_scaled_ = p.T_odom_scaled = f.T_odom_robot;
    return p;
  }
  const double dt = f.time - time_prev_;
  const double usual = usualInterval();
  const double between = intervalForGaps(usual);
  // After k scans that repeated the previous stamp, the k + 1 scans up to this one were taken over
  // dt: each took dt / (k + 1).
  const double per_scan = dt / static_cast<double>(1 + repeated_);
  if (!(dt >= 0.0)) {
    notes_.push_back(fmt::format("time goes backwards by {:.3f} s", -dt));
    p.time_ok = false;
  } else if (!recent_intervals_.empty() && per_scan > opt_.time_gap_s && (between <= 0.0 || per_scan > 5.0 * between)) {
    // Relative to the log's usual interval: keyframe logs are seconds apart on every scan. The
    // log's first interval has none to be measured against and is no gap: a keyframe log's first
    // step takes seconds, and a gap there would leave the odometry untrusted until a scan matched a
    // local map of one scan (keyframes metres apart match none, and the track is lost at once).
    notes_.push_back(fmt::format("gap of {:.1f} s in the log", dt));
    p.time_ok = false;
  }
  // The time the step took (for the sigmas): its stamps' difference, or the usual interval when
  // the stamps do not say (repeated or going backwards); 0 when no interval is known at all.
  p.dt = dt > 0.0 && std::isfinite(dt) ? dt : usual;

  if (odometry) {
    // The odometry's step since the previous scan that had odometry, and that step with its
    // translation scaled (appliedScale): the prediction's, and the scaled chain's (the odometry
    // itself when not scaled).
    const std::optional<SE2> step =
        odom_prev_ ? std::optional<SE2>(odom_prev_->inverse() * *f.T_odom_robot) : std::nullopt;
    const SE2 scaled_step = step ? SE2(appliedScale() * step->translation(), step->theta()) : SE2();
    p.T_odom_scaled = step && opt_.scale_odometry ? *odom_scaled_prev_ * scaled_step : *f.T_odom_robot;
    odom_scaled_ = p.T_odom_scaled;
    // After scans without odometry, or with a frozen reading, the step from the last reading spans
    // all of them: it says where the robot is, not the step from the previous scan, and over one
    // scan interval it would be called implausible.
    bool spans_more = false;
    if (odometry_missing_) {
      notes_.push_back(fmt::format(
          "odometry back after {} scans without it: its first step spans them, constant-velocity prior for this scan",
          odometry_missing_count_));
      odometry_missing_ = false;
      spans_more = true;
    }
    odometry_seen_ = true;
    p.odometry_still = step && !spans_more && f.T_odom_robot->isApprox(*odom_prev_, 0.0, 0.0);
    if (odometry_frozen_ && !p.odometry_still) {
      notes_.push_back(
          fmt::format("odometry reads another pose after {} scans ({:.1f} s) on one: its first step spans "
                      "them, constant-velocity prior for this scan",
                      still_count_, std::max(0.0, time_prev_ - still_since_)));
      odometry_frozen_ = false;
      spans_more = true;
    }
    still_count_ = p.odometry_still ? still_count_ + 1 : 0;
    const std::optional<SE2> usable = spans_more || odometry_frozen_ ? std::nullopt : step;
    // Plausible against the time the step took, not against fixed per-step limits: a gap of
    // seconds during a turn is a long step, and keyframe logs hold metres between scans. At least
    // the usual interval: a scan stamped a millisecond after the previous one (the Intel bag has
    // runs of them) was not taken then.
    auto tooFar = [&](const SE2& d, double took) {
      return took > 0.0 && d.translation().norm() > opt_.max_speed_m_per_s * took;
    };
    auto tooTurned = [&](const SE2& d, double took) {
      return took > 0.0 && std::abs(d.theta()) > opt_.max_turn_rate_rad_per_s * took;
    };
    auto plausibleOver = [&](const SE2& d, double took) {
      return d.isFinite() && !tooFar(d, took) && !tooTurned(d, took);
    };
    const double took = std::max(p.dt, usual);
    std::optional<SE2> step_used = usable;
    bool plausible = usable && plausibleOver(*usable, took);
    // After an implausible step that this reading takes back (since the reading before it the
    // odometry turned less than in that step alone, if the turn made it implausible, and moved less,
    // if the distance did; and plausibly over both steps' time): the odometry since then, less the
    // step the previous scan took. Odometry read off its scan's time in a turn (a lag) errs one way
    // on one step and back on the next, and the motion of the step it was dropped for is not lost.
    // A jump the odometry keeps is not taken back.
    if (anchor_ && usable) {
      const SE2 span = anchor_->odom.inverse() * *f.T_odom_robot;
      const SE2& bad = anchor_->implausible;
      const bool taken_back = (!anchor_->too_far || span.translation().norm() < bad.translation().norm()) &&
                              (!anchor_->too_turned || std::abs(span.theta()) < std::abs(bad.theta()));
      if ((taken_back || !anchor_->pinned) && plausibleOver(span, std::max(f.time - anchor_->time, usual))) {
        step_used = anchor_->taken.inverse() * span;
        plausible = step_used->isFinite();
        notes_.push_back(
            "the odometry takes back the previous scan's implausible step: this step is taken from "
            "the reading before it");
      }
    }
    anchor_.reset();
    pending_anchor_.reset();
    if (usable && !plausible && usable->isFinite() && odom_prev_)
      pending_anchor_ =
          OdometryAnchor{*odom_prev_, time_prev_, *usable, tooFar(*usable, took), tooTurned(*usable, took), SE2()};
    if (usable) {
      const SE2& d = *step_used;
      const double dist = d.translation().norm(), turn = std::abs(d.theta());
      if (plausible) {
        const bool time_ok = p.time_ok;
        const double step_dt = p.dt;
        const std::optional<SE2> scaled = p.T_odom_scaled;
        const bool still = p.odometry_still;
        p = odometryPrediction(opt_, SE2(appliedScale() * d.translation(), d.theta()), step_dt);
        narrowToOdometryNoise(p);
        p.odometry_step = d;
        p.T_odom_scaled = scaled;
        p.time_ok = time_ok;
        p.odometry_still = still;
      } else {
        notes_.push_back(
            d.isFinite()
                ? fmt::format("odometry step of {:.2f} m / {:.1f} deg in {:.2f} s is not plausible: "
                              "constant-velocity prior, the scan decides",
                              dist, turn / kDeg, p.dt)
                : std::string("odometry step is not finite: constant-velocity prior"));
        if (d.isFinite()) p.implausible_odometry = d;
      }
    }
  } else if (opt_.use_odometry && odometry_seen_) {
    if (!odometry_missing_) notes_.push_back("scans without odometry from here: constant-velocity prediction");
    odometry_missing_ = true;
    ++odometry_missing_count_;
  }
  if (p.source != PriorSource::kOdometry) {
    p.source = PriorSource::kConstantVelocity;
    p.delta = p.time_ok ? velocityStep() : SE2();
    // Without an interval (every stamp equal) a second per step: the wide end.
    const double t = p.dt > 0.0 ? p.dt : 1.0;
    p.sigma_m = opt_.prior_velocity_sigma_m + opt_.prior_velocity_sigma_m_per_s * t;
    p.sigma_rad = opt_.prior_velocity_sigma_rad + opt_.prior_velocity_sigma_rad_per_s * t;
    narrowToSpread(p);
  }
  return p;
}

void MotionPrior::remember(const Frame& f, const MotionPrediction& p, const SE2& step, bool first, bool pinned) {
  const bool time_ok = p.time_ok;
  if (!p.odometry_still) {
    still_span_ = SE2();
    still_since_ = f.time;
  } else if (!odometry_frozen_) {
    still_span_ = still_span_ * step;
    const double held = f.time - still_since_;
    const MotionPrediction standing = odometryPrediction(opt_, SE2(), std::isfinite(held) ? held : 0.0);
    const double sigmas = standing.distance(still_span_);
    if (sigmas > opt_.prior_gate_sigmas) {
      odometry_frozen_ = true;
      notes_.push_back(fmt::format(
          "odometry frozen: it read the same pose for {:.1f} s while the scans moved the robot "
          "{:.2f} m / {:.1f} deg ({:.1f} sigmas): constant-velocity prior, and no odometry "
          "links, until it reads another pose",
          std::max(0.0, held), still_span_.translation().norm(), std::abs(still_span_.theta()) / kDeg, sigmas));
    }
  }
  if (!first && pending_anchor_) {
    anchor_ = std::move(pending_anchor_);
    anchor_->taken = step;
    anchor_->pinned = pinned;
  }
  pending_anchor_.reset();
  if (!first) {
    // A gap: the robot may have stopped, so the velocity starts again from a standstill. A scan
    // stamped before the previous one says nothing of the velocity (it may have been taken earlier,
    // or its clock slipped): the history stays.
    const bool backwards = f.time < time_prev_;
    if (!time_ok && !backwards) {
      recent_steps_.clear();
      recent_steps_.push_back(SE2());
      spread_steps_.clear();
    } else if (time_ok && pinned) {
      recent_steps_.push_back(step);
      spread_steps_.push_back(step);
    }
    if (recent_steps_.size() > kVelocitySteps) recent_steps_.pop_front();
    if (spread_steps_.size() > kSpreadSteps) spread_steps_.pop_front();
    // Repeated stamps count (as 0): in a log whose stamps mostly repeat they do not say how long a
    // step took, and one absurd interval among them (a clock wrapping) must not become the usual one.
    const double dt = f.time - time_prev_;
    if (dt >= 0.0 && std::isfinite(dt)) {
      recent_intervals_.push_back(dt);
      if (recent_intervals_.size() > kIntervals) recent_intervals_.pop_front();
    }
    repeated_ = dt == 0.0 ? repeated_ + 1 : 0;
  }
  have_prev_ = true;
  time_prev_ = f.time;
  if (f.T_odom_robot && odom_scaled_) {
    odom_prev_ = f.T_odom_robot;
    odom_scaled_prev_ = odom_scaled_;
  }
}

/// Without odometry, sigmas that grow with time are honest for a log of a few scans per second, but
/// on a keyframe log (a second or more between scans) they reach metres and hundreds of degrees: a
/// flat prior, under which a scan matched backwards along a corridor or turned half a circle wins
/// whenever it explains a few points more than the right match (measured on the corrected logs
/// without odometry: steps of 1 m and 30 degrees, matches 2-3 m back and 180 degrees off chosen).
/// The robot's own recent steps say how much the next one may differ from the prediction: in a log
/// whose usual interval grows the sigmas beyond the correlative search's largest window, each sigma
/// is at most `prior_velocity_spread_sigmas` times the root-mean-square deviation of the last
/// kSpreadSteps steps from their component-wise median (per axis). In a keyframe log the time
/// between scans says little of the motion (the keyframing's thresholds do). Across a gap, and until
/// the history fills again, the prior is as wide as the time makes it.
void MotionPrior::narrowToSpread(MotionPrediction& p) const {
  const double k = opt_.prior_velocity_spread_sigmas;
  if (k <= 0.0 || !p.time_ok || spread_steps_.size() < kMinSpreadSteps) return;
  // The log's usual interval (a second when the stamps do not say) decides, not this step's: in a
  // log of several scans per second a pause keeps the prior that time gives it.
  const double usual = usualInterval() > 0.0 ? usualInterval() : 1.0;
  if (3.0 * (opt_.prior_velocity_sigma_m + opt_.prior_velocity_sigma_m_per_s * usual) <=
          opt_.search_max_linear_window_m &&
      3.0 * (opt_.prior_velocity_sigma_rad + opt_.prior_velocity_sigma_rad_per_s * usual) <=
          opt_.search_max_angular_window_rad)
    return;
  const std::size_t n = spread_steps_.size();
  std::vector<double> x(n), y(n), th(n);
  for (std::size_t i = 0; i < n; ++i) {
    x[i] = spread_steps_[i].x();
    y[i] = spread_steps_[i].y();
    th[i] = spread_steps_[i].theta();
  }
  const double mx = upperMedian(x), my = upperMedian(y), mth = upperMedian(th);
  double ss_m = 0.0, ss_rad = 0.0;
  for (std::size_t i = 0; i < n; ++i) {
    ss_m += (x[i] - mx) * (x[i] - mx) + (y[i] - my) * (y[i] - my);
    ss_rad += angleDiff(th[i], mth) * angleDiff(th[i], mth);
  }
  const double spread_m = std::sqrt(ss_m / (2.0 * static_cast<double>(n)));
  const double spread_rad = std::sqrt(ss_rad / static_cast<double>(n));
  // At least half the smallest correlative window: a robot that drove straight for twenty steps
  // may still turn by a keyframe's threshold on the next (the simulated open world's keyframes: a
  // 37 degree turn after twenty straight steps was lost under the spread alone).
  p.sigma_m = std::min(p.sigma_m, std::max(0.5 * opt_.fallback_linear_window_m, k * spread_m));
  p.sigma_rad = std::min(p.sigma_rad, std::max(0.5 * opt_.fallback_angular_window_rad, k * spread_rad));
  p.from_spread = true;
}

std::optional<SE2> MotionPrior::stepTurning(double turn) const {
  std::vector<double> x, y;
  for (const SE2& s : spread_steps_) {
    if (std::abs(angleDiff(s.theta(), turn)) > kSimilarTurnRad) continue;
    x.push_back(s.x());
    y.push_back(s.y());
  }
  if (x.size() < kMinSimilarSteps) return std::nullopt;
  return SE2(upperMedian(std::move(x)), upperMedian(std::move(y)), turn);
}

/// The constant-velocity step: the component-wise median (x, y, theta) of the last
/// `kVelocitySteps` steps, identity before the first. Not the last step alone: a scan stamped out
/// of order (the Intel bag has some) matches 0.1-0.2 m behind its neighbours, and repeating that
/// step along a corridor - where the scan cannot correct the prediction's translation along it
/// (degeneracy) - drove the estimate backwards by that much on every scan until the corridor
/// ended (metres of error without odometry).
SE2 MotionPrior::velocityStep() const {
  if (recent_steps_.empty()) return SE2();
  std::vector<double> x, y, th;
  for (const SE2& s : recent_steps_) {
    x.push_back(s.x());
    y.push_back(s.y());
    th.push_back(s.theta());
  }
  return SE2(upperMedian(std::move(x)), upperMedian(std::move(y)), upperMedian(std::move(th)));
}

}  // namespace lidar2d::slam::internal
