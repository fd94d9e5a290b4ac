// `lidar2d perturb` end to end with the options of issue 29: without them the output is byte for byte
// what perturb wrote before; --odom-model and the odometry terms, --keyframes, --gap (at a time,
// centred, at the largest turn), --odom-lag, --time-jitter, --time-bursts, --synthesize-times, --keep-odometry,
// the summary line, determinism, and bad input (usage errors exit 2, bad input exits 1 with one
// line, never a partial output file). The library itself is tested in test_perturb.cpp.

#include <fmt/format.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <numbers>
#include <string>

#include "lidar2d/io/carmen_writer.hpp"
#include "lidar2d/io/frame_source.hpp"
#include "lidar2d/sim/log_perturbation.hpp"
#include "lidar2d/sim/noise.hpp"
#include "support/test_support.hpp"

namespace lidar2d {
namespace {

namespace fs = std::filesystem;
using test::CliResult;
using test::runCli;
using test::TempDir;

constexpr double kDeg = std::numbers::pi / 180.0;

std::vector<Frame> readAll(const std::string& path) {
  auto src = io::openLog(path);
  std::vector<Frame> frames;
  while (auto f = src->next()) frames.push_back(std::move(*f));
  return frames;
}

// A simulated office log with truth: 600 scans at 10 Hz (60 s), 31 beams.
std::string simulatedLog(const TempDir& tmp) {
  const std::string log = (tmp / "clean.log").string();
  const CliResult r = runCli({"simulate", "--world", "office", "--beams", "31", "--scans", "600", "-o", log});
  EXPECT_EQ(r.exit_code, 0) << r.err;
  return log;
}

// What perturb wrote before issue 29's options (its loop and comment, kept here verbatim).
std::string legacyOutput(const std::string& in, const TempDir& tmp, double sx, double sy, double sth,
                         std::uint64_t seed) {
  const std::string path = (tmp / "legacy-reference.log").string();
  io::CarmenWriter writer(path);
  writer.comment(fmt::format(
      "lidar2d perturb: source={} odom_noise=[{},{},{}] seed={}: odom_k = odom_(k-1) * (truth_(k-1)^-1 * truth_k) * "
      "SE2(n), n ~ N(0, diag(SX^2, SY^2, STH^2)) per scan step [m, m, rad]",
      in, sx, sy, sth, seed));
  const sim::OdometryNoise noise = sim::OdometryNoise::constant(sx, sy, sth);
  sim::Rng rng(seed);
  std::optional<SE2> prev_truth;
  SE2 odom;
  auto source = io::openLog(in);
  while (auto f = source->next()) {
    const SE2 truth = *f->T_world_robot;
    odom = prev_truth ? odom * sim::noisyOdometryStep(prev_truth->inverse() * truth, noise, rng) : truth;
    prev_truth = truth;
    f->T_odom_robot = odom;
    writer.write(*f);
  }
  writer.commit();
  return test::readFile(path);
}

struct Summary {
  std::size_t read = 0, kept = 0, by_keyframes = 0, by_gaps = 0;
};

// The summary lines are parsed with sscanf, not std::regex: GCC 12's libstdc++ regex raises a false
// -Wmaybe-uninitialized in the sanitizer build (-O1).
Summary parseSummary(const std::string& out) {
  Summary s;
  const int n = std::sscanf(out.c_str(), "perturbed %zu scans: kept %zu, dropped %zu by keyframes, %zu by gaps",
                            &s.read, &s.kept, &s.by_keyframes, &s.by_gaps);
  EXPECT_EQ(n, 4) << out;
  return n == 4 ? s : Summary{};
}

// Whether `text` is "perturbed N scans: final odometry error E m, A deg -> PATH" and a newline, E and
// A non-negative numbers.
bool isFinalErrorLine(const std::string& text, std::size_t scans, const std::string& path) {
  std::size_t n = 0;
  double e = -1.0, a = -1.0;
  int end = 0;
  if (std::sscanf(text.c_str(), "perturbed %zu scans: final odometry error %lf m, %lf deg -> %n", &n, &e, &a, &end) !=
          3 ||
      end == 0)
    return false;
  return n == scans && e >= 0.0 && a >= 0.0 && text.substr(static_cast<std::size_t>(end)) == path + "\n";
}

TEST(PerturbCli, WithoutNewOptionsTheOutputIsAsBefore) {
  TempDir tmp;
  const std::string clean = simulatedLog(tmp);
  const std::string out = (tmp / "p.log").string();
  CliResult r = runCli({"perturb", clean, "--odom-noise", "0.02,0.01,0.003", "--seed", "9", "-o", out});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(test::readFile(out), legacyOutput(clean, tmp, 0.02, 0.01, 0.003, 9));
  EXPECT_TRUE(isFinalErrorLine(r.out, 600, out)) << r.out;
  // The defaults, and --odom-model constant spelled out.
  r = runCli({"perturb", clean, "-o", out});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const std::string expected = legacyOutput(clean, tmp, 0.01, 0.005, 0.002, 1);
  EXPECT_EQ(test::readFile(out), expected);
  ASSERT_EQ(runCli({"perturb", clean, "--odom-model", "constant", "-o", out}).exit_code, 0);
  EXPECT_EQ(test::readFile(out), expected);
}

TEST(PerturbCli, WithoutNewOptionsARealLogIsAsBefore) {
  LIDAR2D_REQUIRE_DATA("corrected/freiburg-101.log.gz");
  TempDir tmp;
  const std::string in = test::dataFile("corrected/freiburg-101.log.gz").string(), out = (tmp / "p.log").string();
  ASSERT_EQ(runCli({"perturb", in, "--seed", "4", "-o", out}).exit_code, 0);
  EXPECT_EQ(test::readFile(out), legacyOutput(in, tmp, 0.01, 0.005, 0.002, 4));
}

TEST(PerturbCli, RealisticKeyframesAndSeeds) {
  TempDir tmp;
  const std::string clean = simulatedLog(tmp);
  const std::string a = (tmp / "a.log").string(), b = (tmp / "b.log").string(), c = (tmp / "c.log").string();
  const CliResult r =
      runCli({"perturb", clean, "--odom-model", "realistic", "--keyframes", "1,30", "--seed", "3", "-o", a});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const Summary s = parseSummary(r.out);
  EXPECT_EQ(s.read, 600u);
  EXPECT_EQ(s.by_gaps, 0u);
  EXPECT_EQ(s.kept + s.by_keyframes, 600u);
  EXPECT_NE(r.out.find("final odometry error"), std::string::npos) << r.out;
  const auto in = readAll(clean), out = readAll(a);
  ASSERT_EQ(out.size(), s.kept);
  ASSERT_GT(out.size(), 20u);
  ASSERT_LT(out.size(), 120u);  // 48 m of driving, turns in the rooms
  for (std::size_t k = 1; k < out.size(); ++k) {
    const SE2 &p = *out[k - 1].T_world_robot, &q = *out[k].T_world_robot;
    const bool far = (q.translation() - p.translation()).norm() >= 1.0 ||
                     std::abs(angleDiff(q.theta(), p.theta())) >= 30 * kDeg - 1e-9;
    EXPECT_TRUE(far) << k;
    EXPECT_FALSE(test::IsNearPose(q, *out[k].T_odom_robot, 1e-6, 1e-6)) << k;  // noisy odometry
  }
  EXPECT_TRUE(test::IsNearPose(*in[0].T_world_robot, *out[0].T_odom_robot, 1e-9, 1e-7));  // odom_0 = truth_0
  ASSERT_EQ(
      runCli({"perturb", clean, "--odom-model", "realistic", "--keyframes", "1,30", "--seed", "3", "-o", b}).exit_code,
      0);
  ASSERT_EQ(
      runCli({"perturb", clean, "--odom-model", "realistic", "--keyframes", "1,30", "--seed", "4", "-o", c}).exit_code,
      0);
  EXPECT_EQ(test::readFile(a), test::readFile(b));
  EXPECT_NE(test::readFile(a), test::readFile(c));
  // An explicit term overrides the model's: without noise terms only the scale error remains.
  ASSERT_EQ(
      runCli({"perturb", clean, "--odom-model", "realistic", "--odom-noise", "0,0,0", "--odom-trans-noise-per-m", "0",
              "--odom-rot-noise-per-rad", "0", "--odom-rot-noise-deg-per-m", "0", "--odom-scale-error", "0.1", "-o", c})
          .exit_code,
      0);
  const auto scaled = readAll(c);
  for (std::size_t k = 1; k < scaled.size(); ++k) {
    const SE2 t = scaled[k - 1].T_world_robot->inverse() * *scaled[k].T_world_robot;
    const SE2 o = scaled[k - 1].T_odom_robot->inverse() * *scaled[k].T_odom_robot;
    ASSERT_TRUE(test::IsNearPose(SE2(1.1 * t.x(), 1.1 * t.y(), t.theta()), o, 1e-6, 1e-5)) << k;
  }
  EXPECT_NE(test::readFile(c).find("scale_error=0.1"), std::string::npos);
}

TEST(PerturbCli, GapsDropTheirWindowsAndTheSummarySaysWhere) {
  TempDir tmp;
  const std::string clean = simulatedLog(tmp);
  const std::string out = (tmp / "g.log").string();
  const CliResult r = runCli({"perturb", clean, "--gap", "5@turn", "--gap", "3@10", "--gap", "1.9", "-o", out});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto in = readAll(clean), got = readAll(out);
  std::vector<sim::TimedPose> samples;
  for (const Frame& f : in) samples.push_back({f.time, *f.T_world_robot});
  const auto windows = sim::planGaps({{5.0, sim::GapPlacement::kLargestTurn, 0},
                                      {3.0, sim::GapPlacement::kAtOffset, 10.0},
                                      {1.9, sim::GapPlacement::kMiddle, 0}},
                                     samples);
  std::vector<double> expected_times;
  for (const Frame& f : in) {
    bool dropped = false;
    for (const auto& w : windows) dropped = dropped || w.contains(f.time);
    if (!dropped) expected_times.push_back(f.time);
  }
  std::vector<double> times;
  for (const Frame& f : got) times.push_back(f.time);
  EXPECT_EQ(times, expected_times);
  const Summary s = parseSummary(r.out);
  EXPECT_EQ(s.read, 600u);
  EXPECT_EQ(s.by_gaps, 600u - got.size());
  EXPECT_EQ(s.by_keyframes, 0u);
  // Where: each gap's offset from the first scan, its turn and its scan count.
  EXPECT_NE(r.out.find(fmt::format("{:.1f}-{:.1f} s, turn {:.0f} deg: ", windows[0].begin_s - in[0].time,
                                   windows[0].end_s - in[0].time, windows[0].turn_rad / kDeg)),
            std::string::npos)
      << r.out;
  EXPECT_NE(r.out.find("10.0-13.0 s"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("29.0-30.9 s"), std::string::npos) << r.out;  // 1.9 s centred in 59.9 s
  EXPECT_GT(windows[0].turn_rad, 90 * kDeg);
}

TEST(PerturbCli, TimestampFaults) {
  TempDir tmp;
  const std::string clean = simulatedLog(tmp);
  const auto in = readAll(clean);
  const std::string bursts = (tmp / "bursts.log").string(), fixed = (tmp / "fixed.log").string(),
                    jitter = (tmp / "jitter.log").string(), plain = (tmp / "plain.log").string();
  // Bursts of 4: each group of 4 scans carries its last scan's stamp.
  ASSERT_EQ(runCli({"perturb", clean, "--time-bursts", "4", "-o", bursts}).exit_code, 0);
  const auto b = readAll(bursts);
  ASSERT_EQ(b.size(), in.size());
  for (std::size_t k = 0; k < b.size(); ++k) EXPECT_EQ(b[k].time, in[(k / 4) * 4 + 3].time) << k;
  // Synthesized times repair them: t0 + i / HZ, t0 the first (burst) stamp.
  ASSERT_EQ(runCli({"perturb", bursts, "--synthesize-times", "10", "-o", fixed}).exit_code, 0);
  const auto f = readAll(fixed);
  for (std::size_t k = 0; k < f.size(); ++k) EXPECT_NEAR(f[k].time, b[0].time + 0.1 * k, 1e-9) << k;
  // Jitter: Gaussian, seeded; the odometry is that of the same seed without jitter.
  ASSERT_EQ(runCli({"perturb", clean, "--time-jitter", "0.01", "--seed", "5", "-o", jitter}).exit_code, 0);
  ASSERT_EQ(runCli({"perturb", clean, "--seed", "5", "-o", plain}).exit_code, 0);
  const auto j = readAll(jitter), p = readAll(plain);
  ASSERT_EQ(j.size(), p.size());
  double sum2 = 0;
  for (std::size_t k = 0; k < j.size(); ++k) {
    sum2 += (j[k].time - in[k].time) * (j[k].time - in[k].time);
    EXPECT_TRUE(test::IsNearPose(*p[k].T_odom_robot, *j[k].T_odom_robot, 1e-9, 1e-7)) << k;
  }
  EXPECT_NEAR(std::sqrt(sum2 / static_cast<double>(j.size())), 0.01, 0.0015);  // 600 samples: 3 % std error
}

TEST(PerturbCli, OdometryLagReadsTheOdometryAtAnotherTime) {
  TempDir tmp;
  const std::string clean = simulatedLog(tmp);
  const auto in = readAll(clean);
  const std::string late = (tmp / "late.log").string(), early = (tmp / "early.log").string(),
                    random = (tmp / "random.log").string(), random2 = (tmp / "random2.log").string();
  // One period late (10 Hz), no noise: each scan's odometry step is the truth's next one; one period
  // early, the previous one.
  ASSERT_EQ(runCli({"perturb", clean, "--odom-noise", "0,0,0", "--odom-lag", "0.1", "-o", late}).exit_code, 0);
  ASSERT_EQ(runCli({"perturb", clean, "--odom-noise", "0,0,0", "--odom-lag", "-0.1", "-o", early}).exit_code, 0);
  const auto l = readAll(late), e = readAll(early);
  ASSERT_EQ(l.size(), in.size());
  ASSERT_EQ(e.size(), in.size());
  auto step = [](const std::vector<Frame>& f, std::size_t k, bool odom) {
    return odom ? f[k - 1].T_odom_robot->inverse() * *f[k].T_odom_robot
                : f[k - 1].T_world_robot->inverse() * *f[k].T_world_robot;
  };
  for (std::size_t k = 2; k + 1 < in.size(); ++k) {
    EXPECT_TRUE(test::IsNearPose(step(in, k + 1, false), step(l, k, true), 1e-6, 1e-4)) << k;
    EXPECT_TRUE(test::IsNearPose(step(in, k - 1, false), step(e, k, true), 1e-6, 1e-4)) << k;
    EXPECT_TRUE(test::IsNearPose(*in[k].T_world_robot, *l[k].T_world_robot, 0, 0)) << k;  // truth unchanged
  }
  // A random lag: seeded, named in the log's comment.
  ASSERT_EQ(runCli({"perturb", clean, "--odom-model", "realistic", "--odom-lag", "0,0.03", "--seed", "3", "-o", random})
                .exit_code,
            0);
  ASSERT_EQ(
      runCli({"perturb", clean, "--odom-model", "realistic", "--odom-lag", "0,0.03", "--seed", "3", "-o", random2})
          .exit_code,
      0);
  EXPECT_EQ(test::readFile(random), test::readFile(random2));
  EXPECT_NE(test::readFile(random).find("lag_s=0,0.03"), std::string::npos);
}

/// An odometry-only CARMEN log of 200 scans at 10 Hz: FLASER lines whose poses are odometry,
/// 5 cm apart, turning 10 degrees per scan over scans 50-79.
std::string turningOdometryLog() {
  std::string text;
  double x = 0, y = 0, th = 0;
  for (int i = 0; i < 200; ++i) {
    if (i >= 50 && i < 80) th += 10 * kDeg;
    x += 0.05 * std::cos(th);
    y += 0.05 * std::sin(th);
    text += fmt::format("FLASER 3 1.0 1.5 2.0 {} {} {} {} {} {} {} host {}\n", x, y, th, x, y, th, 0.1 * i, 0.1 * i);
  }
  return text;
}

TEST(PerturbCli, KeepOdometryDropsAndRetimesALogWithoutTruth) {
  TempDir tmp;
  const std::string in = (tmp / "odo.log").string(), out = (tmp / "kept.log").string();
  test::writeFile(in, turningOdometryLog());
  const CliResult r = runCli({"perturb", in, "--keep-odometry", "--gap", "2@turn", "--keyframes", "0.2,0", "-o", out});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("odometry kept from the log"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("turn 190 deg: 20 scans"), std::string::npos) << r.out;  // 20 scans, 19 turns of 10 deg
  const auto src = readAll(in), got = readAll(out);
  ASSERT_LT(got.size(), src.size());
  for (const Frame& g : got) {
    EXPECT_FALSE(g.T_world_robot);
    const auto i = static_cast<std::size_t>(std::lround(g.time * 10));
    EXPECT_TRUE(test::IsNearPose(*src[i].T_odom_robot, *g.T_odom_robot, 1e-9, 1e-7));
    // Scans 50-79 turn 10 deg each: every 2 s window from scan 49 to scan 60 holds 19 such turns; ties
    // go to the earliest, [4.9, 6.9) s, scans 49-68.
    EXPECT_FALSE(i >= 49 && i <= 68) << i;
  }
}

TEST(PerturbCli, FreezeOdometryKeepsTheScansAndHoldsTheirOdometryThroughATurn) {
  TempDir tmp;
  const std::string in = (tmp / "odo.log").string(), out = (tmp / "frozen.log").string();
  test::writeFile(in, turningOdometryLog());
  const CliResult r = runCli({"perturb", in, "--keep-odometry", "--freeze-odometry", "2@turn", "-o", out});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("kept 200, dropped 0 by keyframes, 0 by gaps (odometry frozen 4.9-6.9 s, turn 190 deg: 20 "
                       "scans)"),
            std::string::npos)
      << r.out;
  const auto src = readAll(in), got = readAll(out);
  ASSERT_EQ(got.size(), src.size());
  // Scans 49-68 read scan 48's odometry; the others their own.
  for (std::size_t i = 0; i < got.size(); ++i)
    EXPECT_TRUE(test::IsNearPose(*src[i >= 49 && i <= 68 ? 48 : i].T_odom_robot, *got[i].T_odom_robot, 1e-9, 1e-7))
        << i;
  EXPECT_NE(test::readFile(out).find("gaps=frozen-odometry[4.900,6.900)"), std::string::npos);
  // A malformed window is a usage error.
  EXPECT_EQ(runCli({"perturb", in, "--keep-odometry", "--freeze-odometry", "abc", "-o", out}).exit_code, 2);
}

TEST(PerturbCli, OdometrySlipAddsMotionTheRobotDidNotMakeDuringATurn) {
  TempDir tmp;
  const std::string in = (tmp / "odo.log").string(), out = (tmp / "slip.log").string();
  test::writeFile(in, turningOdometryLog());
  const CliResult r = runCli({"perturb", in, "--keep-odometry", "--odom-slip", "2@turn,1,-30", "-o", out});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("(odometry slip 1 m, -30 deg 4.9-6.9 s, turn 190 deg: 20 scans)"), std::string::npos) << r.out;
  EXPECT_NE(test::readFile(out).find("gaps=odometry-slip(1m,-30deg)[4.900,6.900)"), std::string::npos);
  const auto src = readAll(in), got = readAll(out);
  ASSERT_EQ(got.size(), src.size());
  // After the window every reading is the log's offset by the slip: 30 degrees less turn.
  const SE2 offset = src.back().T_odom_robot->inverse() * *got.back().T_odom_robot;
  EXPECT_NEAR(offset.theta(), -30.0 * kDeg, 1e-6);
  for (std::size_t i = 0; i < 49; ++i)
    EXPECT_TRUE(test::IsNearPose(*src[i].T_odom_robot, *got[i].T_odom_robot, 1e-9, 1e-7)) << i;
  // A window without its motion, or a motion that is not a number, is a usage error.
  EXPECT_EQ(runCli({"perturb", in, "--keep-odometry", "--odom-slip", "2@turn", "-o", out}).exit_code, 2);
  EXPECT_EQ(runCli({"perturb", in, "--keep-odometry", "--odom-slip", "2@turn,x", "-o", out}).exit_code, 2);
}

TEST(PerturbCli, KeepOdometryOnARealBagWithAGapDuringATurn) {
  LIDAR2D_REQUIRE_DATA("raw/mit-csail.orig.bag");
  TempDir tmp;
  const std::string bag = test::dataFile("raw/mit-csail.orig.bag").string(), out = (tmp / "gap.log").string();
  const CliResult r = runCli({"perturb", bag, "--keep-odometry", "--gap", "10@turn", "-o", out});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const Summary s = parseSummary(r.out);
  EXPECT_EQ(s.read, 1988u);
  EXPECT_GT(s.by_gaps, 30u);
  EXPECT_EQ(s.kept + s.by_gaps, s.read);
  EXPECT_EQ(readAll(out).size(), s.kept);
}

// ---- bad input ----

TEST(PerturbCli, KidnapIsAGapTheOdometryDoesNotSee) {
  TempDir tmp;
  const std::string clean = simulatedLog(tmp);
  const std::string out = (tmp / "k.log").string();
  const CliResult r = runCli({"perturb", clean, "--kidnap", "5@20", "--odom-noise", "0,0,0", "-o", out});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("kidnapping 20.0-25.0 s"), std::string::npos) << r.out;
  const auto got = readAll(out);
  std::size_t jumps = 0;
  for (std::size_t k = 1; k < got.size(); ++k) {
    if (got[k].time - got[k - 1].time < 1.0) continue;  // the file's scans are numbered anew: the gap is in time
    ++jumps;
    // The text log holds the poses to its printed precision.
    EXPECT_TRUE(test::IsNearPose(*got[k - 1].T_odom_robot, *got[k].T_odom_robot, 1e-5, 1e-5));
    EXPECT_GT((got[k].T_world_robot->translation() - got[k - 1].T_world_robot->translation()).norm(), 0.5);
  }
  EXPECT_EQ(jumps, 1u);
}

