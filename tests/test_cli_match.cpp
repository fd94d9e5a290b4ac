// `lidar2d match` end to end: simulated logs matched and evaluated, the output read back with
// io::readRelativePoses, the real intel log, and bad input / usage errors through the CLI.

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

#include "lidar2d/io/trajectory.hpp"
#include "support/test_support.hpp"

namespace lidar2d {
namespace {

namespace fs = std::filesystem;
using test::runCli;
using test::TempDir;

// Value printed after `key` on its own line of `out` (e.g. "success rate: 98.5% ..." -> 98.5).
double valueAfter(const std::string& out, const std::string& key) {
  const auto pos = out.find(key);
  if (pos == std::string::npos) return std::nan("");
  return std::stod(out.substr(pos + key.size()));
}

// The first line of a file (a match output's header).
std::string headerOf(const std::string& path) {
  std::ifstream in(path);
  std::string header;
  std::getline(in, header);
  return header;
}

// How many of the 909 intel pairs of two match outputs differ (by more than 1e-6 m or rad).
void countDifferingIntelPairs(const std::string& path_a, const std::string& path_b, std::size_t* differ) {
  const auto a = io::readRelativePoses(path_a), b = io::readRelativePoses(path_b);
  ASSERT_EQ(a.size(), 909u);
  ASSERT_EQ(b.size(), a.size());
  *differ = 0;
  for (std::size_t i = 0; i < a.size(); ++i) *differ += !test::IsNearPose(a[i].T_prev_cur, b[i].T_prev_cur, 1e-6, 1e-6);
}

// A CARMEN log of `n` FLASER scans of a 4 x 4 m square room seen from its centre, without truth
// (no ODOM lines: the laser messages' poses are odometry).
std::string roomLog(int n) {
  std::ostringstream s;
  for (int k = 0; k < n; ++k) {
    s << "FLASER 180";
    for (int i = 0; i < 180; ++i) {
      const double a = (-90.0 + i) * 3.14159265358979 / 180.0;
      s << " " << std::min(2.0 / std::max(std::abs(std::cos(a)), 1e-9), 2.0 / std::max(std::abs(std::sin(a)), 1e-9));
    }
    s << " 0 0 0 0 0 0 " << 1.0 + 0.1 * k << " host " << 1.0 + 0.1 * k << "\n";
  }
  return s.str();
}

TEST(CliMatch, SimulatedOfficeMatchesAndEvaluates) {
  TempDir tmp;
  const std::string log = (tmp / "sim.log").string();
  auto r = runCli({"simulate", "--world", "office", "-o", log, "--scans", "40", "--beams", "181", "--seed", "3"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  for (const std::string method : {"p2p", "p2l"})
    for (const std::string solver : {"gn", "ceres"}) {
      const std::string out = (tmp / (method + solver + ".txt")).string();
      r = runCli({"match", log, "--method", method, "--solver", solver, "-o", out, "--eval"});
      ASSERT_EQ(r.exit_code, 0) << r.err;
      const auto pairs = io::readRelativePoses(out);
      ASSERT_EQ(pairs.size(), 39u);
      EXPECT_LT(pairs[0].t_prev, pairs[0].t_cur);
      EXPECT_EQ(pairs[1].t_prev, pairs[0].t_cur);
      EXPECT_EQ(valueAfter(r.out, "pairs: "), 39.0) << r.out;
      // Simulated scans with 1 cm range noise and odometry from the default noise model.
      EXPECT_GE(valueAfter(r.out, "success rate: "), 95.0) << method << "/" << solver << "\n" << r.out;
      EXPECT_LT(valueAfter(r.out, "median translation error: "), 2.0) << r.out;  // [cm]
      EXPECT_NE(r.out.find("ms per pair: "), std::string::npos) << r.out;
    }
}

TEST(CliMatch, IdentityInitAndOdometryInitBothWork) {
  TempDir tmp;
  const std::string log = (tmp / "sim.log").string();
  ASSERT_EQ(runCli({"simulate", "--world", "office", "-o", log, "--scans", "20", "--beams", "181"}).exit_code, 0);
  const std::string out = (tmp / "m.txt").string();
  const auto r = runCli({"match", log, "--init", "identity", "-o", out, "-q"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(r.err.empty()) << r.err;  // -q
  EXPECT_EQ(io::readRelativePoses(out).size(), 19u);
}

// Pairs are matched in chunks of frames on several threads; the output must not depend on how many
// (300 scans cross two chunk borders).
TEST(CliMatch, ThreadCountDoesNotChangeTheOutput) {
  TempDir tmp;
  const std::string log = (tmp / "sim.log").string();
  ASSERT_EQ(runCli({"simulate", "--world", "office", "-o", log, "--scans", "300", "--beams", "181"}).exit_code, 0);
  std::string first;
  for (const char* threads : {"1", "2", "3"}) {
    const std::string out = (tmp / (std::string("m") + threads + ".txt")).string();
    const auto r = runCli({"match", log, "--threads", threads, "-o", out, "-q"});
    ASSERT_EQ(r.exit_code, 0) << r.err;
    const std::string content = test::readFile(out);
    const auto pairs = io::readRelativePoses(out);
    ASSERT_EQ(pairs.size(), 299u);
    for (std::size_t k = 1; k < pairs.size(); ++k) {  // consecutive scans, also across chunk borders
      EXPECT_EQ(pairs[k].t_prev, pairs[k - 1].t_cur) << k;
      EXPECT_LT(pairs[k].T_prev_cur.translation().norm(), 0.5) << k;  // the route moves a few cm per scan
    }
    if (first.empty())
      first = content;
    else
      EXPECT_EQ(content, first) << threads << " threads";
  }
}

// Correlative search (default window 1 m, 30 degrees) then point-to-line ICP, from no guess at all.
TEST(CliMatch, CorrelativeThenIcpFromIdentity) {
  TempDir tmp;
  const std::string log = (tmp / "sim.log").string();
  const auto sim =
      runCli({"simulate", "--world", "office", "-o", log, "--scans", "20", "--beams", "181", "--seed", "3"});
  ASSERT_EQ(sim.exit_code, 0) << sim.err;
  const std::string out = (tmp / "m.txt").string();
  const auto r = runCli({"match", log, "--method", "corr", "--then", "p2l", "--init", "identity", "-o", out, "--eval"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(valueAfter(r.out, "pairs: "), 19.0) << r.out;
  EXPECT_GE(valueAfter(r.out, "success rate: "), 95.0) << r.out;
  EXPECT_LT(valueAfter(r.out, "median translation error: "), 2.0) << r.out;  // [cm]
  const std::string header = headerOf(out);
  EXPECT_NE(header.find("method=corr then p2l"), std::string::npos) << header;
}

TEST(CliMatch, PointPairsOptionMatchesAndIsRecorded) {
  TempDir tmp;
  const std::string log = (tmp / "sim.log").string();
  ASSERT_EQ(runCli({"simulate", "--world", "office", "-o", log, "--scans", "20", "--beams", "181", "--seed", "3"}).exit_code, 0);
  const std::string out = (tmp / "m.txt").string();
  const auto r = runCli({"match", log, "--method", "p2l", "--point-pairs", "0.5", "-o", out, "--eval"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_GE(valueAfter(r.out, "success rate: "), 95.0) << r.out;
  const std::string header = headerOf(out);
  EXPECT_NE(header.find("point_pairs=0.5"), std::string::npos) << header;
}

// --no-two-point-lines (IcpOptions::two_point_lines) is recorded in the header and changes the
// matches: point-to-line then drops the pairs of the target points that fit no line.
TEST(CliMatch, NoTwoPointLinesIsRecordedAndChangesTheMatches) {
  LIDAR2D_REQUIRE_DATA("corrected/intel.log.gz");
  TempDir tmp;
  const std::string log = test::dataFile("corrected/intel.log.gz").string();
  const std::string with = (tmp / "with.txt").string(), without = (tmp / "without.txt").string();
  ASSERT_EQ(runCli({"match", log, "-o", with}).exit_code, 0);
  const auto r = runCli({"match", log, "--no-two-point-lines", "-o", without});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const std::string header = headerOf(without);
  EXPECT_NE(header.find("two_point_lines=0"), std::string::npos) << header;
  std::size_t differ = 0;
  ASSERT_NO_FATAL_FAILURE(countDifferingIntelPairs(with, without, &differ));
  EXPECT_GT(differ, 100u);
}

// --source-spacing (IcpOptions::min_source_spacing_m) is recorded in the header when it is not the
// default, changes the matches (0 keeps every point), and out of its domain is one clear error.
TEST(CliMatch, SourceSpacingIsRecordedAndChangesTheMatches) {
  LIDAR2D_REQUIRE_DATA("corrected/intel.log.gz");
  TempDir tmp;
  const std::string log = test::dataFile("corrected/intel.log.gz").string();
  const std::string thinned = (tmp / "thinned.txt").string(), all = (tmp / "all.txt").string();
  ASSERT_EQ(runCli({"match", log, "-o", thinned}).exit_code, 0);
  auto r = runCli({"match", log, "--source-spacing", "0", "-o", all});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const std::string header_thinned = headerOf(thinned), header_all = headerOf(all);
  EXPECT_EQ(header_thinned.find("source_spacing"), std::string::npos) << header_thinned;
  EXPECT_NE(header_all.find("source_spacing=0"), std::string::npos) << header_all;
  std::size_t differ = 0;
  ASSERT_NO_FATAL_FAILURE(countDifferingIntelPairs(thinned, all, &differ));
  EXPECT_GT(differ, 100u);
  const std::string bad = (tmp / "bad.txt").string();
  r = runCli({"match", log, "--source-spacing", "-0.1", "-o", bad});
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("min_source_spacing_m"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(bad));
}

TEST(CliMatch, IntelLogWithItsRawOdometry) {
  LIDAR2D_REQUIRE_DATA("corrected/intel.log.gz");
  TempDir tmp;
  const std::string out = (tmp / "intel.txt").string();
  const auto r = runCli({"match", test::dataFile("corrected/intel.log.gz").string(), "-o", out, "--eval"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  // 910 FLASER scans (zcat intel.log.gz | grep -c ^FLASER) -> 909 pairs.
  EXPECT_EQ(io::readRelativePoses(out).size(), 909u);
  // Measured 96.7% with p2l/gn from the raw odometry; the canonical scan matcher gets 95.7% from a
  // perturbed guess (issue 4).
  EXPECT_GE(valueAfter(r.out, "success rate: "), 90.0) << r.out;
}

TEST(CliMatch, BadInputExitsOneWithoutOutput) {
  TempDir tmp;
  const std::string out = (tmp / "out.txt").string();
  // Missing log.
  auto r = runCli({"match", (tmp / "missing.log").string(), "-o", out});
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("lidar2d: error:"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(out));
  // --eval on a log without truth.
  const std::string notruth = (tmp / "room.log").string();
  test::writeFile(notruth, roomLog(5));
  r = runCli({"match", notruth, "-o", out, "--eval"});
  EXPECT_EQ(r.exit_code, 1) << r.err;
  EXPECT_NE(r.err.find("truth"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(out));
  // Without --eval the same log matches (identical scans: identity).
  r = runCli({"match", notruth, "-o", out});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto pairs = io::readRelativePoses(out);
  ASSERT_EQ(pairs.size(), 4u);
  EXPECT_TRUE(test::IsNearPose(SE2(), pairs[0].T_prev_cur, 1e-6, 1e-4));
  fs::remove(out);
  // A single scan.
  test::writeFile(notruth, roomLog(1));
  r = runCli({"match", notruth, "-o", out});
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("at least 2"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(out));
  // An out-of-domain matcher option.
  test::writeFile(notruth, roomLog(3));
  r = runCli({"match", notruth, "--point-pairs", "-1", "-o", out});
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("point_pair_weight"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(out));
  // A non-finite number is a usage error of every floating-point option (exit 2).
  for (const char* opt : {"--point-pairs", "--max-dist"}) {
    r = runCli({"match", notruth, opt, "nan", "-o", out});
    EXPECT_EQ(r.exit_code, 2) << opt;
    EXPECT_NE(r.err.find(std::string(opt) + ": must be a finite number"), std::string::npos) << r.err;
    EXPECT_FALSE(fs::exists(out));
  }
  // Unwritable output.
  r = runCli({"match", notruth, "-o", notruth + "/x.txt"});  // a folder under a regular file
  EXPECT_EQ(r.exit_code, 1);
}

TEST(CliMatch, UsageErrorsExitTwo) {
  TempDir tmp;
  const std::string log = (tmp / "room.log").string();
  test::writeFile(log, roomLog(3));
  const std::string out = (tmp / "out.txt").string();
  EXPECT_EQ(runCli({"match", log, "--method", "icp", "-o", out}).exit_code, 2);
  EXPECT_EQ(runCli({"match", log, "--solver", "lm", "-o", out}).exit_code, 2);
  EXPECT_EQ(runCli({"match", log, "--init", "truth", "-o", out}).exit_code, 2);
  // --then takes an ICP method only.
  EXPECT_EQ(runCli({"match", log, "--method", "corr", "--then", "lf", "-o", out}).exit_code, 2);
  EXPECT_EQ(runCli({"match", log}).exit_code, 2);  // no -o
  EXPECT_FALSE(fs::exists(out));
}

}  // namespace
}  // namespace lidar2d
