#include "lidar2d/sim/log_perturbation.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <numeric>
#include <utility>

#include "lidar2d/core/error.hpp"

namespace lidar2d::sim {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

// The truth that odometry is made from; the same message from both passes.
const SE2& requireTruth(const Frame& f) {
  if (!f.T_world_robot)
    throw badInput(
        fmt::format("scan {} (time {:.6f}) has no ground-truth pose; odometry made from the truth needs a "
                    "log with truth (TRUEPOS lines, or a SLAM-corrected CARMEN log)",
                    f.index, f.time));
  return *f.T_world_robot;
}

// The reference pose of step 3 (truth, or the log's odometry), or an error naming what needs it.
const SE2& requireReference(const Frame& f, bool use_truth, const char* needed_by) {
  const std::optional<SE2>& ref = use_truth ? f.T_world_robot : f.T_odom_robot;
  if (!ref)
    throw badInput(fmt::format("scan {} (time {:.6f}) has no {} pose, which {} need", f.index, f.time,
                               use_truth ? "ground-truth" : "odometry", needed_by));
  return *ref;
}

// A heading change in integer nanoradians: sums of them are exact and independent of the order of
// summation, so equal turns compare equal and ties go to the earliest window (1e-9 rad per pair of
// frames is far below any turn that matters; 1e6 frames of pi each stay below 2^63).
std::int64_t nanoRadians(double a) { return std::llround(a * 1e9); }

// A Fenwick tree (Fenwick 1994) of integer weights: prefix sums in O(log n).
class Fenwick {
 public:
  explicit Fenwick(std::size_t n) : tree_(n + 1, 0) {}
  void add(std::size_t i, std::int64_t w) {
    for (++i; i < tree_.size(); i += i & (~i + 1)) tree_[i] += w;
  }
  // Sum of the weights at positions [0, n).
  std::int64_t prefix(std::size_t n) const {
    std::int64_t s = 0;
    for (; n > 0; n -= n & (~n + 1)) s += tree_[n];
    return s;
  }

 private:
  std::vector<std::int64_t> tree_;
};

struct Window {
  double begin_s, end_s;
};

bool overlaps(const Window& a, const GapWindow& b) { return a.end_s > b.begin_s && a.begin_s < b.end_s; }

// The kLargestTurn placement: among the candidate windows that fit, the one with the largest turn.
// turn(w) = sum of w_j over pairs j with lo_j >= begin and hi_j < end, computed for all candidates
// at once: candidates by decreasing begin, pairs inserted once their lo reaches the begin, the hi
// condition a prefix sum over the pairs' his in increasing order.
std::optional<Window> largestTurnWindow(const std::vector<TimedPose>& samples, double duration_s,
                                        const std::vector<GapWindow>& placed) {
  const double t_first = samples.front().time_s, t_last = samples.back().time_s;
  std::vector<Window> candidates;
  auto consider = [&](Window w) {
    if (!(w.begin_s >= t_first && w.end_s <= t_last)) return;
    for (const GapWindow& p : placed)
      if (overlaps(w, p)) return;
    candidates.push_back(w);
  };
  for (const TimedPose& s : samples) consider({s.time_s, s.time_s + duration_s});
  consider({t_last - duration_s, t_last});
  for (const GapWindow& p : placed) consider({p.begin_s - duration_s, p.begin_s});
  if (candidates.empty()) return std::nullopt;

  struct Pair {
    double lo, hi;
    std::int64_t w;
  };
  std::vector<Pair> pairs;
  pairs.reserve(samples.size());
  for (std::size_t j = 0; j + 1 < samples.size(); ++j) {
    const double a = samples[j].time_s, b = samples[j + 1].time_s;
    const double turn = std::abs(angleDiff(samples[j + 1].T_world_robot.theta(), samples[j].T_world_robot.theta()));
    pairs.push_back({std::min(a, b), std::max(a, b), nanoRadians(turn)});
  }
  std::vector<double> his(pairs.size());
  std::transform(pairs.begin(), pairs.end(), his.begin(), [](const Pair& p) { return p.hi; });
  std::sort(his.begin(), his.end());
  std::sort(pairs.begin(), pairs.end(), [](const Pair& a, const Pair& b) { return a.lo > b.lo; });
  std::vector<std::size_t> order(candidates.size());
  std::iota(order.begin(), order.end(), std::size_t{0});
  std::sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) {
    return candidates[a].begin_s > candidates[b].begin_s ||
           (candidates[a].begin_s == candidates[b].begin_s && candidates[a].end_s > candidates[b].end_s);
  });

  Fenwick tree(his.size());
  std::size_t next_pair = 0;
  std::int64_t best_turn = -1;
  Window best{};
  for (std::size_t c : order) {
    const Window& w = candidates[c];
    for (; next_pair < pairs.size() && pairs[next_pair].lo >= w.begin_s; ++next_pair) {
      const auto rank = std::lower_bound(his.begin(), his.end(), pairs[next_pair].hi) - his.begin();
      tree.add(static_cast<std::size_t>(rank), pairs[next_pair].w);
    }
    const auto below = std::lower_bound(his.begin(), his.end(), w.end_s) - his.begin();  // his < end
    const std::int64_t turn = tree.prefix(static_cast<std::size_t>(below));
    // Candidates come latest first: >= lets an equal turn move the choice to the earlier window.
    if (turn >= best_turn) {
      best_turn = turn;
      best = w;
    }
  }
  return best;
}

}  // namespace