TEST(PerturbCli, UsageErrorsExit2WithoutOutput) {
  TempDir tmp;
  const std::string clean = simulatedLog(tmp);
  const std::string out = (tmp / "x.log").string();
  const std::vector<std::vector<std::string>> bad{
      {"--keyframes", "0,0"},
      {"--keyframes", "-1,10"},
      {"--keyframes", "1,200"},
      {"--keyframes", "1"},
      {"--keyframes", "nan,5"},
      {"--keyframes", "1,2,3"},
      {"--gap", "-5"},
      {"--gap", "0"},
      {"--gap", "5@-1"},
      {"--gap", "5@"},
      {"--gap", "inf"},
      {"--gap", "5@corner"},
      {"--kidnap", "0"},
      {"--kidnap", "5@x"},
      {"--time-jitter", "-0.1"},
      {"--time-jitter", "nan"},
      {"--time-bursts", "0"},
      {"--time-bursts", "-2"},
      {"--synthesize-times", "0"},
      {"--synthesize-times", "-10"},
      {"--odom-model", "fancy"},
      {"--odom-scale-error", "-1"},
      {"--odom-trans-noise-per-m", "-0.1"},
      {"--odom-rot-noise-per-rad", "inf"},
      {"--odom-rot-noise-deg-per-m", "-1"},
      {"--odom-drift-deg-per-m", "nan"},
      {"--keep-odometry", "--odom-model", "realistic"},
      {"--keep-odometry", "--odom-noise", "0.1,0.1,0.1"},
      {"--odom-lag", "x"},
      {"--odom-lag", "0.1,-0.02"},
      {"--odom-lag", "inf"},
      {"--odom-lag", "0.1,nan"},
      {"--odom-lag", "0.1,0.02,3"},
      {"--keep-odometry", "--odom-lag", "0.05"},
  };
  for (const auto& opts : bad) {
    std::vector<std::string> args{"perturb", clean, "-o", out};
    args.insert(args.end(), opts.begin(), opts.end());
    const CliResult r = runCli(args);
    EXPECT_EQ(r.exit_code, 2) << opts[0] << " " << opts[1] << ": " << r.err;
    EXPECT_NE(r.err.find(opts[0] == "--keep-odometry" ? "excludes" : opts[0]), std::string::npos)
        << opts[0] << ": " << r.err;
    EXPECT_FALSE(fs::exists(out)) << opts[0];
  }
  const CliResult r = runCli({"perturb", clean, "--keyframes", "0,0", "-o", out});
  EXPECT_NE(r.err.find("D and K are both 0"), std::string::npos) << r.err;
}

