// Trajectory, relations and relative-pose files: parsing, exact round trips, format detection, and
// errors that name file, line and field.

#include <gtest/gtest.h>

#include <ostream>

#include <cmath>
#include <filesystem>
#include <numbers>
#include <string>

#include "lidar2d/core/error.hpp"
#include "lidar2d/io/trajectory.hpp"
#include "support/test_support.hpp"

namespace lidar2d::io {
namespace {

using test::TempDir;
using test::throwsError;
using test::writeFile;

constexpr double kPi = std::numbers::pi;

TEST(ReadTrajectory, PlainWithCommentsBlankLinesTabsAndCrlf) {
  TempDir tmp;
  const auto p = (tmp / "t.txt").string();
  writeFile(p, "# timestamp x y theta\n\n1.5 1 2 0.5\r\n  2.5\t\t-1   -2 -0.25  \n# end\n+3.5 1e-3 2E2 0\n");
  const Trajectory t = readTrajectory(p);
  ASSERT_EQ(t.size(), 3u);
  EXPECT_EQ(t[0].time, 1.5);
  EXPECT_TRUE(test::IsNearPose(SE2(1, 2, 0.5), t[0].pose, 1e-12, 1e-10));
  EXPECT_EQ(t[1].time, 2.5);
  EXPECT_TRUE(test::IsNearPose(SE2(-1, -2, -0.25), t[1].pose, 1e-12, 1e-10));
  EXPECT_EQ(t[2].time, 3.5);
  EXPECT_TRUE(test::IsNearPose(SE2(1e-3, 200, 0), t[2].pose, 1e-12, 1e-10));
}

TEST(ReadTrajectory, KeepsFileOrderWithRepeatedAndBackwardTimes) {
  TempDir tmp;
  writeFile(tmp / "t.txt", "5 0 0 0\n5 1 0 0\n4 2 0 0\n");
  const Trajectory t = readTrajectory((tmp / "t.txt").string());
  ASSERT_EQ(t.size(), 3u);
  EXPECT_EQ(t[0].time, 5.0);
  EXPECT_EQ(t[1].pose.x(), 1.0);
  EXPECT_EQ(t[2].time, 4.0);
}

TEST(ReadTrajectory, TumQuaternionGivesYaw) {
  TempDir tmp;
  const double th = 2.5;  // beyond pi/2 so that a wrong half-angle formula would show
  const std::string line = "10.0 1 2 0.3 0 0 " + std::to_string(std::sin(th / 2)) + " " + std::to_string(std::cos(th / 2));
  writeFile(tmp / "t.tum", line + "\n11.0 0 0 0 0 0 0 1\n12.0 0 0 0 0 0 -1 0\n");
  const Trajectory t = readTrajectory((tmp / "t.tum").string());
  ASSERT_EQ(t.size(), 3u);
  EXPECT_TRUE(test::IsNearPose(SE2(1, 2, th), t[0].pose, 1e-12, 1e-3));
  EXPECT_TRUE(test::IsNearPose(SE2(0, 0, 0), t[1].pose, 1e-12, 1e-9));
  EXPECT_TRUE(test::IsNearPose(SE2(0, 0, kPi), t[2].pose, 1e-12, 1e-9));
}

TEST(WriteTrajectory, PlainRoundTripKeepsMicrosecondTimesExactly) {
  TempDir tmp;
  const auto p = (tmp / "out.txt").string();
  Trajectory t{{1134864629.895182, SE2(1.234567891, -2.5, 3.0)},
               {976052905.167303, SE2(-1e-9, 1e4, -3.1)},
               {1216.630413, SE2(0.1, 0.2, kPi)}};
  writeTrajectory(p, t);
  const Trajectory r = readTrajectory(p);
  ASSERT_EQ(r.size(), t.size());
  for (std::size_t i = 0; i < t.size(); ++i) {
    // Times are compared as printed to microseconds: that is what the data sets carry.
    EXPECT_EQ(r[i].time, t[i].time) << "pose " << i;
    EXPECT_TRUE(test::IsNearPose(t[i].pose, r[i].pose, 1e-9, 1e-7)) << "pose " << i;
  }
  // No temporary files are left behind.
  std::size_t files = 0;
  for (const auto& e : std::filesystem::directory_iterator(tmp.path())) files += e.is_regular_file();
  EXPECT_EQ(files, 1u);
}

TEST(WriteTrajectory, TumRoundTrip) {
  TempDir tmp;
  const auto p = (tmp / "out.tum").string();
  Trajectory t{{1.0, SE2(1, 2, 0.7)}, {2.0, SE2(-3, 4, -2.9)}, {3.0, SE2(0, 0, kPi)}};
  writeTrajectory(p, t, TrajectoryFormat::kTum);
  const Trajectory r = readTrajectory(p);
  ASSERT_EQ(r.size(), t.size());
  for (std::size_t i = 0; i < t.size(); ++i) EXPECT_TRUE(test::IsNearPose(t[i].pose, r[i].pose, 1e-9, 1e-8));
}

TEST(WriteTrajectory, UnwritablePathThrowsAndLeavesNothing) {
  TempDir tmp;
  const auto p = (tmp / "missing-folder" / "out.txt").string();
  EXPECT_TRUE(throwsError([&] { writeTrajectory(p, {{1.0, SE2()}}); }, ErrorKind::kIo, {"missing-folder"}));
  EXPECT_FALSE(std::filesystem::exists(p));
}

struct BadCase {
  const char* name;
  const char* content;
  std::vector<std::string> expected;  // substrings of what()
};
// gtest prints parameters in test listings; a name instead of a byte dump keeps ctest readable.
[[maybe_unused]] void PrintTo(const BadCase&, std::ostream* os) { *os << "BadCase"; }


class MalformedTrajectory : public ::testing::TestWithParam<BadCase> {};

TEST_P(MalformedTrajectory, NamesFileLineAndField) {
  TempDir tmp;
  const auto p = (tmp / "bad.txt").string();
  writeFile(p, GetParam().content);
  try {
    readTrajectory(p);
    FAIL() << "no error";
  } catch (const Error& e) {
    EXPECT_EQ(e.kind(), ErrorKind::kBadInput);
    const std::string what = e.what();
    EXPECT_NE(what.find(p), std::string::npos) << what;
    for (const auto& s : GetParam().expected) EXPECT_NE(what.find(s), std::string::npos) << what << " lacks " << s;
  }
}

INSTANTIATE_TEST_SUITE_P(
    Cases, MalformedTrajectory,
    ::testing::Values(
        BadCase{"non_numeric", "# h\n1 0 0 0\n2 0 abc 0\n", {":3:", "field 3 (y)", "not a number: 'abc'"}},
        BadCase{"trailing_garbage", "1 0 0 0.5rad\n", {":1:", "field 4 (theta)", "'0.5rad'"}},
        BadCase{"nan", "1 0 0 0\n2 nan 0 0\n", {":2:", "field 2 (x)", "not a finite number"}},
        BadCase{"inf_time", "inf 0 0 0\n", {":1:", "field 1 (timestamp)", "not a finite number"}},
        BadCase{"out_of_range", "1 1e999 0 0\n", {":1:", "field 2 (x)", "out of range"}},
        BadCase{"five_fields", "1 0 0 0 7\n", {":1:", "found 5 fields"}},
        BadCase{"three_fields_later", "1 0 0 0\n\n2 0 0\n", {":3:", "expected 4 fields as on line 1, found 3"}},
        BadCase{"tum_then_plain", "1 0 0 0 0 0 0 1\n2 0 0 0\n", {":2:", "expected 8 fields"}},
        BadCase{"non_unit_quaternion", "1 0 0 0 0 0 0.5 0.5\n", {":1:", "qx qy qz qw", "norm 0.707107"}},
        BadCase{"empty", "", {"holds no poses"}},
        BadCase{"only_comments", "# nothing\n\n   \n", {"holds no poses"}}),
    [](const auto& info) { return std::string(info.param.name); });

TEST(ReadTrajectory, MissingFileIsAnIoError) {
  TempDir tmp;
  const auto p = (tmp / "nope.txt").string();
  EXPECT_TRUE(throwsError([&] { readTrajectory(p); }, ErrorKind::kIo, {"nope.txt", "cannot open"}));
}

TEST(ReadRelations, MultipleSpacesTabsAndHeader) {
  TempDir tmp;
  const auto p = (tmp / "x.relations").string();
  writeFile(p,
            "# t1 t2 dx dy dz droll dpitch dyaw\n"
            "1134864645.90321 1134864646.32420 0.31293 0.02935 0.00000  0.00000 0.00000 0.24198\n"
            "976052905.167303\t976052911.885496  -0.056990 -0.128430 0 0 0 -1.682210\n");
  const Relations r = readRelations(p);
  ASSERT_EQ(r.size(), 2u);
  EXPECT_EQ(r[0].t1, 1134864645.90321);
  EXPECT_EQ(r[0].t2, 1134864646.32420);
  EXPECT_TRUE(test::IsNearPose(SE2(0.31293, 0.02935, 0.24198), r[0].T_1_2, 1e-12, 1e-9));
  EXPECT_EQ(r[1].t1, 976052905.167303);
  EXPECT_TRUE(test::IsNearPose(SE2(-0.056990, -0.128430, -1.682210), r[1].T_1_2, 1e-12, 1e-9));
}

TEST(ReadRelations, Errors) {
  TempDir tmp;
  const auto p = (tmp / "bad.relations").string();
  writeFile(p, "1 2 0.1 0.2 0 0 0 0.1\n1 2 0.1 0.2 0\n");
  EXPECT_TRUE(throwsError([&] { readRelations(p); }, ErrorKind::kBadInput,
                          {p + ":2:", "expected 8 fields (t1 t2 dx dy dz droll dpitch dyaw), found 5 fields"}));
  writeFile(p, "1 2 0.1 0.2 0 0 0 x\n");
  EXPECT_TRUE(throwsError([&] { readRelations(p); }, ErrorKind::kBadInput, {p + ":1:", "field 8 (dyaw)", "'x'"}));
  writeFile(p, "1 2 0.1 0.2 0 0 0 -nan\n");
  EXPECT_TRUE(throwsError([&] { readRelations(p); }, ErrorKind::kBadInput, {p + ":1:", "field 8 (dyaw)", "finite"}));
  writeFile(p, "# header only\n");
  EXPECT_TRUE(throwsError([&] { readRelations(p); }, ErrorKind::kBadInput, {p, "holds no relations"}));
}

TEST(ReadRelations, IntelFileHasEveryLine) {
  LIDAR2D_REQUIRE_DATA("raw/intel.relations");
  // 2984: `awk 'NF==8 && $1 !~ /^#/ {n++} END {print n}' raw/intel.relations` (and wc -l: 2984).
  const Relations r = readRelations(test::dataFile("raw/intel.relations").string());
  ASSERT_EQ(r.size(), 2984u);
  // First line: 976052905.167303 976052911.885496 -0.056990 -0.128430 0.000000 0.000000 0.000000 -1.682210
  EXPECT_EQ(r[0].t1, 976052905.167303);
  EXPECT_TRUE(test::IsNearPose(SE2(-0.056990, -0.128430, -1.682210), r[0].T_1_2, 1e-12, 1e-9));
}

TEST(ReadRelations, EveryRelationsFileOfTheSharedData) {
  // Counts: `grep -vc '^#' FILE`; first and last data lines: `grep -v '^#' FILE | head -1`, `tail -1 FILE`.
  struct Expect {
    const char* file;
    std::size_t count;
    double t1_first, t2_first, dx_first, dy_first, dyaw_first;
    double t1_last, t2_last, dx_last, dy_last, dyaw_last;
  };
  const Expect files[] = {
      {"raw/fr079.relations", 1685, 1216.630413, 1217.490267, 0.407950, -0.016330, -0.069620, 2085.180238, 2249.930901,
       0.743610, 0.263510, 3.119120},
      {"raw/mit-csail.relations", 1172, 1134864645.90321, 1134864646.32420, 0.31293, 0.02935, 0.24198, 1134864686.65618,
       1134865034.47520, 0.69012, 0.56141, -0.57907},
      {"raw/intel.relations", 2984, 976052905.167303, 976052911.885496, -0.056990, -0.128430, -1.682210, 976054744.377487,
       976055538.433137, 0.881540, 0.001790, 0.075760},
  };
  for (const Expect& e : files) {
    if (!std::filesystem::exists(test::dataFile(e.file))) GTEST_SKIP() << test::dataFile(e.file) << " is missing";
    const Relations r = readRelations(test::dataFile(e.file).string());
    ASSERT_EQ(r.size(), e.count) << e.file;
    EXPECT_EQ(r.front().t1, e.t1_first) << e.file;
    EXPECT_EQ(r.front().t2, e.t2_first) << e.file;
    EXPECT_TRUE(test::IsNearPose(SE2(e.dx_first, e.dy_first, e.dyaw_first), r.front().T_1_2, 1e-12, 1e-9)) << e.file;
    EXPECT_EQ(r.back().t1, e.t1_last) << e.file;
    EXPECT_EQ(r.back().t2, e.t2_last) << e.file;
    EXPECT_TRUE(test::IsNearPose(SE2(e.dx_last, e.dy_last, e.dyaw_last), r.back().T_1_2, 1e-12, 1e-9)) << e.file;
  }
}

TEST(ReadRelativePoses, SevenAndFiveFields) {
  TempDir tmp;
  const auto p = (tmp / "pairs.txt").string();
  writeFile(p, "# t_prev t_cur dx dy dtheta converged iterations\n1.0 1.1 0.5 -0.1 0.02 1 12\n1.1 1.2 0 0 0 0 50\n");
  const auto r = readRelativePoses(p);
  ASSERT_EQ(r.size(), 2u);
  EXPECT_EQ(r[0].t_prev, 1.0);
  EXPECT_EQ(r[0].t_cur, 1.1);
  EXPECT_TRUE(test::IsNearPose(SE2(0.5, -0.1, 0.02), r[0].T_prev_cur, 1e-12, 1e-9));
  EXPECT_TRUE(r[0].converged);
  EXPECT_EQ(r[0].iterations, 12);
  EXPECT_FALSE(r[1].converged);
  EXPECT_EQ(r[1].iterations, 50);

  writeFile(p, "1.0 1.1 0.5 -0.1 0.02\n");
  const auto r5 = readRelativePoses(p);
  ASSERT_EQ(r5.size(), 1u);
  EXPECT_TRUE(r5[0].converged);
}

TEST(ReadRelativePoses, Errors) {
  TempDir tmp;
  const auto p = (tmp / "pairs.txt").string();
  writeFile(p, "1.0 1.1 0.5 -0.1 0.02 2 12\n");
  EXPECT_TRUE(throwsError([&] { readRelativePoses(p); }, ErrorKind::kBadInput, {p + ":1:", "field 6 (converged)"}));
  writeFile(p, "1.0 1.1 0.5 -0.1 0.02 1 -3\n");
  EXPECT_TRUE(throwsError([&] { readRelativePoses(p); }, ErrorKind::kBadInput, {p + ":1:", "field 7 (iterations)"}));
  writeFile(p, "1.0 1.1 0.5 -0.1 0.02 1 2.5\n");
  EXPECT_TRUE(throwsError([&] { readRelativePoses(p); }, ErrorKind::kBadInput, {p + ":1:", "field 7 (iterations)"}));
  writeFile(p, "1.0 1.1 0.5 -0.1 0.02 1 2\n1.1 1.2 0 0 0\n");
  EXPECT_TRUE(throwsError([&] { readRelativePoses(p); }, ErrorKind::kBadInput, {p + ":2:", "expected 7 fields"}));
  writeFile(p, "1.0 1.1 0.5 -0.1\n");
  EXPECT_TRUE(throwsError([&] { readRelativePoses(p); }, ErrorKind::kBadInput, {p + ":1:", "found 4 fields"}));
}

TEST(DetectPoseFile, TellsTrajectoriesRelationsAndLogsApart) {
  TempDir tmp;
  writeFile(tmp / "plain.txt", "# c\n1 0 0 0\n");
  writeFile(tmp / "tum.txt", "1 0 0 0 0 0 0 1\n2 1 0 0 0 0 0.0998334 0.9950042\n");
  writeFile(tmp / "rel.txt", "1 2 0.1 0.2 0 0 0 0.3\n");
  writeFile(tmp / "named.relations", "garbage\n");  // the extension decides; the reader reports content
  writeFile(tmp / "carmen.log", "# CARMEN\nPARAM robot_name x\nFLASER 0 0 0 0 0 0 0 1 h 1\n");
  writeFile(tmp / "empty.txt", "");
  writeFile(tmp / "word.txt", "abc 0 0 0\n");
  test::writeGzip(tmp / "log.gz", "1 0 0 0\n");
  writeFile(tmp / "bag.bag", "#ROSBAG V2.0\n....");
  EXPECT_EQ(detectPoseFile((tmp / "plain.txt").string()), PoseFileKind::kTrajectory);
  EXPECT_EQ(detectPoseFile((tmp / "tum.txt").string()), PoseFileKind::kTrajectory);
  EXPECT_EQ(detectPoseFile((tmp / "rel.txt").string()), PoseFileKind::kRelations);
  EXPECT_EQ(detectPoseFile((tmp / "named.relations").string()), PoseFileKind::kRelations);
  EXPECT_EQ(detectPoseFile((tmp / "carmen.log").string()), PoseFileKind::kLog);
  EXPECT_EQ(detectPoseFile((tmp / "empty.txt").string()), PoseFileKind::kTrajectory);
  EXPECT_EQ(detectPoseFile((tmp / "word.txt").string()), PoseFileKind::kTrajectory);
  EXPECT_EQ(detectPoseFile((tmp / "log.gz").string()), PoseFileKind::kLog);
  EXPECT_EQ(detectPoseFile((tmp / "bag.bag").string()), PoseFileKind::kLog);
  EXPECT_EQ(detectPoseFile(tmp.path().string()), PoseFileKind::kLog);
  EXPECT_TRUE(throwsError([&] { detectPoseFile((tmp / "nope").string()); }, ErrorKind::kIo, {"no such file"}));
}

}  // namespace
}  // namespace lidar2d::io