OdometryNoise realisticOdometryNoise() {
  OdometryNoise n = OdometryNoise::none();
  n.sigma_x_m = 0.005;
  n.sigma_y_m = 0.005;
  n.trans_sigma_per_m = 0.03;
  n.rot_sigma_per_rad = 0.03;
  n.rot_sigma_per_m = std::numbers::pi / 180.0;
  n.scale_bias = 0.02;
  return n;
}

void KeyframeOptions::validate() const {
  if (!std::isfinite(min_distance_m) || min_distance_m < 0)
    throw invalidArgument(fmt::format("keyframe distance must be finite and >= 0, got {}", min_distance_m),
                          ErrorLocation({}, 0, "min_distance_m"));
  if (!std::isfinite(min_turn_rad) || min_turn_rad < 0 || min_turn_rad > std::numbers::pi)
    throw invalidArgument(fmt::format("keyframe turn must be in [0, pi] rad, got {}", min_turn_rad),
                          ErrorLocation({}, 0, "min_turn_rad"));
}

void GapRequest::validate() const {
  if (!std::isfinite(duration_s) || duration_s <= 0)
    throw invalidArgument(fmt::format("gap duration must be finite and > 0, got {}", duration_s),
                          ErrorLocation({}, 0, "duration_s"));
  if (placement == GapPlacement::kAtOffset && (!std::isfinite(offset_s) || offset_s < 0))
    throw invalidArgument(fmt::format("gap start must be finite and >= 0, got {}", offset_s),
                          ErrorLocation({}, 0, "offset_s"));
  if (carried && frozen_odometry)
    throw invalidArgument("a window is either carried (its scans dropped) or freezes the odometry (its scans kept)",
                          ErrorLocation({}, 0, "frozen_odometry"));
  if (odometry_slip && (carried || frozen_odometry))
    throw invalidArgument("a window of odometry slip is neither carried nor frozen",
                          ErrorLocation({}, 0, "odometry_slip"));
  if (!std::isfinite(slip_m) || !std::isfinite(slip_rad))
    throw invalidArgument(fmt::format("odometry slip must be finite, got {} m, {} rad", slip_m, slip_rad),
                          ErrorLocation({}, 0, "slip_m"));
}

