// `lidar2d eval` end to end: JSON keys and values, -o, logs as estimate and truth, malformed input
// (exit 1, one stderr line naming file and line, no partial -o file), usage errors (exit 2), and the
// real intel data against its Kuemmerle relations.

#include <gtest/gtest.h>

#include <ostream>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <numbers>
#include <sstream>

#include "lidar2d/io/trajectory.hpp"
#include "support/test_support.hpp"

namespace lidar2d {
namespace {

using nlohmann::json;
using test::CliResult;
using test::runCli;
using test::TempDir;
using test::writeFile;

constexpr double kDeg = std::numbers::pi / 180.0;

Trajectory path(std::size_t n, double dt = 0.2) {
  Trajectory t;
  SE2 T;
  for (std::size_t i = 0; i < n; ++i) {
    t.push_back({1000.0 + dt * static_cast<double>(i), T});
    T = T * SE2(0.3, 0.01, 0.1 * std::sin(0.2 * static_cast<double>(i)));
  }
  return t;
}

json parse(const CliResult& r) {
  EXPECT_EQ(r.exit_code, 0) << r.err;
  return json::parse(r.out);
}

std::size_t filesIn(const std::filesystem::path& dir) {
  std::size_t n = 0;
  for (const auto& e : std::filesystem::directory_iterator(dir)) n += e.is_regular_file();
  return n;
}

TEST(CliEval, TruthAgainstItselfIsZeroAndOutputFileMatchesStdout) {
  TempDir tmp;
  const auto traj = (tmp / "truth.txt").string();
  io::writeTrajectory(traj, path(50));
  const auto out = (tmp / "m.json").string();
  const CliResult r = runCli({"eval", traj, "--truth", traj, "-o", out});
  const json j = parse(r);
  for (const char* k : {"ate_rmse_m", "ate_mean_m", "ate_max_m", "ate_rot_rmse_deg", "rpe_trans_rmse_m",
                        "rpe_rot_rmse_deg", "rpe_per_m_trans_mean", "rpe_per_m_rot_mean_deg"})
    EXPECT_EQ(j.at(k).get<double>(), 0.0) << k;
  EXPECT_EQ(j.at("matched").get<int>(), 50);
  EXPECT_EQ(j.at("unmatched").get<int>(), 0);
  EXPECT_EQ(j.at("association").get<std::string>(), "index");
  EXPECT_EQ(test::readFile(out), r.out);
}

TEST(CliEval, RigidTransformIsAlignedAway) {
  TempDir tmp;
  const Trajectory truth = path(60);
  Trajectory est = truth;
  const SE2 T(4.0, -1.0, 0.8);
  for (auto& p : est) p.pose = T * p.pose;
  io::writeTrajectory((tmp / "truth.txt").string(), truth);
  io::writeTrajectory((tmp / "est.tum").string(), est, io::TrajectoryFormat::kTum);  // TUM estimate
  const json j = parse(runCli({"eval", (tmp / "est.tum").string(), "--truth", (tmp / "truth.txt").string()}));
  EXPECT_LT(j.at("ate_rmse_m").get<double>(), 1e-6);
  EXPECT_GT(j.at("ate_unaligned_rmse_m").get<double>(), 1.0);
  EXPECT_NEAR(j.at("alignment").at("theta_deg").get<double>(), -0.8 / kDeg, 1e-6);
  const json u = parse(runCli({"eval", (tmp / "est.tum").string(), "--truth", (tmp / "truth.txt").string(), "--no-align"}));
  EXPECT_GT(u.at("ate_rmse_m").get<double>(), 1.0);
}

TEST(CliEval, TimeToleranceDecidesMatching) {
  TempDir tmp;
  const Trajectory truth = path(20, 1.0);  // poses 1 s apart
  Trajectory est = truth;
  for (auto& p : est) p.time += 0.15;
  io::writeTrajectory((tmp / "truth.txt").string(), truth);
  io::writeTrajectory((tmp / "est.txt").string(), est);
  const CliResult none = runCli({"eval", (tmp / "est.txt").string(), "--truth", (tmp / "truth.txt").string()});
  EXPECT_EQ(none.exit_code, 1);
  EXPECT_NE(none.err.find("no estimated pose is within"), std::string::npos) << none.err;
  const json j = parse(runCli({"eval", (tmp / "est.txt").string(), "--truth", (tmp / "truth.txt").string(),
                               "--max-dt", "0.2"}));
  EXPECT_EQ(j.at("association").get<std::string>(), "time");
  EXPECT_EQ(j.at("matched").get<int>(), 20);
  EXPECT_LT(j.at("ate_rmse_m").get<double>(), 1e-9);
}

// Two clocks that agree on one pose only (an estimate of a log whose times were rewritten): the
// ATE of that one pose is zero, and must not read as a perfect score.
TEST(CliEval, AFewStrayMatchesAreSaidToBeAFew) {
  TempDir tmp;
  const Trajectory truth = path(20, 1.0);
  Trajectory est = truth;
  for (std::size_t i = 1; i < est.size(); ++i) est[i].time += 1000.0;
  io::writeTrajectory((tmp / "truth.txt").string(), truth);
  io::writeTrajectory((tmp / "est.txt").string(), est);
  const CliResult r = runCli({"eval", (tmp / "est.txt").string(), "--truth", (tmp / "truth.txt").string()});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const json j = json::parse(r.out);
  EXPECT_EQ(j.at("matched").get<int>(), 1);
  EXPECT_NE(j.at("warnings").dump().find("only 1 of the 20 estimated and 20 truth poses"), std::string::npos)
      << j.dump(2);
  EXPECT_NE(r.err.find("warning: only 1 of the 20"), std::string::npos) << r.err;
  const json all = parse(runCli({"eval", (tmp / "truth.txt").string(), "--truth", (tmp / "truth.txt").string()}));
  EXPECT_TRUE(all.at("warnings").empty()) << all.dump(2);
}

TEST(CliEval, RelationsWithKnownErrors) {
  TempDir tmp;
  writeFile(tmp / "est.txt", "10 0 0 0\n11 1 0 0\n12 2 0 0\n");
  // Errors 0, 0.1 m / 1 deg, 0.2 m / 2 deg; the last relation is outside 0.1 s and skipped. No
  // .relations extension: detected from 8 numeric fields that are not a unit quaternion.
  writeFile(tmp / "gt.txt",
            "10 11 1 0 0 0 0 0\n"
            "11.05 12 1 0.1 0 0 0 " + std::to_string(1.0 * kDeg) + "\n"
            "10 12 2.2 0 0 0 0 " + std::to_string(-2.0 * kDeg) + "\n"
            "10 12.2 2 0 0 0 0 0\n");
  const json j = parse(runCli({"eval", (tmp / "est.txt").string(), "--truth", (tmp / "gt.txt").string()}));
  EXPECT_EQ(j.at("truth").at("kind").get<std::string>(), "relations");
  EXPECT_FALSE(j.contains("ate_rmse_m"));
  const json& r = j.at("relations");
  EXPECT_EQ(r.at("count").get<int>(), 3);
  EXPECT_EQ(r.at("skipped").get<int>(), 1);
  EXPECT_NEAR(r.at("trans_mean_m").get<double>(), 0.1, 1e-9);
  EXPECT_NEAR(r.at("trans_std_m").get<double>(), 0.1, 1e-9);  // sample std of {0, 0.1, 0.2}
  EXPECT_NEAR(r.at("rot_mean_deg").get<double>(), 1.0, 1e-3);  // to_string keeps 6 decimals of radians
  EXPECT_NEAR(r.at("rot_std_deg").get<double>(), 1.0, 1e-3);
}

TEST(CliEval, PairsSuccessRateAndMedians) {
  TempDir tmp;
  writeFile(tmp / "truth.txt", "1 0 0 0\n2 1 0 0\n3 2 0 0\n4 3 0 0\n");
  // Errors: 0; 0.05 m; 0.3 m (failure); median 0.05 m.
  writeFile(tmp / "pairs.txt", "1 2 1 0 0 1 5\n2 3 1.05 0 0 1 7\n3 4 1 0.3 0 0 30\n");
  const json j = parse(runCli({"eval", (tmp / "truth.txt").string(), "--truth", (tmp / "truth.txt").string(),
                               "--pairs", (tmp / "pairs.txt").string()}));
  const json& p = j.at("pairs");
  EXPECT_EQ(p.at("count").get<int>(), 3);
  EXPECT_EQ(p.at("successes").get<int>(), 2);
  EXPECT_NEAR(p.at("success_rate").get<double>(), 2.0 / 3.0, 1e-12);
  EXPECT_NEAR(p.at("median_trans_m").get<double>(), 0.05, 1e-9);
  EXPECT_EQ(p.at("median_rot_deg").get<double>(), 0.0);
  EXPECT_EQ(p.at("converged").get<int>(), 2);
  EXPECT_EQ(p.at("association").get<std::string>(), "index");
}

TEST(CliEval, CarmenLogAsEstimateAndAsTruth) {
  TempDir tmp;
  // FLASER lines without ODOM lines: the pose triples are odometry and there is no truth.
  writeFile(tmp / "small.log",
            "FLASER 5 1 1 1 1 1 0.5 0.25 0.1 0.5 0.25 0.1 100.0 h 100.0\n"
            "FLASER 5 1 1 1 1 1 1.0 0.5 0.2 1.0 0.5 0.2 100.5 h 100.5\n"
            "FLASER 5 1 1 1 1 1 1.5 0.5 0.3 1.5 0.5 0.3 101.0 h 101.0\n");
  writeFile(tmp / "same.txt", "100.0 0.5 0.25 0.1\n100.5 1.0 0.5 0.2\n101.0 1.5 0.5 0.3\n");
  const auto log = (tmp / "small.log").string();
  const json j = parse(runCli({"eval", log, "--truth", (tmp / "same.txt").string()}));
  EXPECT_EQ(j.at("estimate").at("kind").get<std::string>(), "log");
  EXPECT_EQ(j.at("matched").get<int>(), 3);
  EXPECT_EQ(j.at("ate_rmse_m").get<double>(), 0.0);

  const CliResult no_truth = runCli({"eval", (tmp / "same.txt").string(), "--truth", log});
  EXPECT_EQ(no_truth.exit_code, 1);
  EXPECT_NE(no_truth.err.find("small.log: the log has no ground-truth poses"), std::string::npos) << no_truth.err;
  const CliResult frame = runCli({"eval", log, "--estimate-from", "truth", "--truth", (tmp / "same.txt").string()});
  EXPECT_EQ(frame.exit_code, 1);
  EXPECT_NE(frame.err.find("frame 0 (t=100.000000): has no ground-truth pose"), std::string::npos) << frame.err;
}

// ---------------------------------------------------------------- malformed input: exit 1

struct BadInput {
  const char* name;
  const char* est;       // content of est.txt (nullptr: a valid trajectory)
  const char* truth;     // content of the truth file (nullptr: a valid trajectory)
  const char* truth_name;
  const char* expected;  // substring of stderr after the file path
};
// gtest prints parameters in test listings; a name instead of a byte dump keeps ctest readable.
[[maybe_unused]] void PrintTo(const BadInput&, std::ostream* os) { *os << "BadInput"; }


class CliEvalMalformed : public ::testing::TestWithParam<BadInput> {};

TEST_P(CliEvalMalformed, OneLineNamingFileAndLineAndNoOutputFile) {
  const BadInput& c = GetParam();
  TempDir tmp;
  const std::string valid = "1 0 0 0\n2 1 0 0\n3 2 0.5 0.1\n";
  writeFile(tmp / "est.txt", c.est ? c.est : valid);
  writeFile(tmp / c.truth_name, c.truth ? c.truth : valid);
  const auto out = tmp / "m.json";
  const CliResult r = runCli({"eval", (tmp / "est.txt").string(), "--truth", (tmp / c.truth_name).string(), "-o", out.string()});
  EXPECT_EQ(r.exit_code, 1) << r.out << r.err;
  EXPECT_TRUE(r.out.empty()) << r.out;
  EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
  EXPECT_EQ(r.err.rfind("lidar2d: error: ", 0), 0u) << r.err;
  EXPECT_NE(r.err.find(c.expected), std::string::npos) << r.err << " lacks " << c.expected;
  EXPECT_FALSE(std::filesystem::exists(out));
  EXPECT_EQ(filesIn(tmp.path()), 2u);  // est and truth only: no temporary file left
}

INSTANTIATE_TEST_SUITE_P(
    Cases, CliEvalMalformed,
    ::testing::Values(
        BadInput{"non_numeric_estimate", "1 0 0 0\n2 x 0 0\n", nullptr, "truth.txt", "est.txt:2: field 2 (x): not a number"},
        BadInput{"non_numeric_first_line", "a 0 0 0\n", nullptr, "truth.txt", "est.txt:1: field 1 (timestamp)"},
        BadInput{"nan_truth", nullptr, "1 0 0 0\n\n2 0 0 nan\n", "truth.txt", "truth.txt:3: field 4 (theta): not a finite"},
        BadInput{"wrong_field_count", "1 0 0 0\n2 0 0 0 0 0\n", nullptr, "truth.txt", "est.txt:2: expected 4 fields"},
        BadInput{"empty_estimate", "", nullptr, "truth.txt", "est.txt: holds no poses"},
        BadInput{"relations_with_5_fields", nullptr, "1 2 0.5 0 0 0 0 0\n2 3 0.5 0\t0\n", "gt.relations",
                 "gt.relations:2: expected 8 fields"},
        BadInput{"relations_non_numeric", nullptr, "# t1 t2 dx dy dz droll dpitch dyaw\n1 2 0.5 0 0 0 0 abc\n",
                 "gt.relations", "gt.relations:2: field 8 (dyaw)"},
        BadInput{"estimate_is_relations", "1 2 0.5 0 0 0 0 0.3\n", nullptr, "truth.txt", "est.txt: is a relations file"},
        BadInput{"bad_quaternion", "1 0 0 0 0 0 0 1\n2 0 0 0 0 0 0 2\n", nullptr, "truth.txt", "est.txt:2: fields 5-8"}),
    [](const auto& info) { return std::string(info.param.name); });

TEST(CliEval, UnwritableOutputPathIsExit1) {
  TempDir tmp;
  writeFile(tmp / "t.txt", "1 0 0 0\n2 1 0 0\n");
  // A folder cannot be created under a regular file (a missing folder would be created).
  const auto out = tmp / "t.txt" / "m.json";
  const CliResult r = runCli({"eval", (tmp / "t.txt").string(), "--truth", (tmp / "t.txt").string(), "-o", out.string()});
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_TRUE(r.out.empty());
  EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
  EXPECT_NE(r.err.find("m.json"), std::string::npos) << r.err;
  EXPECT_FALSE(std::filesystem::exists(out));
  const CliResult dir = runCli({"eval", (tmp / "t.txt").string(), "--truth", (tmp / "t.txt").string(), "-o", tmp.path().string()});
  EXPECT_EQ(dir.exit_code, 1) << dir.err;
}

TEST(CliEval, MissingFilesAndBadPairsAreExit1) {
  TempDir tmp;
  writeFile(tmp / "t.txt", "1 0 0 0\n2 1 0 0\n");
  writeFile(tmp / "pairs.txt", "1 2 1 0 0 1 5\n1 2 1 0 0 3 5\n");
  const auto t = (tmp / "t.txt").string();
  const CliResult missing = runCli({"eval", (tmp / "nope.txt").string(), "--truth", t});
  EXPECT_EQ(missing.exit_code, 1);
  EXPECT_NE(missing.err.find("nope.txt: no such file"), std::string::npos) << missing.err;
  const CliResult pairs = runCli({"eval", t, "--truth", t, "--pairs", (tmp / "pairs.txt").string()});
  EXPECT_EQ(pairs.exit_code, 1);
  EXPECT_NE(pairs.err.find("pairs.txt:2: field 6 (converged)"), std::string::npos) << pairs.err;
  EXPECT_TRUE(pairs.out.empty());
}

// ---------------------------------------------------------------- usage errors: exit 2

TEST(CliEval, UsageErrorsExit2) {
  TempDir tmp;
  writeFile(tmp / "t.txt", "1 0 0 0\n2 1 0 0\n");
  writeFile(tmp / "g.relations", "1 2 1 0 0 0 0 0\n");
  const auto t = (tmp / "t.txt").string();
  const std::vector<std::vector<std::string>> cases{
      {"eval"},
      {"eval", t},
      {"eval", "--truth", t},
      {"eval", t, "--truth", t, "--estimate-from", "magic"},
      {"eval", t, "--truth", t, "--max-dt", "-1"},
      {"eval", t, "--truth", t, "--max-dt", "abc"},
      {"eval", t, "--truth", t, "--association", "nearest"},
      {"eval", t, "--truth", t, "--bogus"},
      {"eval", t, "--truth", (tmp / "g.relations").string(), "--pairs", t},
  };
  for (const auto& args : cases) {
    const CliResult r = runCli(args);
    std::string joined;
    for (const auto& a : args) joined.append(a).append(" ");
    EXPECT_EQ(r.exit_code, 2) << joined << "\n" << r.err;
  }
}

// ---------------------------------------------------------------- real data

TEST(CliEvalData, IntelRawOdometryAgainstRelations) {
  LIDAR2D_REQUIRE_DATA("raw/intel.orig.bag");
  LIDAR2D_REQUIRE_DATA("raw/intel.relations");
  const json j = parse(runCli({"eval", test::dataFile("raw/intel.orig.bag").string(), "--truth",
                               test::dataFile("raw/intel.relations").string()}));
  const json& r = j.at("relations");
  // 2984 relations: `awk 'NF==8 && $1 !~ /^#/' raw/intel.relations | wc -l`; every relation time is
  // a scan time, so none is skipped.
  EXPECT_EQ(r.at("count").get<int>() + r.at("skipped").get<int>(), 2984);
  EXPECT_EQ(r.at("skipped").get<int>(), 0);
  // Independent figures from /usr/bin/python3 with Debian's rosbag: /odom poses (header stamps)
  // linearly interpolated at each /scan header stamp, nearest scan within 0.1 s of t1 and t2,
  // |(dx,dy)_est - (dx,dy)_ref| and |wrap(dyaw_est - dyaw_ref)|, sample std:
  //   trans 7.378063630438084 +- 14.347460309851868 m, rot 39.34273637789118 +- 53.69117967371299 deg.
  // Raw wheel odometry drifts by several metres over the 2691 s log.
  EXPECT_NEAR(r.at("trans_mean_m").get<double>(), 7.37806363, 1e-3);
  EXPECT_NEAR(r.at("trans_std_m").get<double>(), 14.34746031, 1e-3);
  EXPECT_NEAR(r.at("rot_mean_deg").get<double>(), 39.34273638, 1e-2);
  EXPECT_NEAR(r.at("rot_std_deg").get<double>(), 53.69117967, 1e-2);
  EXPECT_EQ(j.at("estimate").at("poses").get<int>(), 13631);  // scans in the bag (python rosbag)
}

TEST(CliEvalData, CorrectedIntelTruthAgainstItselfIsZero) {
  LIDAR2D_REQUIRE_DATA("corrected/intel.log.gz");
  const auto log = test::dataFile("corrected/intel.log.gz").string();
  const json j = parse(runCli({"eval", log, "--truth", log, "--estimate-from", "truth"}));
  // 910 scans: `zcat corrected/intel.log.gz | grep -c '^FLASER'`. Some times go backwards, so the
  // association must be by index to give exactly 0.
  EXPECT_EQ(j.at("matched").get<int>(), 910);
  EXPECT_EQ(j.at("association").get<std::string>(), "index");
  for (const char* k : {"ate_rmse_m", "ate_max_m", "ate_rot_rmse_deg", "rpe_trans_rmse_m", "rpe_rot_rmse_deg",
                        "rpe_per_m_trans_mean"})
    EXPECT_EQ(j.at(k).get<double>(), 0.0) << k;
  // The same log's odometry (interpolated from its ODOM lines) is not the truth. (Measured: ATE
  // 0.066 m RMSE; this log's ODOM lines stay close to the corrected poses.)
  const json o = parse(runCli({"eval", log, "--truth", log}));
  EXPECT_EQ(o.at("estimate").at("poses_from").get<std::string>(), "odometry");
  EXPECT_GT(o.at("ate_rmse_m").get<double>(), 0.01);
}

}  // namespace
}  // namespace lidar2d
