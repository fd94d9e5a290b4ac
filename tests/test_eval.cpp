// Evaluation metrics: association, closed-form alignment (against a numerical minimisation), ATE,
// RPE, the Kuemmerle relation metric and per-pair errors, on hand-made trajectories with known answers.

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <random>

#include "lidar2d/core/error.hpp"
#include "lidar2d/eval/alignment.hpp"
#include "lidar2d/eval/metrics.hpp"
#include "support/test_support.hpp"

namespace lidar2d::eval {
namespace {

using lidar2d::RelativePose;
using lidar2d::Relation;
using lidar2d::Relations;
using lidar2d::Trajectory;

constexpr double kPi = std::numbers::pi;
constexpr double kDeg = kPi / 180.0;

/// A wiggly path with turns in both directions: poses at t = t0 + i * dt.
Trajectory wigglyPath(std::size_t n, double t0 = 100.0, double dt = 0.1) {
  Trajectory t;
  SE2 T;
  for (std::size_t i = 0; i < n; ++i) {
    t.push_back({t0 + static_cast<double>(i) * dt, T});
    const double fi = static_cast<double>(i);
    T = T * SE2(0.2 + 0.05 * std::sin(0.3 * fi), 0.02 * std::cos(0.7 * fi), 0.15 * std::sin(0.11 * fi));
  }
  return t;
}

/// Every pose left-multiplied by `T`: the same trajectory expressed in another world frame.
Trajectory transformed(const Trajectory& t, const SE2& T) {
  Trajectory out = t;
  for (auto& p : out) p.pose = T * p.pose;
  return out;
}

// ---------------------------------------------------------------- statistics and time lookup

TEST(Summarize, KnownValuesAndSampleStd) {
  const ErrorStats s = summarize({3.0, 1.0, 2.0, 4.0});
  EXPECT_EQ(s.count, 4u);
  EXPECT_DOUBLE_EQ(s.mean, 2.5);
  EXPECT_DOUBLE_EQ(s.median, 2.5);
  EXPECT_DOUBLE_EQ(s.min, 1.0);
  EXPECT_DOUBLE_EQ(s.max, 4.0);
  EXPECT_DOUBLE_EQ(s.rmse, std::sqrt(30.0 / 4.0));
  EXPECT_DOUBLE_EQ(s.stddev, std::sqrt(5.0 / 3.0));  // sum of squared deviations 5, divisor n - 1
  EXPECT_DOUBLE_EQ(summarize({7.0, 1.0, 4.0}).median, 4.0);
  EXPECT_EQ(summarize({7.0}).stddev, 0.0);
  const ErrorStats e = summarize({});
  EXPECT_EQ(e.count, 0u);
  EXPECT_TRUE(std::isnan(e.mean));
  EXPECT_TRUE(std::isnan(e.rmse));
}

TEST(Percentile, InterpolatesBetweenOrderStatistics) {
  const std::vector<double> v{4.0, 1.0, 3.0, 2.0, 5.0};
  EXPECT_DOUBLE_EQ(percentile(v, 0.0), 1.0);
  EXPECT_DOUBLE_EQ(percentile(v, 0.5), 3.0);
  EXPECT_DOUBLE_EQ(percentile(v, 1.0), 5.0);
  EXPECT_DOUBLE_EQ(percentile(v, 0.95), 4.8);  // position 3.8 between 4 and 5
  EXPECT_DOUBLE_EQ(percentile({3.0, 1.0, 2.0, 4.0}, 0.5), summarize({3.0, 1.0, 2.0, 4.0}).median);
  EXPECT_DOUBLE_EQ(percentile({7.0}, 0.95), 7.0);
  EXPECT_TRUE(std::isnan(percentile({}, 0.5)));
  EXPECT_TRUE(std::isnan(percentile(v, 1.5)));
  EXPECT_TRUE(std::isnan(percentile(v, std::numeric_limits<double>::quiet_NaN())));
}

// ---------------------------------------------------------------- association

TEST(Associate, SameTimesGoByIndexEvenWhenTimesRepeat) {
  // A log whose times repeat (as infinite-corridor): by time, every repeated time would pick the
  // same pose; by index each pose gets its own partner.
  Trajectory ref{{1.0, SE2(0, 0, 0)}, {1.0, SE2(1, 0, 0)}, {1.0, SE2(2, 0, 0)}, {2.0, SE2(3, 0, 0)}};
  const Association a = associate(ref, ref);
  EXPECT_EQ(a.mode, AssociationMode::kIndex);
  ASSERT_EQ(a.matches.size(), 4u);
  for (std::size_t i = 0; i < 4; ++i) {
    EXPECT_EQ(a.matches[i].est, i);
    EXPECT_EQ(a.matches[i].ref, i);
  }
  const TrajectoryResult r = evaluateTrajectory(ref, ref);
  EXPECT_EQ(r.ate.trans_m.max, 0.0);

  // Forced time association maps all three t = 1.0 reference poses to the first estimate: the
  // error that index association avoids.
  Options by_time;
  by_time.association = AssociationMode::kTime;
  const Association t = associate(ref, ref, by_time);
  EXPECT_EQ(t.mode, AssociationMode::kTime);
  EXPECT_TRUE(t.ambiguous_times);
  EXPECT_EQ(t.unmatched_estimate, 2u);
  Options no_align = by_time;
  no_align.align = false;
  EXPECT_GT(computeAte(ref, ref, t, no_align).trans_m.max, 1.5);
}

TEST(Associate, ByNearestTimeReportsMatchedAndUnmatched) {
  const Trajectory ref = wigglyPath(20, 100.0, 0.5);  // 100.0 .. 109.5
  Trajectory est;
  // Estimates at +0.04 s of every second reference pose, plus two far off in time.
  for (std::size_t i = 0; i < ref.size(); i += 2) est.push_back({ref[i].time + 0.04, ref[i].pose});
  est.push_back({50.0, SE2()});
  est.push_back({200.0, SE2()});
  const Association a = associate(est, ref);
  EXPECT_EQ(a.mode, AssociationMode::kTime);
  EXPECT_EQ(a.matches.size(), 10u);
  EXPECT_EQ(a.unmatched_reference, 10u);
  EXPECT_EQ(a.unmatched_estimate, 2u);
  EXPECT_NEAR(a.max_abs_dt_s, 0.04, 1e-9);
  for (const Match& m : a.matches) EXPECT_EQ(m.ref, 2 * m.est);
  EXPECT_LT(evaluateTrajectory(est, ref).ate.trans_m.max, 1e-12);
}

TEST(Associate, IndexModeNeedsEqualLengths) {
  const Trajectory ref = wigglyPath(5);
  const Trajectory est = wigglyPath(4);
  Options o;
  o.association = AssociationMode::kIndex;
  try {
    associate(est, ref, o);
    FAIL() << "no error";
  } catch (const Error& e) {
    EXPECT_EQ(e.kind(), ErrorKind::kInvalidArgument);
  }
}

TEST(Ate, NoMatchIsBadInput) {
  const Trajectory ref = wigglyPath(5, 100.0);
  const Trajectory est = wigglyPath(5, 500.0);
  try {
    evaluateTrajectory(est, ref);
    FAIL() << "no error";
  } catch (const Error& e) {
    EXPECT_EQ(e.kind(), ErrorKind::kBadInput);
  }
}

// ---------------------------------------------------------------- alignment

double alignmentCost(const std::vector<Eigen::Vector2d>& a, const std::vector<Eigen::Vector2d>& b, const SE2& T) {
  double c = 0.0;
  for (std::size_t i = 0; i < a.size(); ++i) c += (b[i] - T * a[i]).squaredNorm();
  return c;
}

class AlignmentVsNumeric : public ::testing::TestWithParam<int> {};

TEST_P(AlignmentVsNumeric, ClosedFormIsTheGlobalMinimum) {
  std::mt19937 rng(static_cast<unsigned>(GetParam()));
  std::uniform_real_distribution<double> pos(-20.0, 20.0), ang(-kPi, kPi);
  std::normal_distribution<double> noise(0.0, 0.5);
  const SE2 T_true(pos(rng), pos(rng), ang(rng));
  std::vector<Eigen::Vector2d> est, ref;
  for (int i = 0; i < 30; ++i) {
    est.emplace_back(pos(rng), pos(rng));
    ref.push_back(T_true * est.back() + Eigen::Vector2d(noise(rng), noise(rng)));
  }
  const SE2 closed = alignPoints(est, ref);

  // Reference: for a fixed angle the best translation is exact (centroid difference), so search the
  // angle on a dense grid and refine by golden-section search around the best grid point.
  Eigen::Vector2d mu_e = Eigen::Vector2d::Zero(), mu_r = Eigen::Vector2d::Zero();
  for (std::size_t i = 0; i < est.size(); ++i) {
    mu_e += est[i] / 30.0;
    mu_r += ref[i] / 30.0;
  }
  const auto poseAt = [&](double th) { return SE2(mu_r - SE2(0, 0, th).rotation() * mu_e, th); };
  const auto cost = [&](double th) { return alignmentCost(est, ref, poseAt(th)); };
  double best_th = 0.0, best_c = std::numeric_limits<double>::infinity();
  for (int k = 0; k < 3600; ++k) {
    const double th = -kPi + 2.0 * kPi * k / 3600.0;
    if (const double c = cost(th); c < best_c) {
      best_c = c;
      best_th = th;
    }
  }
  double lo = best_th - 2.0 * kPi / 3600.0, hi = best_th + 2.0 * kPi / 3600.0;
  const double g = (std::sqrt(5.0) - 1.0) / 2.0;
  for (int it = 0; it < 100; ++it) {
    const double m1 = hi - g * (hi - lo), m2 = lo + g * (hi - lo);
    if (cost(m1) < cost(m2))
      hi = m2;
    else
      lo = m1;
  }
  const SE2 numeric = poseAt(0.5 * (lo + hi));

  EXPECT_TRUE(test::IsNearPose(numeric, closed, 1e-6, 1e-5));
  EXPECT_LE(alignmentCost(est, ref, closed), alignmentCost(est, ref, numeric) + 1e-9);
  // Local optimality in every parameter direction.
  const double c0 = alignmentCost(est, ref, closed);
  for (const Eigen::Vector3d& d : {Eigen::Vector3d(1e-4, 0, 0), Eigen::Vector3d(0, 1e-4, 0), Eigen::Vector3d(0, 0, 1e-5)}) {
    EXPECT_GT(alignmentCost(est, ref, SE2::fromVector(closed.vector() + d)), c0);
    EXPECT_GT(alignmentCost(est, ref, SE2::fromVector(closed.vector() - d)), c0);
  }
  // With 0.5 m noise on 30 points spread over 40 m the true transform is recovered closely.
  EXPECT_TRUE(test::IsNearPose(T_true, closed, 0.5, 1.0));
}

INSTANTIATE_TEST_SUITE_P(Seeds, AlignmentVsNumeric, ::testing::Range(1, 9));

TEST(Alignment, DegenerateAndInvalidInput) {
  const SE2 one = alignPoints({Eigen::Vector2d(1, 2)}, {Eigen::Vector2d(4, 6)});
  EXPECT_TRUE(test::IsNearPose(SE2(3, 4, 0), one, 1e-12, 1e-12));
  EXPECT_THROW(alignPoints({}, {}), Error);
  EXPECT_THROW(alignPoints({Eigen::Vector2d(1, 2)}, {}), Error);
}

// ---------------------------------------------------------------- ATE and RPE

TEST(TrajectoryMetrics, TruthAgainstItselfIsZero) {
  const Trajectory ref = wigglyPath(200);
  const TrajectoryResult r = evaluateTrajectory(ref, ref);
  EXPECT_EQ(r.association.mode, AssociationMode::kIndex);
  EXPECT_EQ(r.association.matches.size(), 200u);
  EXPECT_EQ(r.association.unmatched_reference, 0u);
  EXPECT_TRUE(test::IsNearPose(SE2(), r.ate.T_ref_est, 1e-12, 1e-10));
  EXPECT_NEAR(r.ate.trans_m.max, 0.0, 1e-12);
  EXPECT_NEAR(r.ate.rot_rad.max, 0.0, 1e-12);
  EXPECT_EQ(r.ate.unaligned_trans_m.max, 0.0);
  EXPECT_EQ(r.rpe.trans_m.count, 199u);
  EXPECT_NEAR(r.rpe.trans_m.max, 0.0, 1e-12);
  EXPECT_NEAR(r.rpe.rot_rad.max, 0.0, 1e-12);
  EXPECT_GT(r.rpe.trans_per_m.count, 100u);
  EXPECT_NEAR(r.rpe.trans_per_m.max, 0.0, 1e-12);
  EXPECT_NEAR(r.rpe.rot_rad_per_m.max, 0.0, 1e-12);
}

TEST(TrajectoryMetrics, RigidTransformIsRecoveredByAlignment) {
  const Trajectory ref = wigglyPath(150);
  const SE2 T_est_ref(3.0, -7.0, 2.2);  // the estimate lives in another world frame
  const Trajectory est = transformed(ref, T_est_ref);
  const TrajectoryResult r = evaluateTrajectory(est, ref);
  EXPECT_TRUE(test::IsNearPose(T_est_ref.inverse(), r.ate.T_ref_est, 1e-9, 1e-7));
  EXPECT_LT(r.ate.trans_m.rmse, 1e-9);
  EXPECT_LT(r.ate.rot_rad.max, 1e-9);
  EXPECT_GT(r.ate.unaligned_trans_m.rmse, 1.0);
  EXPECT_LT(r.rpe.trans_m.max, 1e-9);  // relative errors do not see the frame
  EXPECT_LT(r.rpe.rot_rad.max, 1e-9);

  Options no_align;
  no_align.align = false;
  const TrajectoryResult u = evaluateTrajectory(est, ref, no_align);
  EXPECT_TRUE(test::IsNearPose(SE2(), u.ate.T_ref_est, 0, 0));
  EXPECT_DOUBLE_EQ(u.ate.trans_m.rmse, r.ate.unaligned_trans_m.rmse);
  EXPECT_NEAR(u.ate.rot_rad.max, 2.2, 1e-9);
}

TEST(TrajectoryMetrics, ConstantStepErrorGivesTheExpectedRpe) {
  // Reference: straight along x in 0.5 m steps. Estimate: every step followed by a constant error
  // E = (0.05, 0.02, 0.01 rad), i.e. T_est_k+1 = T_est_k * S * E with S = (0.5, 0, 0).
  const SE2 S(0.5, 0.0, 0.0), E(0.05, 0.02, 0.01);
  Trajectory ref, est;
  SE2 T_est;
  for (int i = 0; i < 41; ++i) {
    ref.push_back({static_cast<double>(i), SE2(0.5 * i, 0.0, 0.0)});
    est.push_back({static_cast<double>(i), T_est});
    T_est = T_est * S * E;
  }
  const TrajectoryResult r = evaluateTrajectory(est, ref);
  // Consecutive: T_ref_rel = S, T_est_rel = S E, so |t(S E) - t(S)| = |t(E)| and the angle 0.01.
  EXPECT_EQ(r.rpe.trans_m.count, 40u);
  EXPECT_NEAR(r.rpe.trans_m.rmse, std::hypot(0.05, 0.02), 1e-12);
  EXPECT_NEAR(r.rpe.trans_m.max - r.rpe.trans_m.min, 0.0, 1e-12);
  EXPECT_NEAR(r.rpe.rot_rad.rmse, 0.01, 1e-12);
  // Per 1 m: segments join poses k and k+2 (reference path exactly 1 m); the estimate's relative
  // pose is (S E)(S E) with S E = (0.55, 0.02, 0.01), so
  //   x = 0.55 + 0.55 cos(0.01) - 0.02 sin(0.01),  y = 0.02 + 0.55 sin(0.01) + 0.02 cos(0.01),
  // against (1, 0, 0): error per metre = hypot(x - 1, y) / 1 m and 0.02 rad / 1 m.
  const double x = 0.55 + 0.55 * std::cos(0.01) - 0.02 * std::sin(0.01);
  const double y = 0.02 + 0.55 * std::sin(0.01) + 0.02 * std::cos(0.01);
  EXPECT_EQ(r.rpe.trans_per_m.count, 39u);  // starts 0..38; start 39 has only 0.5 m ahead
  EXPECT_NEAR(r.rpe.trans_per_m.mean, std::hypot(x - 1.0, y), 1e-12);
  EXPECT_NEAR(r.rpe.trans_per_m.stddev, 0.0, 1e-12);
  EXPECT_NEAR(r.rpe.rot_rad_per_m.mean, 0.02, 1e-12);

  // With 2 m segments: poses k and k+4; (S E)^4 computed by composition against (2, 0, 0), / 2 m.
  Options two;
  two.rpe_distance_m = 2.0;
  const RpeResult r2 = computeRpe(est, ref, associate(est, ref, two), two);
  const SE2 SE4 = (S * E) * (S * E) * (S * E) * (S * E);
  EXPECT_EQ(r2.trans_per_m.count, 37u);
  EXPECT_NEAR(r2.trans_per_m.mean, std::hypot(SE4.x() - 2.0, SE4.y()) / 2.0, 1e-12);
  EXPECT_NEAR(r2.rot_rad_per_m.mean, 0.04 / 2.0, 1e-12);
}

TEST(TrajectoryMetrics, AteOfAKnownOffsetAfterAlignment) {
  // Points on a square; the estimate has one pose displaced by 0.4 m. Alignment cannot remove a
  // single-point error, and ATE stays well defined: check against the cost of the found alignment.
  Trajectory ref{{0, SE2(0, 0, 0)}, {1, SE2(1, 0, 0)}, {2, SE2(1, 1, 0)}, {3, SE2(0, 1, 0)}};
  Trajectory est = ref;
  est[2].pose = SE2(1.4, 1.0, 0.0);
  const TrajectoryResult r = evaluateTrajectory(est, ref);
  double sq = 0.0;
  for (std::size_t i = 0; i < 4; ++i) sq += (ref[i].pose.translation() - r.ate.T_ref_est * est[i].pose.translation()).squaredNorm();
  EXPECT_NEAR(r.ate.trans_m.rmse, std::sqrt(sq / 4.0), 1e-12);
  EXPECT_LT(r.ate.trans_m.rmse, r.ate.unaligned_trans_m.rmse);
  EXPECT_NEAR(r.ate.unaligned_trans_m.rmse, 0.2, 1e-12);  // sqrt(0.4^2 / 4)
  EXPECT_NEAR(r.ate.unaligned_trans_m.max, 0.4, 1e-12);
}

// ---------------------------------------------------------------- relations

TEST(Relations, KnownErrorsMeanAndSampleStd) {
  // Estimated poses at t = 10, 11, 12, 13.
  const Trajectory est{{10.0, SE2(0, 0, 0)}, {11.0, SE2(1, 0, 0.5)}, {12.0, SE2(2, 1, 1.0)}, {13.0, SE2(2, 3, -3.0)}};
  const auto rel = [&](std::size_t a, std::size_t b) { return est[a].pose.inverse() * est[b].pose; };
  Relations rels;
  rels.push_back({10.0, 12.0, rel(0, 2)});  // exact: error 0
  // Error 0.1 m along y and 1 degree, times just inside the tolerance (|dt| = 0.09 s).
  const SE2 r13 = rel(1, 3);
  rels.push_back({11.09, 12.91, SE2(r13.x(), r13.y() + 0.1, r13.theta() + 1.0 * kDeg)});
  // Error 0.2 m and 2 degrees.
  const SE2 r02 = rel(0, 2);
  rels.push_back({9.95, 12.0, SE2(r02.x() - 0.12, r02.y() + 0.16, r02.theta() - 2.0 * kDeg)});
  rels.push_back({10.0, 11.11, rel(0, 1)});  // t2 just outside (0.11 s): skipped
  rels.push_back({9.89, 11.0, rel(0, 1)});   // t1 just outside: skipped
  rels.push_back({50.0, 60.0, SE2()});       // far outside the estimate: skipped

  const RelationsResult r = evaluateRelations(est, rels);
  EXPECT_EQ(r.count, 3u);
  EXPECT_EQ(r.skipped, 3u);
  ASSERT_EQ(r.errors.size(), 3u);
  EXPECT_EQ(r.errors[1].relation, 1u);
  EXPECT_NEAR(r.errors[0].trans_m, 0.0, 1e-12);
  EXPECT_NEAR(r.errors[1].trans_m, 0.1, 1e-12);
  EXPECT_NEAR(r.errors[2].trans_m, 0.2, 1e-12);
  EXPECT_NEAR(r.errors[1].rot_rad, 1.0 * kDeg, 1e-12);
  // Errors {0, 0.1, 0.2}: mean 0.1, sample std sqrt((0.01 + 0 + 0.01) / 2) = 0.1.
  EXPECT_NEAR(r.trans_m.mean, 0.1, 1e-12);
  EXPECT_NEAR(r.trans_m.stddev, 0.1, 1e-12);
  EXPECT_NEAR(r.rot_rad.mean, 1.0 * kDeg, 1e-12);
  EXPECT_NEAR(r.rot_rad.stddev, 1.0 * kDeg, 1e-12);

  // A wider tolerance takes in the two near misses (exact relations: error 0), not the far one.
  Options wide;
  wide.max_dt_s = 0.2;
  const RelationsResult w = evaluateRelations(est, rels, wide);
  EXPECT_EQ(w.count, 5u);
  EXPECT_EQ(w.skipped, 1u);
}

TEST(Relations, AngularErrorIsWrapped) {
  const Trajectory est{{0.0, SE2(0, 0, 0)}, {1.0, SE2(1, 0, -kPi + 0.01)}};
  const Relations rels{{0.0, 1.0, SE2(1, 0, kPi - 0.01)}};
  const RelationsResult r = evaluateRelations(est, rels);
  ASSERT_EQ(r.count, 1u);
  EXPECT_NEAR(r.errors[0].rot_rad, 0.02, 1e-12);
  EXPECT_NEAR(r.errors[0].trans_m, 0.0, 1e-12);
  EXPECT_EQ(r.trans_m.stddev, 0.0);
}

TEST(Relations, TruthRelationsOfTheTruthAreZeroAndFrameIndependent) {
  const Trajectory ref = wigglyPath(100);
  Relations rels;
  for (std::size_t i = 0; i + 7 < ref.size(); i += 3)
    rels.push_back({ref[i].time, ref[i + 7].time, ref[i].pose.inverse() * ref[i + 7].pose});
  const RelationsResult r = evaluateRelations(transformed(ref, SE2(5, -2, 1.0)), rels);
  EXPECT_EQ(r.count, rels.size());
  EXPECT_EQ(r.skipped, 0u);
  EXPECT_LT(r.trans_m.max, 1e-9);
  EXPECT_LT(r.rot_rad.max, 1e-9);
}

// ---------------------------------------------------------------- per-pair errors

TEST(Pairs, ErrorsSuccessRateAndMedians) {
  const Trajectory ref = wigglyPath(6, 0.0, 1.0);  // t = 0..5
  const auto truth = [&](std::size_t a, std::size_t b) { return ref[a].pose.inverse() * ref[b].pose; };
  std::vector<RelativePose> pairs;
  const auto add = [&](std::size_t k, double ex, double ey, double eth, bool conv) {
    const SE2 T = truth(k, k + 1);
    pairs.push_back({ref[k].time, ref[k + 1].time, SE2(T.x() + ex, T.y() + ey, T.theta() + eth), conv, 10});
  };
  add(0, 0.0, 0.0, 0.0, true);            // exact
  add(1, 0.03, 0.04, 1.0 * kDeg, true);   // 0.05 m, 1 deg: success
  add(2, 0.0, -0.15, 0.0, true);          // 0.15 m: failure
  add(3, 0.0, 0.0, 3.0 * kDeg, false);    // 3 deg: failure
  add(4, 0.07, 0.08, -1.5 * kDeg, true);  // 0.106 m: failure
  const PairsResult r = evaluatePairs(pairs, ref);
  EXPECT_EQ(r.mode, AssociationMode::kIndex);
  EXPECT_EQ(r.count, 5u);
  EXPECT_EQ(r.skipped, 0u);
  EXPECT_EQ(r.successes, 2u);
  EXPECT_EQ(r.converged, 4u);
  EXPECT_DOUBLE_EQ(r.success_rate, 0.4);
  // Translation errors {0, 0.05, 0.15, 0, 0.106}: median 0.05; rotation {0, 1, 0, 3, 1.5} deg: median 1.
  EXPECT_NEAR(r.trans_m.median, 0.05, 1e-12);
  EXPECT_NEAR(r.rot_rad.median, 1.0 * kDeg, 1e-12);
  EXPECT_NEAR(r.trans_m.max, 0.15, 1e-12);
  EXPECT_TRUE(r.errors[1].success);
  EXPECT_FALSE(r.errors[2].success);

  // Looser thresholds change the verdicts, not the errors.
  Options loose;
  loose.pair_max_trans_m = 0.2;
  loose.pair_max_rot_deg = 5.0;
  EXPECT_EQ(evaluatePairs(pairs, ref, loose).successes, 5u);
}

TEST(Pairs, ByTimeWithSkippedPairs) {
  const Trajectory ref = wigglyPath(10, 0.0, 1.0);
  std::vector<RelativePose> pairs;
  // Every second step, times off by 0.05 s: not the consecutive poses, so by time.
  for (std::size_t k = 0; k + 2 < ref.size(); k += 2)
    pairs.push_back({ref[k].time + 0.05, ref[k + 2].time - 0.05, ref[k].pose.inverse() * ref[k + 2].pose, true, 3});
  pairs.push_back({100.0, 101.0, SE2(), true, 1});  // no reference there
  const PairsResult r = evaluatePairs(pairs, ref);
  EXPECT_EQ(r.mode, AssociationMode::kTime);
  EXPECT_EQ(r.count, 4u);
  EXPECT_EQ(r.skipped, 1u);
  EXPECT_EQ(r.successes, 4u);
  EXPECT_NEAR(r.trans_m.max, 0.0, 1e-12);
}

TEST(Pairs, RepeatedTimesUseIndices) {
  // All scans share one time (as infinite-corridor's 6-digit stamps): only index association works.
  Trajectory ref;
  for (int i = 0; i < 5; ++i) ref.push_back({7.0, SE2(0.3 * i, 0.0, 0.1 * i)});
  std::vector<RelativePose> pairs;
  for (std::size_t k = 0; k + 1 < ref.size(); ++k)
    pairs.push_back({7.0, 7.0, ref[k].pose.inverse() * ref[k + 1].pose, true, 5});
  const PairsResult r = evaluatePairs(pairs, ref);
  EXPECT_EQ(r.mode, AssociationMode::kIndex);
  EXPECT_EQ(r.successes, 4u);
  Options by_time;
  by_time.association = AssociationMode::kTime;
  EXPECT_EQ(evaluatePairs(pairs, ref, by_time).successes, 0u);  // every lookup finds pose 0
}

}  // namespace
}  // namespace lidar2d::eval