void TimeFaults::validate() const {
  if (!std::isfinite(synthesize_rate_hz) || synthesize_rate_hz < 0)
    throw invalidArgument(fmt::format("synthesized rate must be finite and >= 0, got {}", synthesize_rate_hz),
                          ErrorLocation({}, 0, "synthesize_rate_hz"));
  if (!std::isfinite(jitter_sigma_s) || jitter_sigma_s < 0)
    throw invalidArgument(fmt::format("time jitter must be finite and >= 0, got {}", jitter_sigma_s),
                          ErrorLocation({}, 0, "jitter_sigma_s"));
  if (burst_size == 0) throw invalidArgument("burst size must be >= 1", ErrorLocation({}, 0, "burst_size"));
}

void OdometryLag::validate() const {
  if (!std::isfinite(mean_s))
    throw invalidArgument(fmt::format("odometry lag must be finite, got {}", mean_s), ErrorLocation({}, 0, "mean_s"));
  if (!std::isfinite(sigma_s) || sigma_s < 0)
    throw invalidArgument(fmt::format("odometry lag sigma must be finite and >= 0, got {}", sigma_s),
                          ErrorLocation({}, 0, "sigma_s"));
}

SE2 truthAt(const std::vector<TimedPose>& timeline, std::size_t index, double t_s) {
  if (index >= timeline.size())
    throw invalidArgument(fmt::format("frame {} is not in the truth timeline of {} frames", index, timeline.size()),
                          ErrorLocation({}, 0, "truth_timeline"));
  auto between = [&](std::size_t a, std::size_t b) {
    const TimedPose& p = timeline[a];
    const TimedPose& q = timeline[b];
    const double f = (t_s - p.time_s) / (q.time_s - p.time_s);
    const Eigen::Vector2d xy =
        p.T_world_robot.translation() + f * (q.T_world_robot.translation() - p.T_world_robot.translation());
    return SE2(xy.x(), xy.y(),
               p.T_world_robot.theta() + f * angleDiff(q.T_world_robot.theta(), p.T_world_robot.theta()));
  };
  std::size_t j = index;
  if (t_s == timeline[j].time_s) return timeline[j].T_world_robot;
  if (t_s > timeline[j].time_s) {
    // Forward to the first frame later than t_s; the one before it opens the bracket.
    while (j + 1 < timeline.size() && timeline[j + 1].time_s <= t_s) ++j;
    if (j + 1 < timeline.size() && timeline[j + 1].time_s > timeline[j].time_s) return between(j, j + 1);
    return timeline[j].T_world_robot;
  }
  // Back to the last frame of the run later than t_s; the one before it opens the bracket.
  while (j > 0 && timeline[j - 1].time_s > t_s) --j;
  if (j > 0) return between(j - 1, j);
  return timeline[0].T_world_robot;
}

void LogPerturbationOptions::validate() const {
  if (odometry_source == OdometrySource::kNoisyFromTruth) odometry.validate();
  odometry_lag.validate();
  if (odometry_lag.enabled()) {
    if (odometry_source != OdometrySource::kNoisyFromTruth)
      throw invalidArgument("an odometry lag needs odometry made from the truth, not the log's own",
                            ErrorLocation({}, 0, "odometry_lag"));
    if (truth_timeline.empty())
      throw invalidArgument("an odometry lag needs the log's truth timeline (GapPlanner::samples)",
                            ErrorLocation({}, 0, "truth_timeline"));
  }
  keyframes.validate();
  time.validate();
  for (const GapWindow& g : gaps)
    if (!(std::isfinite(g.begin_s) && std::isfinite(g.end_s) && g.begin_s <= g.end_s))
      throw invalidArgument(fmt::format("gap window [{}, {}) is not a finite interval", g.begin_s, g.end_s),
                            ErrorLocation({}, 0, "gaps"));
}