TEST(PerturbCli, BadInputExits1WithOneLineAndNoOutput) {
  TempDir tmp;
  const std::string clean = simulatedLog(tmp);  // 59.9 s from the first to the last scan
  const std::string out = (tmp / "x.log").string();
  const std::string equal_times = (tmp / "equal.log").string();
  ASSERT_EQ(runCli({"perturb", clean, "--time-bursts", "1000", "-o", equal_times}).exit_code, 0);
  test::writeFile(tmp / "odo.log",
                  "FLASER 3 1.0 1.5 2.0 0.0 0.0 0.0 0.0 0.0 0.0 1.0 host 1.0\n"
                  "FLASER 3 1.0 1.5 2.0 0.1 0.0 0.0 0.1 0.0 0.0 1.1 host 1.1\n");
  struct Case {
    std::vector<std::string> args;
    std::string message;
  };
  const std::vector<Case> cases{
      {{"perturb", clean, "--gap", "100", "-o", out}, "does not fit"},
      {{"perturb", clean, "--gap", "60@turn", "-o", out}, "does not fit"},
      {{"perturb", clean, "--gap", "10@55", "-o", out}, "ends after the last scan"},
      {{"perturb", clean, "--gap", "40", "--gap", "20@turn", "-o", out}, "no room"},
      {{"perturb", equal_times, "--gap", "1", "-o", out}, "timestamps do not advance"},
      {{"perturb", (tmp / "odo.log").string(), "--keyframes", "1,0", "-o", out}, "--keep-odometry"},
      {{"perturb", (tmp / "odo.log").string(), "--gap", "0.05@turn", "-o", out}, "no ground-truth pose"},
      {{"perturb", (tmp / "nope.log").string(), "--gap", "1", "-o", out}, "nope.log"},
      // A folder under a regular file cannot be created (a missing folder would be).
      {{"perturb", clean, "--gap", "1", "-o", clean + "/x.log"}, "clean.log/x.log"},
  };
  for (const Case& c : cases) {
    const CliResult r = runCli(c.args);
    EXPECT_EQ(r.exit_code, 1) << c.message << ": " << r.err;
    EXPECT_EQ(r.err.rfind("lidar2d: error: ", 0), 0u) << r.err;
    EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
    EXPECT_NE(r.err.find(c.message), std::string::npos) << r.err;
    EXPECT_FALSE(fs::exists(out)) << c.message;
  }
  for (const auto& e : fs::directory_iterator(tmp.path()))
    EXPECT_TRUE(e.path().extension() == ".log") << e.path();  // no temporary file left behind
}

}  // namespace
}  // namespace lidar2d
