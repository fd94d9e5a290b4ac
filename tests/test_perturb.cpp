// sim::LogPerturber and sim::planGaps (the library of `lidar2d perturb`) on simulated logs: the
// defaults reproduce perturb's original loop, keyframe spacing, gap windows (the largest-turn window
// against a brute-force search), odometry across gaps, the realistic model's statistics, timestamp
// faults, kept odometry, determinism and bad input.

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>

#include "lidar2d/core/error.hpp"
#include "lidar2d/sim/log_perturbation.hpp"
#include "lidar2d/sim/noise.hpp"
#include "lidar2d/sim/path.hpp"
#include "lidar2d/sim/simulator.hpp"
#include "lidar2d/sim/worlds.hpp"
#include "support/test_support.hpp"

namespace lidar2d::sim {
namespace {

constexpr double kPi = std::numbers::pi;
constexpr double kDeg = kPi / 180.0;
using lidar2d::test::IsNearPose;
using lidar2d::test::throwsError;

using lidar2d::test::Stats;

// A simulated log along a built-in world's route (few beams: the scans only ride along).
std::vector<Frame> simulatedLog(const std::string& world, std::size_t scans = 0) {
  const Scenario s = builtinScenario(world);
  SimulatorOptions o;
  o.laser.beams = 9;
  o.seed = 4;
  return simulate(s.world, samplePath(s.waypoints, PathOptions{}, scans), o);
}

std::vector<TimedPose> truthSamples(const std::vector<Frame>& frames) {
  std::vector<TimedPose> s;
  for (const Frame& f : frames) s.push_back({f.time, *f.T_world_robot});
  return s;
}

bool sameFrames(const std::vector<Frame>& a, const std::vector<Frame>& b) {
  if (a.size() != b.size()) return false;
  auto samePose = [](const std::optional<SE2>& p, const std::optional<SE2>& q) {
    return p.has_value() == q.has_value() && (!p || (p->x() == q->x() && p->y() == q->y() && p->theta() == q->theta()));
  };
  for (std::size_t k = 0; k < a.size(); ++k)
    if (a[k].index != b[k].index || a[k].time != b[k].time || !samePose(a[k].T_odom_robot, b[k].T_odom_robot) ||
        !samePose(a[k].T_world_robot, b[k].T_world_robot) || a[k].scan.ranges() != b[k].scan.ranges())
      return false;
  return true;
}

// ---- defaults ----

TEST(LogPerturber, DefaultsReproducePerturbsOriginalLoop) {
  const auto in = simulatedLog("office");
  LogPerturbationOptions o;
  o.seed = 11;
  PerturbationStats st;
  const auto out = perturbLog(in, o, {}, &st);
  // The loop `lidar2d perturb` ran before the library existed.
  Rng rng(11);
  const OdometryNoise noise = OdometryNoise::constant(0.01, 0.005, 0.002);
  std::vector<Frame> ref = in;
  SE2 odom;
  for (std::size_t k = 0; k < ref.size(); ++k) {
    const SE2 truth = *ref[k].T_world_robot;
    odom = k == 0 ? truth : odom * noisyOdometryStep(in[k - 1].T_world_robot->inverse() * truth, noise, rng);
    ref[k].T_odom_robot = odom;
  }
  EXPECT_TRUE(sameFrames(ref, out));
  EXPECT_EQ(st.scans_read, in.size());
  EXPECT_EQ(st.scans_kept, in.size());
  EXPECT_EQ(st.dropped_by_gaps + st.dropped_by_keyframes, 0u);
}

TEST(LogPerturber, SameSeedSameOutput) {
  const auto in = simulatedLog("office");
  LogPerturbationOptions o;
  o.odometry = realisticOdometryNoise();
  o.keyframes.min_distance_m = 0.5;
  o.keyframes.min_turn_rad = 20 * kDeg;
  o.time.jitter_sigma_s = 0.02;
  o.time.burst_size = 3;
  const std::vector<GapRequest> gaps{{5.0, GapPlacement::kLargestTurn, 0.0}, {3.0, GapPlacement::kAtOffset, 20.0}};
  o.seed = 3;
  const auto a = perturbLog(in, o, gaps), b = perturbLog(in, o, gaps);
  o.seed = 4;
  const auto c = perturbLog(in, o, gaps);
  EXPECT_TRUE(sameFrames(a, b));
  EXPECT_FALSE(sameFrames(a, c));
  ASSERT_EQ(a.size(), c.size());  // the seed changes noise, not which scans are kept
}

// ---- keyframes ----

struct KeyframeCase {
  double d_m, k_deg;
};

class Keyframes : public ::testing::TestWithParam<KeyframeCase> {};

TEST_P(Keyframes, SpacingHoldsAndNoScanIsDroppedTooEarly) {
  const auto in = simulatedLog("office");
  LogPerturbationOptions o;
  o.keyframes.min_distance_m = GetParam().d_m;
  o.keyframes.min_turn_rad = GetParam().k_deg * kDeg;
  PerturbationStats st;
  const auto out = perturbLog(in, o, {}, &st);
  ASSERT_GT(out.size(), 10u);
  EXPECT_EQ(out.front().index, 0u);  // the first scan is kept
  auto farEnough = [&](const SE2& from, const SE2& to) {
    const double moved = (to.translation() - from.translation()).norm();
    const double turned = std::abs(angleDiff(to.theta(), from.theta()));
    return (o.keyframes.min_distance_m > 0 && moved >= o.keyframes.min_distance_m) ||
           (o.keyframes.min_turn_rad > 0 && turned >= o.keyframes.min_turn_rad);
  };
  std::size_t next = 0;  // position in `out`
  SE2 last_kept;
  for (const Frame& f : in) {
    const bool kept = next < out.size() && out[next].index == f.index;
    if (f.index > 0) {
      EXPECT_EQ(kept, farEnough(last_kept, *f.T_world_robot)) << "scan " << f.index;
    }
    if (kept) {
      last_kept = *f.T_world_robot;
      ++next;
    }
  }
  EXPECT_EQ(next, out.size());
  EXPECT_EQ(st.dropped_by_keyframes, in.size() - out.size());
  EXPECT_EQ(st.dropped_by_gaps, 0u);
}

INSTANTIATE_TEST_SUITE_P(DistanceTurnOrBoth, Keyframes,
                         ::testing::Values(KeyframeCase{1.0, 0.0}, KeyframeCase{0.0, 30.0}, KeyframeCase{1.0, 30.0},
                                           KeyframeCase{3.0, 90.0}, KeyframeCase{0.5, 10.0}));

TEST(LogPerturber, NoiseAppliesToTheStepsBetweenKeptScans) {
  const auto in = simulatedLog("office");
  LogPerturbationOptions o;
  o.odometry = OdometryNoise::none();
  o.odometry.scale_bias = 0.1;  // a bias shows which step it was applied to
  o.keyframes.min_distance_m = 1.0;
  const auto out = perturbLog(in, o);
  ASSERT_GT(out.size(), 20u);
  EXPECT_TRUE(IsNearPose(*out[0].T_world_robot, *out[0].T_odom_robot, 1e-12, 1e-9));
  for (std::size_t k = 1; k < out.size(); ++k) {
    const SE2 t = out[k - 1].T_world_robot->inverse() * *out[k].T_world_robot;
    const SE2 odom_step = out[k - 1].T_odom_robot->inverse() * *out[k].T_odom_robot;
    EXPECT_TRUE(IsNearPose(SE2(1.1 * t.x(), 1.1 * t.y(), t.theta()), odom_step, 1e-9, 1e-7)) << k;
  }
}

// ---- gaps ----

TEST(PlanGaps, FixedWindowsDropExactlyTheScansInside) {
  const auto in = simulatedLog("office");
  const double t0 = in.front().time, span = in.back().time - t0;
  const std::vector<GapRequest> requests{{4.0, GapPlacement::kAtOffset, 10.0},
                                         {2.5, GapPlacement::kMiddle, 0.0},
                                         {3.0, GapPlacement::kAtOffset, 11.0}};  // overlaps the first
  LogPerturbationOptions o;
  PerturbationStats st;
  const auto out = perturbLog(in, o, requests, &st);
  std::vector<std::size_t> expected_kept;
  std::size_t in_first = 0, in_middle = 0, in_third = 0;
  const double mid = t0 + (span - 2.5) / 2;
  for (const Frame& f : in) {
    // The same expressions as the planner's, so that rounding agrees.
    const bool a = f.time >= t0 + 10.0 && f.time < t0 + 10.0 + 4.0;
    const bool b = f.time >= mid && f.time < mid + 2.5;
    const bool c = f.time >= t0 + 11.0 && f.time < t0 + 11.0 + 3.0;
    in_first += a;
    in_middle += b;
    in_third += c;
    if (!a && !b && !c) expected_kept.push_back(f.index);
  }
  std::vector<std::size_t> kept;
  for (const Frame& f : out) kept.push_back(f.index);
  EXPECT_EQ(kept, expected_kept);
  ASSERT_EQ(st.dropped_per_gap.size(), 3u);
  EXPECT_EQ(st.dropped_per_gap[0], in_first);
  EXPECT_EQ(st.dropped_per_gap[1], in_middle);
  EXPECT_EQ(st.dropped_per_gap[2], in_third);
  EXPECT_EQ(st.dropped_by_gaps, in.size() - out.size());
  EXPECT_GT(in_first, 30u);  // 10 Hz
  // The windows as planned.
  const auto w = planGaps(requests, truthSamples(in));
  ASSERT_EQ(w.size(), 3u);
  EXPECT_EQ(w[0].begin_s, t0 + 10.0);
  EXPECT_EQ(w[0].end_s, t0 + 10.0 + 4.0);
  EXPECT_NEAR(w[1].begin_s, mid, 1e-12);
  EXPECT_NEAR(w[0].turn_rad, turnInWindow(truthSamples(in), w[0].begin_s, w[0].end_s), 1e-12);
}

TEST(PlanGaps, TurnInWindowSumsTheTurnsBetweenScansInside) {
  // Headings 0, 10, 30, 20, -170 (= 190), 170 deg at t = 0..5 s.
  std::vector<TimedPose> s;
  for (double deg : {0.0, 10.0, 30.0, 20.0, -170.0, 170.0}) s.push_back({s.size() * 1.0, SE2(0, 0, deg * kDeg)});
  EXPECT_NEAR(turnInWindow(s, 0.0, 6.0), (10 + 20 + 10 + 170 + 20) * kDeg, 1e-12);
  EXPECT_NEAR(turnInWindow(s, 1.0, 3.0), 20 * kDeg, 1e-12);  // scans 1 and 2; scan 3 is at the end (excluded)
  EXPECT_NEAR(turnInWindow(s, 3.0, 5.5), (170 + 20) * kDeg, 1e-12);
  EXPECT_EQ(turnInWindow(s, 0.5, 1.5), 0.0);  // one scan: no pair inside
}

// Brute force: the largest turn over windows starting on a fine grid, at every scan time, and ending
// at the log's end or where a window to avoid begins.
double bruteForceLargestTurn(const std::vector<TimedPose>& s, double duration, const std::vector<GapWindow>& avoid) {
  const double t_first = s.front().time_s, t_last = s.back().time_s;
  std::vector<std::pair<double, double>> windows;
  for (double b = t_first; b + duration <= t_last; b += 0.01) windows.push_back({b, b + duration});
  for (const TimedPose& p : s) windows.push_back({p.time_s, p.time_s + duration});
  windows.push_back({t_last - duration, t_last});
  for (const GapWindow& w : avoid) windows.push_back({w.begin_s - duration, w.begin_s});
  double best = -1;
  for (const auto& [b, e] : windows) {
    if (b < t_first || e > t_last) continue;
    bool free = true;
    for (const GapWindow& w : avoid) free = free && (e <= w.begin_s || b >= w.end_s);
    if (free) best = std::max(best, turnInWindow(s, b, e));
  }
  return best;
}

TEST(PlanGaps, AtTurnPicksTheLargestTurnWindow) {
  for (const std::string world : {"office", "symmetric"}) {
    const auto s = truthSamples(simulatedLog(world));
    for (double duration : {2.0, 7.5}) {
      const auto w = planGaps({{duration, GapPlacement::kLargestTurn, 0.0}}, s);
      ASSERT_EQ(w.size(), 1u);
      EXPECT_NEAR(w[0].end_s - w[0].begin_s, duration, 1e-9);
      EXPECT_GE(w[0].begin_s, s.front().time_s);
      EXPECT_LE(w[0].end_s, s.back().time_s);
      EXPECT_NEAR(w[0].turn_rad, turnInWindow(s, w[0].begin_s, w[0].end_s), 1e-12);
      EXPECT_NEAR(w[0].turn_rad, bruteForceLargestTurn(s, duration, {}), 1e-6) << world << " " << duration;
      EXPECT_GT(w[0].turn_rad, 60 * kDeg);  // the routes turn at corners and in rooms
    }
  }
}

TEST(PlanGaps, AtTurnOnRandomHeadingsAndDisorderedTimes) {
  // Random headings and irregular times, a few of them out of order (as in real logs); two @turn
  // gaps and a fixed one: each @turn window is the best one that avoids the windows placed before.
  Rng rng(21);
  for (int trial = 0; trial < 5; ++trial) {
    std::vector<TimedPose> s;
    double t = 100.0;
    for (int i = 0; i < 300; ++i) {
      t += 0.05 + 0.3 * rng.uniform();
      const double stamp = rng.uniform() < 0.03 ? t - 0.5 : t;  // an out-of-order stamp
      s.push_back({stamp, SE2(0, 0, 2 * kPi * rng.uniform() - kPi)});
    }
    const std::vector<GapRequest> req{{3.0, GapPlacement::kLargestTurn, 0.0},
                                      {6.0, GapPlacement::kAtOffset, 20.0},
                                      {4.0, GapPlacement::kLargestTurn, 0.0}};
    const auto w = planGaps(req, s);
    ASSERT_EQ(w.size(), 3u);
    EXPECT_NEAR(w[0].turn_rad, bruteForceLargestTurn(s, 3.0, {w[1]}), 1e-6) << trial;
    EXPECT_NEAR(w[2].turn_rad, bruteForceLargestTurn(s, 4.0, {w[1], w[0]}), 1e-6) << trial;
    for (int a = 0; a < 3; ++a)
      for (int b = a + 1; b < 3; ++b) EXPECT_TRUE(w[a].end_s <= w[b].begin_s || w[b].end_s <= w[a].begin_s);
  }
}

TEST(PlanGaps, TiesGoToTheEarliestWindow) {
  // No turn at all: every window turns 0; the earliest one starts at the first scan.
  std::vector<TimedPose> s;
  for (int i = 0; i < 100; ++i) s.push_back({10.0 + 0.1 * i, SE2(0.1 * i, 0, 0.3)});
  const auto w = planGaps({{2.0, GapPlacement::kLargestTurn, 0.0}}, s);
  EXPECT_EQ(w[0].begin_s, 10.0);
  EXPECT_EQ(w[0].turn_rad, 0.0);
}

TEST(LogPerturber, FirstScanAfterAGapGetsTheWholeMotionAcrossIt) {
  const auto in = simulatedLog("office");
  LogPerturbationOptions o;
  o.odometry = OdometryNoise::none();
  o.odometry.scale_bias = -0.2;
  PerturbationStats st;
  const auto out = perturbLog(in, o, {{6.0, GapPlacement::kLargestTurn, 0.0}}, &st);
  ASSERT_EQ(st.dropped_per_gap.size(), 1u);
  ASSERT_GT(st.dropped_by_gaps, 50u);
  std::size_t jumps = 0;
  for (std::size_t k = 1; k < out.size(); ++k) {
    const SE2 t = out[k - 1].T_world_robot->inverse() * *out[k].T_world_robot;
    const SE2 odom_step = out[k - 1].T_odom_robot->inverse() * *out[k].T_odom_robot;
    EXPECT_TRUE(IsNearPose(SE2(0.8 * t.x(), 0.8 * t.y(), t.theta()), odom_step, 1e-9, 1e-7)) << k;
    if (out[k].index != out[k - 1].index + 1) {
      ++jumps;
      EXPECT_EQ(out[k].index - out[k - 1].index - 1, st.dropped_by_gaps);
    }
  }
  EXPECT_EQ(jumps, 1u);
}

TEST(LogPerturber, AcrossACarriedGapTheOdometryReadsNoMotion) {
  // A kidnapping: the truth jumps across the window, the odometry stays put; elsewhere every step
  // is the truth's (noise-free model) or the log's own (kKeepLog).
  const auto in = simulatedLog("office");
  GapRequest kidnap{10.0, GapPlacement::kMiddle, 0.0};
  kidnap.carried = true;
  for (const OdometrySource source : {OdometrySource::kNoisyFromTruth, OdometrySource::kKeepLog}) {
    LogPerturbationOptions o;
    o.odometry = OdometryNoise::none();
    o.odometry_source = source;
    PerturbationStats st;
    const auto out = perturbLog(in, o, {kidnap}, &st);
    ASSERT_GT(st.dropped_by_gaps, 50u);
    std::size_t jumps = 0;
    for (std::size_t k = 1; k < out.size(); ++k) {
      const SE2 truth_step = out[k - 1].T_world_robot->inverse() * *out[k].T_world_robot;
      const SE2 odom_step = out[k - 1].T_odom_robot->inverse() * *out[k].T_odom_robot;
      if (out[k].index != out[k - 1].index + 1) {
        ++jumps;
        EXPECT_GT(truth_step.translation().norm(), 1.0);             // carried metres away ...
        EXPECT_TRUE(IsNearPose(SE2(), odom_step, 1e-9, 1e-9)) << k;  // ... and the wheels did not turn
      } else if (source == OdometrySource::kKeepLog) {
        const SE2 log_step = in[out[k - 1].index].T_odom_robot->inverse() * *in[out[k].index].T_odom_robot;
        EXPECT_TRUE(IsNearPose(log_step, odom_step, 1e-9, 1e-9)) << k;
      } else {
        EXPECT_TRUE(IsNearPose(truth_step, odom_step, 1e-9, 1e-7)) << k;
      }
    }
    EXPECT_EQ(jumps, 1u);
  }
}

TEST(LogPerturber, AFrozenOdometryWindowKeepsItsScansAndHoldsTheirOdometry) {
  // Every scan is kept; inside the window each reads the odometry of the last scan before it, and
  // after it the odometry reads what it would have read without the window (the wheels counted).
  const auto in = simulatedLog("office");
  GapRequest freeze{10.0, GapPlacement::kMiddle, 0.0};
  freeze.frozen_odometry = true;
  for (const OdometrySource source : {OdometrySource::kNoisyFromTruth, OdometrySource::kKeepLog}) {
    LogPerturbationOptions o;
    o.odometry_source = source;
    PerturbationStats st, plain_st;
    const auto plain = perturbLog(in, o, {}, &plain_st);
    const auto out = perturbLog(in, o, {freeze}, &st);
    ASSERT_EQ(out.size(), in.size());
    EXPECT_EQ(st.dropped_by_gaps, 0u);
    ASSERT_EQ(st.dropped_per_gap.size(), 1u);
    EXPECT_GT(st.frozen_odometry, 50u);
    EXPECT_EQ(st.frozen_odometry, st.dropped_per_gap[0]);
    std::size_t frozen = 0, first = out.size(), last = 0;
    for (std::size_t k = 0; k < out.size(); ++k) {
      const bool differs = !IsNearPose(*plain[k].T_odom_robot, *out[k].T_odom_robot, 0.0, 0.0);
      if (!differs) continue;
      first = std::min(first, k);
      last = k;
      ++frozen;
      ASSERT_GT(first, 0u);
      EXPECT_TRUE(IsNearPose(*plain[first - 1].T_odom_robot, *out[k].T_odom_robot, 0.0, 0.0)) << k;
      EXPECT_EQ(out[k].time, plain[k].time);
    }
    EXPECT_EQ(frozen, st.frozen_odometry);
    EXPECT_EQ(last - first + 1, frozen);  // one stretch: after it the odometry reads what the wheels counted
  }
  GapRequest both = freeze;
  both.carried = true;
  EXPECT_THROW(both.validate(), Error);
}

TEST(LogPerturber, AnOdometrySlipWindowAddsItsMotionToTheStepsItSpans) {
  // Every scan is kept; the steps before and after the window are the plain log's, and the steps
  // the window spans carry, on top of theirs, its slip in all: the metres forward and the turn.
  const auto in = simulatedLog("office");
  GapRequest slip{10.0, GapPlacement::kMiddle, 0.0};
  slip.odometry_slip = true;
  slip.slip_m = -1.5;
  slip.slip_rad = 0.5;
  for (const OdometrySource source : {OdometrySource::kNoisyFromTruth, OdometrySource::kKeepLog}) {
    LogPerturbationOptions o;
    o.odometry_source = source;
    PerturbationStats st;
    const auto plain = perturbLog(in, o, {});
    const auto out = perturbLog(in, o, {slip}, &st);
    ASSERT_EQ(out.size(), in.size());
    EXPECT_EQ(st.dropped_by_gaps, 0u);
    ASSERT_EQ(st.dropped_per_gap.size(), 1u);
    EXPECT_GT(st.dropped_per_gap[0], 50u);
    // The window's scans, and the first after it (its step ends the window).
    EXPECT_GE(st.slipped_odometry, st.dropped_per_gap[0]);
    EXPECT_LE(st.slipped_odometry, st.dropped_per_gap[0] + 1);
    double moved = 0.0, turned = 0.0;
    std::size_t slipped = 0;
    for (std::size_t k = 1; k < out.size(); ++k) {
      const SE2 plain_step = plain[k - 1].T_odom_robot->inverse() * *plain[k].T_odom_robot;
      const SE2 step = out[k - 1].T_odom_robot->inverse() * *out[k].T_odom_robot;
      const double dm = (step.translation() - plain_step.translation()).norm();
      const double dth = angleDiff(step.theta(), plain_step.theta());
      if (dm > 1e-9 || std::abs(dth) > 1e-9) ++slipped;
      moved += dm;
      turned += dth;
      EXPECT_EQ(out[k].time, plain[k].time);
    }
    EXPECT_TRUE(IsNearPose(*plain[0].T_odom_robot, *out[0].T_odom_robot, 0.0, 0.0));
    EXPECT_EQ(slipped, st.slipped_odometry);
    EXPECT_NEAR(moved, 1.5, 1e-6);
    EXPECT_NEAR(turned, 0.5, 1e-6);
  }
  GapRequest both = slip;
  both.frozen_odometry = true;
  EXPECT_THROW(both.validate(), Error);
  both = slip;
  both.slip_m = std::numeric_limits<double>::infinity();
  EXPECT_THROW(both.validate(), Error);
}

TEST(LogPerturber, AGapAtTheStartKeepsOdometryAnchoredAtTheFirstTruth) {
  const auto in = simulatedLog("office");
  LogPerturbationOptions o;
  o.odometry = OdometryNoise::none();
  const auto out = perturbLog(in, o, {{3.0, GapPlacement::kAtOffset, 0.0}});
  ASSERT_GT(out.front().index, 0u);
  for (const Frame& f : out) EXPECT_TRUE(IsNearPose(*f.T_world_robot, *f.T_odom_robot, 1e-9, 1e-7));
}

// ---- the realistic odometry model ----

TEST(LogPerturber, RealisticNoiseStatisticsPerMetre) {
  // ~1 m steps between keyframes over a long drive; the per-step noise, normalised by the model's
  // standard deviation, must be N(0, 1), and distances read 2 % long.
  const auto in = simulatedLog("office", 30000);
  LogPerturbationOptions o;
  o.odometry = realisticOdometryNoise();
  o.keyframes.min_distance_m = 1.0;
  o.seed = 8;
  const auto out = perturbLog(in, o);
  ASSERT_GT(out.size(), 1500u);
  Stats zx, zy, zth, scale, lateral_per_m;
  const OdometryNoise& m = o.odometry;
  for (std::size_t k = 1; k < out.size(); ++k) {
    const SE2 t = out[k - 1].T_world_robot->inverse() * *out[k].T_world_robot;
    const SE2 odom_step = out[k - 1].T_odom_robot->inverse() * *out[k].T_odom_robot;
    const double d = t.translation().norm();
    const SE2 biased(t.x() * (1 + m.scale_bias), t.y() * (1 + m.scale_bias), t.theta());
    const SE2 e = biased.inverse() * odom_step;  // SE2(n_x, n_y, n_theta)
    zx.add(e.x() / (0.005 + 0.03 * d));
    zy.add(e.y() / (0.005 + 0.03 * d));
    zth.add(e.theta() / (0.03 * std::abs(t.theta()) + kDeg * d));
    scale.add(odom_step.translation().norm() / d - 1.0);
    lateral_per_m.add(e.y() / d);
  }
  // n > 1500: standard errors 0.026 (mean) and 0.018 (std); allow about 4 of them.
  EXPECT_NEAR(zx.mean(), 0.0, 0.1);
  EXPECT_NEAR(zy.mean(), 0.0, 0.1);
  EXPECT_NEAR(zth.mean(), 0.0, 0.1);
  EXPECT_NEAR(zx.stddev(), 1.0, 0.07);
  EXPECT_NEAR(zy.stddev(), 1.0, 0.07);
  EXPECT_NEAR(zth.stddev(), 1.0, 0.07);
  // Per metre: 2 % long on average (noise std ~0.035 per step), lateral error ~0.035 m/m.
  EXPECT_NEAR(scale.mean(), 0.02, 0.004);
  EXPECT_NEAR(lateral_per_m.mean(), 0.0, 0.004);
  EXPECT_NEAR(lateral_per_m.stddev(), 0.035, 0.004);
}

TEST(LogPerturber, RealisticModelIsTheIssuesModel) {
  const OdometryNoise n = realisticOdometryNoise();
  EXPECT_EQ(n.sigma_x_m, 0.005);
  EXPECT_EQ(n.sigma_y_m, 0.005);
  EXPECT_EQ(n.sigma_theta_rad, 0.0);
  EXPECT_EQ(n.trans_sigma_per_m, 0.03);
  EXPECT_EQ(n.rot_sigma_per_rad, 0.03);
  EXPECT_NEAR(n.rot_sigma_per_m, kDeg, 1e-15);
  EXPECT_EQ(n.scale_bias, 0.02);
  EXPECT_EQ(n.heading_bias_per_m, 0.0);
}

// ---- timestamps ----

TEST(LogPerturber, JitterHasItsSigmaAndLeavesOdometryAlone) {
  const auto in = simulatedLog("office", 5000);
  LogPerturbationOptions o;
  const auto plain = perturbLog(in, o);
  o.time.jitter_sigma_s = 0.03;
  const auto jittered = perturbLog(in, o);
  ASSERT_EQ(plain.size(), jittered.size());
  Stats dt;
  for (std::size_t k = 0; k < in.size(); ++k) {
    dt.add(jittered[k].time - in[k].time);
    EXPECT_EQ(plain[k].T_odom_robot->x(), jittered[k].T_odom_robot->x());  // another random stream
    EXPECT_EQ(plain[k].T_odom_robot->theta(), jittered[k].T_odom_robot->theta());
    EXPECT_EQ(plain[k].T_world_robot->x(), jittered[k].T_world_robot->x());  // truth stays with its scan
  }
  EXPECT_NEAR(dt.mean(), 0.0, 0.002);
  EXPECT_NEAR(dt.stddev(), 0.03, 0.0015);
}

// ---- odometry lag ----

TEST(TruthAt, InterpolatesBetweenTheFramesAroundTheTime) {
  // Stamps 0, 1, 1 (repeated), 0.5 (backwards), 3; headings across +-pi.
  const std::vector<TimedPose> tl = {{0.0, SE2(0, 0, 3.0)},
                                     {1.0, SE2(1, 0, -3.0)},
                                     {1.0, SE2(1, 1, -3.0)},
                                     {0.5, SE2(9, 9, 0.0)},
                                     {3.0, SE2(3, 1, -2.0)}};
  // Between frames 0 and 1: the heading the short way round (3.0 -> -3.0 is +0.283 rad).
  const SE2 a = truthAt(tl, 0, 0.5);
  EXPECT_NEAR(a.x(), 0.5, 1e-12);
  EXPECT_NEAR(angleDiff(a.theta(), 3.0 + 0.5 * (2 * kPi - 6.0)), 0.0, 1e-12);
  // From frame 2 forward: past the backward stamp to the first later frame (frame 4 at 3) and the
  // one before it (frame 3 at 0.5).
  const SE2 b = truthAt(tl, 2, 1.75);
  EXPECT_NEAR(b.x(), 9 + (1.75 - 0.5) / 2.5 * (3 - 9), 1e-12);
  // From frame 4 backward: to the bracket (frame 3 at 0.5, frame 4 at 3).
  EXPECT_NEAR(truthAt(tl, 4, 2.0).y(), 9 + 1.5 / 2.5 * (1 - 9), 1e-12);
  // Before the first and after the last frame: their truth.
  EXPECT_TRUE(IsNearPose(tl[0].T_world_robot, truthAt(tl, 0, -1.0), 0.0, 0.0));
  EXPECT_TRUE(IsNearPose(tl[4].T_world_robot, truthAt(tl, 4, 5.0), 0.0, 0.0));
  // At a frame's own time, its truth.
  EXPECT_TRUE(IsNearPose(tl[1].T_world_robot, truthAt(tl, 1, 1.0), 0.0, 0.0));
  EXPECT_TRUE(IsNearPose(tl[2].T_world_robot, truthAt(tl, 2, 1.0), 0.0, 0.0));
  EXPECT_TRUE(throwsError([&] { truthAt(tl, 5, 0.0); }, ErrorKind::kInvalidArgument, {"truth timeline"}));
}

TEST(LogPerturber, AConstantLagReadsTheOdometryOneScanLate) {
  // A log at 10 Hz and a lag of one period, no noise: each scan's odometry step is the truth's step
  // one scan later, and the odometry error does not grow over the log.
  const auto in = simulatedLog("office", 600);
  ASSERT_NEAR(in[1].time - in[0].time, 0.1, 1e-9);
  LogPerturbationOptions o;
  o.odometry = OdometryNoise::constant(0, 0, 0);
  o.odometry_lag.mean_s = in[1].time - in[0].time;
  const auto out = perturbLog(in, o);
  ASSERT_EQ(out.size(), in.size());
  double worst_turn_error = 0.0, worst_step = 0.0;
  for (std::size_t k = 1; k + 1 < in.size(); ++k) {
    const SE2 odom_step = out[k - 1].T_odom_robot->inverse() * *out[k].T_odom_robot;
    const SE2 next_truth_step = in[k].T_world_robot->inverse() * *in[k + 1].T_world_robot;
    EXPECT_TRUE(IsNearPose(next_truth_step, odom_step, 1e-9, 1e-9)) << "scan " << k;
    const SE2 truth_step = in[k - 1].T_world_robot->inverse() * *in[k].T_world_robot;
    worst_turn_error = std::max(worst_turn_error, std::abs(angleDiff(odom_step.theta(), truth_step.theta())));
    worst_step = std::max(worst_step, std::abs(truth_step.theta()));
  }
  EXPECT_GT(worst_turn_error, 0.5 * kDeg);  // the route turns: a step late is a heading error there
  // Without noise the odometry stays one scan ahead of the truth: its heading error never exceeds
  // one step's turn.
  for (std::size_t k = 0; k < in.size(); ++k)
    EXPECT_LE(std::abs(angleDiff(out[k].T_odom_robot->theta(), in[k].T_world_robot->theta())), worst_step + 1e-9);
}

TEST(LogPerturber, ARandomLagHasItsSigmaAndLeavesTheNoiseDrawsAlone) {
  const auto in = simulatedLog("office", 3000);
  LogPerturbationOptions o;
  o.odometry = OdometryNoise::constant(0, 0, 0);
  o.odometry_lag.sigma_s = 0.02;
  const auto out = perturbLog(in, o);
  ASSERT_EQ(out.size(), in.size());
  // Inside a straight stretch at constant speed the odometry's step k is the path driven between
  // t_(k-1) + lag_(k-1) and t_k + lag_k: its length over the speed, less the period, is
  // lag_k - lag_(k-1), of std sqrt(2) sigma.
  const double speed = PathOptions{}.speed_mps;
  Stats d;
  for (std::size_t k = 2; k + 1 < in.size(); ++k) {
    bool straight = true;
    for (std::size_t m = k - 1; m <= k + 1; ++m) {
      const SE2 step = in[m - 1].T_world_robot->inverse() * *in[m].T_world_robot;
      straight = straight && std::abs(step.theta()) < 1e-12 && std::abs(step.y()) < 1e-12 &&
                 std::abs(step.x() - speed * (in[m].time - in[m - 1].time)) < 1e-9;
    }
    if (!straight) continue;
    const SE2 odom_step = out[k - 1].T_odom_robot->inverse() * *out[k].T_odom_robot;
    d.add(odom_step.translation().norm() / speed - (in[k].time - in[k - 1].time));
  }
  ASSERT_GT(d.n, 500.0);
  EXPECT_NEAR(d.mean(), 0.0, 0.003);
  EXPECT_NEAR(d.stddev(), std::sqrt(2.0) * 0.02, 0.003);
  // With noise: a lag far too small to move a pose leaves the odometry as it is without one, so the
  // lag draws from its own stream, not from the noise's.
  LogPerturbationOptions noisy;
  noisy.odometry = realisticOdometryNoise();
  const auto plain = perturbLog(in, noisy);
  noisy.odometry_lag.sigma_s = 1e-300;
  ASSERT_TRUE(noisy.odometry_lag.enabled());
  const auto lagged = perturbLog(in, noisy);
  ASSERT_EQ(plain.size(), lagged.size());
  for (std::size_t k = 0; k < plain.size(); ++k)
    EXPECT_TRUE(IsNearPose(*plain[k].T_odom_robot, *lagged[k].T_odom_robot, 1e-12, 1e-12)) << "scan " << k;
}

TEST(LogPerturber, BurstsCarryTheirLastScansStamp) {
  const auto in = simulatedLog("office");
  for (std::size_t n : {2u, 5u, 7u}) {
    LogPerturbationOptions o;
    o.time.burst_size = n;
    const auto out = perturbLog(in, o);
    ASSERT_EQ(out.size(), in.size());
    for (std::size_t k = 0; k < out.size(); ++k) {
      const std::size_t last = std::min(in.size() - 1, (k / n + 1) * n - 1);  // the last group may be short
      EXPECT_EQ(out[k].time, in[last].time) << n << " " << k;
    }
  }
}

TEST(LogPerturber, SynthesizedTimesRestoreAClockAndGapsUseIt) {
  // Stamps ruined (all equal): synthesized times t0 + i / rate, with holes where scans are dropped.
  auto in = simulatedLog("office");
  for (Frame& f : in) f.time = 42.0;
  LogPerturbationOptions o;
  o.time.synthesize_rate_hz = 20.0;
  o.keyframes.min_turn_rad = 5 * kDeg;
  PerturbationStats st;
  const auto out = perturbLog(in, o, {{2.0, GapPlacement::kAtOffset, 30.0}}, &st);
  ASSERT_LT(out.size(), in.size());
  for (const Frame& f : out) {
    EXPECT_EQ(f.time, 42.0 + static_cast<double>(f.index) / 20.0);
    EXPECT_FALSE(f.time >= 72.0 && f.time < 74.0);
  }
  EXPECT_EQ(st.dropped_per_gap[0], 40u);
  // Without synthesized times, a gap does not fit in a log whose stamps do not advance.
  o.time.synthesize_rate_hz = 0;
  EXPECT_TRUE(throwsError(
      [&] {
        perturbLog(in, o, {{2.0, GapPlacement::kAtOffset, 0.0}});
      },
      ErrorKind::kBadInput, {"does not fit", "timestamps do not advance"}));
}

// ---- the log's own odometry ----

TEST(LogPerturber, KeepLogOdometryOnlyDropsAndRetimes) {
  auto in = simulatedLog("office");
  for (Frame& f : in) f.T_world_robot.reset();  // a log without truth: the reference is the odometry
  LogPerturbationOptions o;
  o.odometry_source = OdometrySource::kKeepLog;
  o.keyframes.min_distance_m = 0.5;
  PerturbationStats st;
  const auto out = perturbLog(in, o, {{4.0, GapPlacement::kLargestTurn, 0.0}}, &st);
  ASSERT_GT(st.dropped_by_gaps, 0u);
  ASSERT_GT(st.dropped_by_keyframes, 0u);
  SE2 last = *out.front().T_odom_robot;
  for (std::size_t k = 0; k < out.size(); ++k) {
    const Frame& f = out[k];
    EXPECT_TRUE(IsNearPose(*in[f.index].T_odom_robot, *f.T_odom_robot, 0, 0));
    EXPECT_FALSE(f.T_world_robot);
    if (k > 0) {
      EXPECT_GE((f.T_odom_robot->translation() - last.translation()).norm(), 0.5);
    }
    last = *f.T_odom_robot;
  }
  // The @turn window was planned on the odometry's heading.
  std::vector<TimedPose> odo;
  for (const Frame& f : in) odo.push_back({f.time, *f.T_odom_robot});
  EXPECT_NEAR(planGaps({{4.0, GapPlacement::kLargestTurn, 0.0}}, odo)[0].turn_rad, bruteForceLargestTurn(odo, 4.0, {}),
              1e-6);
}

// ---- bad input ----

TEST(LogPerturber, BadInput) {
  const auto in = simulatedLog("office");
  const auto s = truthSamples(in);
  const double span = s.back().time_s - s.front().time_s;
  EXPECT_TRUE(throwsError(
      [&] {
        planGaps({{span + 1, GapPlacement::kLargestTurn, 0}}, s);
      },
      ErrorKind::kBadInput, {"does not fit"}));
  EXPECT_TRUE(throwsError(
      [&] {
        planGaps({{span + 1, GapPlacement::kMiddle, 0}}, s);
      },
      ErrorKind::kBadInput, {"does not fit"}));
  EXPECT_TRUE(throwsError(
      [&] {
        planGaps({{5, GapPlacement::kAtOffset, span - 4}}, s);
      },
      ErrorKind::kBadInput, {"ends after the last scan"}));
  EXPECT_NO_THROW(planGaps({{span, GapPlacement::kAtOffset, 0}}, s));  // ends exactly at the last scan
  EXPECT_TRUE(throwsError(
      [&] {
        planGaps({{span * 0.6, GapPlacement::kMiddle, 0}, {span * 0.6, GapPlacement::kLargestTurn, 0}}, s);
      },
      ErrorKind::kBadInput, {"no room"}));
  EXPECT_TRUE(throwsError(
      [&] {
        planGaps({{1, GapPlacement::kMiddle, 0}}, {});
      },
      ErrorKind::kBadInput, {"without scans"}));
  for (double bad : {0.0, -1.0, std::nan("")})
    EXPECT_TRUE(throwsError(
        [&] {
          planGaps({{bad, GapPlacement::kMiddle, 0}}, s);
        },
        ErrorKind::kInvalidArgument, {"duration"}));
  EXPECT_TRUE(throwsError(
      [&] {
        planGaps({{1, GapPlacement::kAtOffset, -2}}, s);
      },
      ErrorKind::kInvalidArgument, {"start"}));

  LogPerturbationOptions lag;
  lag.odometry_lag.sigma_s = 0.01;
  EXPECT_TRUE(throwsError([&] { LogPerturber p(lag); }, ErrorKind::kInvalidArgument, {"truth timeline"}));
  lag.truth_timeline = s;
  lag.odometry_source = OdometrySource::kKeepLog;
  EXPECT_TRUE(throwsError([&] { LogPerturber p(lag); }, ErrorKind::kInvalidArgument, {"made from the truth"}));
  lag.odometry_source = OdometrySource::kNoisyFromTruth;
  for (double bad : {-1.0, std::nan("")}) {
    lag.odometry_lag.sigma_s = bad;
    EXPECT_TRUE(throwsError([&] { LogPerturber p(lag); }, ErrorKind::kInvalidArgument, {"lag sigma"}));
  }
  lag.odometry_lag.sigma_s = 0;
  lag.odometry_lag.mean_s = std::numeric_limits<double>::infinity();
  EXPECT_TRUE(throwsError([&] { LogPerturber p(lag); }, ErrorKind::kInvalidArgument, {"odometry lag must be finite"}));

  LogPerturbationOptions o;
  o.keyframes.min_distance_m = -1;
  EXPECT_TRUE(throwsError([&] { LogPerturber p(o); }, ErrorKind::kInvalidArgument, {"keyframe distance"}));
  o = {};
  o.keyframes.min_turn_rad = 4;
  EXPECT_TRUE(throwsError([&] { LogPerturber p(o); }, ErrorKind::kInvalidArgument, {"keyframe turn"}));
  o = {};
  o.time.burst_size = 0;
  EXPECT_TRUE(throwsError([&] { LogPerturber p(o); }, ErrorKind::kInvalidArgument, {"burst"}));
  o = {};
  o.time.jitter_sigma_s = std::numeric_limits<double>::infinity();
  EXPECT_TRUE(throwsError([&] { LogPerturber p(o); }, ErrorKind::kInvalidArgument, {"jitter"}));
  o = {};
  o.odometry.trans_sigma_per_m = -0.1;
  EXPECT_TRUE(throwsError([&] { LogPerturber p(o); }, ErrorKind::kInvalidArgument, {"odometry"}));

  // Odometry from the truth needs truth; keyframes need a reference pose.
  auto no_truth = in;
  no_truth[5].T_world_robot.reset();
  EXPECT_TRUE(throwsError([&] { perturbLog(no_truth, {}); }, ErrorKind::kBadInput, {"scan 5", "ground-truth"}));
  LogPerturbationOptions keep;
  keep.odometry_source = OdometrySource::kKeepLog;
  keep.keyframes.min_distance_m = 1;
  EXPECT_TRUE(
      throwsError([&] { perturbLog(no_truth, keep); }, ErrorKind::kBadInput, {"scan 5", "ground-truth", "keyframes"}));
  keep.keyframes = {};
  EXPECT_TRUE(throwsError(
      [&] {
        perturbLog(no_truth, keep, {{2, GapPlacement::kLargestTurn, 0}});
      },
      ErrorKind::kBadInput, {"scan 5", "largest turn"}));
  EXPECT_NO_THROW(perturbLog(no_truth, keep, {{2, GapPlacement::kMiddle, 0}}));  // no pose needed
}

}  // namespace
}  // namespace lidar2d::sim