double clockTime(const TimeFaults& time, double first_stamp_s, std::size_t index, double stamp_s) {
  if (time.synthesize_rate_hz > 0) return first_stamp_s + static_cast<double>(index) / time.synthesize_rate_hz;
  return stamp_s;
}

double turnInWindow(const std::vector<TimedPose>& samples, double begin_s, double end_s) {
  auto inside = [&](double t) { return t >= begin_s && t < end_s; };
  double turn = 0.0;
  for (std::size_t j = 0; j + 1 < samples.size(); ++j)
    if (inside(samples[j].time_s) && inside(samples[j + 1].time_s))
      turn += std::abs(angleDiff(samples[j + 1].T_world_robot.theta(), samples[j].T_world_robot.theta()));
  return turn;
}

std::vector<GapWindow> planGaps(const std::vector<GapRequest>& requests, const std::vector<TimedPose>& samples) {
  for (const GapRequest& r : requests) r.validate();
  if (requests.empty()) return {};
  if (samples.empty()) throw badInput("cannot place gaps in a log without scans");
  const double t_first = samples.front().time_s, t_last = samples.back().time_s;
  const double span = t_last - t_first;
  auto noRoom = [&](const GapRequest& r) {
    return badInput(
        fmt::format("a gap of {} s does not fit in the log, which spans {} s from its first to its last "
                    "scan{}",
                    r.duration_s, span, span <= 0 ? " (its timestamps do not advance)" : ""));
  };

  std::vector<std::optional<GapWindow>> placed(requests.size());
  std::vector<GapWindow> so_far;
  // Fixed windows first, so that the largest-turn ones avoid them.
  for (std::size_t k = 0; k < requests.size(); ++k) {
    const GapRequest& r = requests[k];
    if (r.placement == GapPlacement::kLargestTurn) continue;
    if (r.duration_s > span) throw noRoom(r);
    GapWindow w;
    w.request = r;
    w.begin_s = t_first + (r.placement == GapPlacement::kMiddle ? (span - r.duration_s) / 2 : r.offset_s);
    w.end_s = w.begin_s + r.duration_s;
    if (w.end_s > t_last)
      throw badInput(
          fmt::format("a gap from {} s to {} s after the first scan ends after the last scan, {} s after "
                      "the first",
                      w.begin_s - t_first, w.end_s - t_first, span));
    placed[k] = w;
    so_far.push_back(w);
  }
  for (std::size_t k = 0; k < requests.size(); ++k) {
    const GapRequest& r = requests[k];
    if (r.placement != GapPlacement::kLargestTurn) continue;
    if (r.duration_s > span) throw noRoom(r);
    const std::optional<Window> w = largestTurnWindow(samples, r.duration_s, so_far);
    if (!w)
      throw badInput(fmt::format("no room for a gap of {} s at a turn beside the other gaps (the log spans {} s)",
                                 r.duration_s, span));
    GapWindow g;
    g.request = r;
    g.begin_s = w->begin_s;
    g.end_s = w->end_s;
    placed[k] = g;
    so_far.push_back(g);
  }
  std::vector<GapWindow> out;
  out.reserve(requests.size());
  for (auto& w : placed) {
    w->turn_rad = turnInWindow(samples, w->begin_s, w->end_s);
    out.push_back(*w);
  }
  return out;
}

GapPlanner::GapPlanner(std::vector<GapRequest> requests, OdometrySource source, TimeFaults time)
    : requests_(std::move(requests)), source_(source), time_(time) {
  for (const GapRequest& r : requests_) {
    r.validate();
    if (r.placement == GapPlacement::kLargestTurn) need_poses_ = true;
  }
  time_.validate();
}

void GapPlanner::add(const Frame& frame) {
  const std::size_t i = samples_.size();
  if (i == 0) {
    first_stamp_s_ = frame.time;
    use_truth_ = source_ == OdometrySource::kNoisyFromTruth || frame.T_world_robot.has_value();
  }
  if (source_ == OdometrySource::kNoisyFromTruth) requireTruth(frame);
  const std::optional<SE2>& ref = use_truth_ ? frame.T_world_robot : frame.T_odom_robot;
  if (!ref) {
    if (need_poses_) requireReference(frame, use_truth_, "gaps placed at the largest turn");
    poses_complete_ = false;
  }
  samples_.push_back({clockTime(time_, first_stamp_s_, i, frame.time), ref.value_or(SE2())});
}

std::vector<GapWindow> GapPlanner::plan() const {
  std::vector<GapWindow> windows = planGaps(requests_, samples_);
  if (!poses_complete_)
    for (GapWindow& w : windows) w.turn_rad = kNaN;
  return windows;
}

LogPerturber::LogPerturber(LogPerturbationOptions options)
    : options_(std::move(options)),
      odom_rng_(options_.seed),
      jitter_rng_(options_.seed ^ kJitterSeedSalt),
      lag_rng_(options_.seed ^ kLagSeedSalt) {
  options_.validate();
  stats_.dropped_per_gap.assign(options_.gaps.size(), 0);
}

std::vector<Frame> LogPerturber::push(Frame f) {
  const std::size_t i = stats_.scans_read++;
  const bool from_truth = options_.odometry_source == OdometrySource::kNoisyFromTruth;
  if (i == 0) {
    first_stamp_s_ = f.time;
    use_truth_ = from_truth || f.T_world_robot.has_value();
  }
  const double t = clockTime(options_.time, first_stamp_s_, i, f.time);
  if (from_truth) {
    const SE2& truth = requireTruth(f);
    if (i == 0) {  // odom_0 = truth_0, whether frame 0 is kept or not
      odom_ = truth;
      prev_truth_ = odometryReadingPoint(f, i, t);
    }
  }

  bool in_gap = false, frozen = false;
  for (std::size_t k = 0; k < options_.gaps.size(); ++k)
    if (options_.gaps[k].contains(t)) {
      ++stats_.dropped_per_gap[k];
      if (options_.gaps[k].request.odometry_slip) continue;  // kept: slipped below
      if (options_.gaps[k].request.frozen_odometry) {
        frozen = true;
        continue;
      }
      in_gap = true;
      if (options_.gaps[k].request.carried && stats_.scans_kept > 0) carried_ = true;
    }
  if (in_gap) {
    ++stats_.dropped_by_gaps;
    return {};
  }

  const KeyframeOptions& kf = options_.keyframes;
  if (kf.enabled()) {
    const SE2& ref = requireReference(f, use_truth_, "keyframes");
    if (last_kept_reference_) {
      const double moved = (ref.translation() - last_kept_reference_->translation()).norm();
      const double turned = std::abs(angleDiff(ref.theta(), last_kept_reference_->theta()));
      const bool keep =
          (kf.min_distance_m > 0 && moved >= kf.min_distance_m) || (kf.min_turn_rad > 0 && turned >= kf.min_turn_rad);
      if (!keep) {
        ++stats_.dropped_by_keyframes;
        return {};
      }
    }
    last_kept_reference_ = ref;
  }

  if (from_truth) {
    const SE2 truth = odometryReadingPoint(f, i, t);
    // One noisy step from the last integration point: across dropped frames, the whole motion;
    // across a carried gap, none.
    const SE2 step = carried_ ? SE2() : prev_truth_.inverse() * truth;
    if (i > 0) odom_ = odom_ * noisyOdometryStep(step, options_.odometry, odom_rng_);
    prev_truth_ = truth;
    f.T_odom_robot = odom_;
  } else if (f.T_odom_robot) {
    if (carried_ && stats_.last_T_odom_robot) log_odom_shift_ = *stats_.last_T_odom_robot * f.T_odom_robot->inverse();
    if (log_odom_shift_) f.T_odom_robot = *log_odom_shift_ * *f.T_odom_robot;
  }
  carried_ = false;
  if (frozen && f.T_odom_robot) {
    if (!frozen_reading_) frozen_reading_ = stats_.last_T_odom_robot.value_or(*f.T_odom_robot);
    f.T_odom_robot = frozen_reading_;
    ++stats_.frozen_odometry;
  } else if (!frozen) {
    frozen_reading_.reset();
  }
  f.T_odom_robot = slipped(f.T_odom_robot, t);
  f.time = t;
  if (options_.time.jitter_sigma_s > 0) f.time += jitter_rng_.gaussian(options_.time.jitter_sigma_s);
  ++stats_.scans_kept;
  stats_.last_T_odom_robot = f.T_odom_robot;
  stats_.last_T_world_robot = f.T_world_robot;
  burst_.push_back(std::move(f));
  if (burst_.size() >= options_.time.burst_size) return flush();
  return {};
}

std::optional<SE2> LogPerturber::slipped(const std::optional<SE2>& odom, double t) {
  if (!odom) return odom;
  SE2 extra;
  bool slips = false;
  for (const GapWindow& g : options_.gaps) {
    if (!g.request.odometry_slip) continue;
    slips = true;
    if (!slip_read_prev_) continue;
    const double overlap = std::min(t, g.end_s) - std::max(slip_t_prev_, g.begin_s);
    if (overlap <= 0.0 || g.end_s <= g.begin_s) continue;
    const double f = overlap / (g.end_s - g.begin_s);
    extra = extra * SE2(f * g.request.slip_m, 0.0, f * g.request.slip_rad);
  }
  if (!slips) return odom;
  SE2 out = *odom;
  if (slip_read_prev_) {
    if (extra.translation().squaredNorm() > 0.0 || extra.theta() != 0.0) ++stats_.slipped_odometry;
    out = *slip_out_prev_ * (slip_read_prev_->inverse() * *odom) * extra;
  }
  slip_read_prev_ = odom;
  slip_out_prev_ = out;
  slip_t_prev_ = t;
  return out;
}

SE2 LogPerturber::odometryReadingPoint(const Frame& frame, std::size_t index, double t) {
  const OdometryLag& lag = options_.odometry_lag;
  if (!lag.enabled()) return *frame.T_world_robot;
  const double offset = lag.mean_s + (lag.sigma_s > 0 ? lag_rng_.gaussian(lag.sigma_s) : 0.0);
  return truthAt(options_.truth_timeline, index, t + offset);
}

std::vector<Frame> LogPerturber::finish() { return flush(); }

std::vector<Frame> LogPerturber::flush() {
  if (!burst_.empty()) {
    // A burst is delivered at once: every frame carries the time of the last one.
    const double t = burst_.back().time;
    for (Frame& f : burst_) f.time = t;
  }
  std::vector<Frame> out;
  out.swap(burst_);
  return out;
}

std::vector<Frame> perturbLog(const std::vector<Frame>& frames, LogPerturbationOptions options,
                              const std::vector<GapRequest>& gaps, PerturbationStats* stats) {
  const bool lag = options.odometry_lag.enabled() && options.odometry_source == OdometrySource::kNoisyFromTruth;
  if (!gaps.empty() || lag) {
    GapPlanner planner(gaps, options.odometry_source, options.time);
    for (const Frame& f : frames) planner.add(f);
    for (const GapWindow& w : planner.plan()) options.gaps.push_back(w);
    if (lag) options.truth_timeline = planner.samples();
  }
  LogPerturber perturber(std::move(options));
  std::vector<Frame> out;
  auto append = [&out](std::vector<Frame> ready) {
    for (Frame& f : ready) out.push_back(std::move(f));
  };
  for (const Frame& f : frames) append(perturber.push(f));
  append(perturber.finish());
  if (stats) *stats = perturber.stats();
  return out;
}

}  // namespace lidar2d::sim
