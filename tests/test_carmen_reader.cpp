// CARMEN reader: the real Radish / MIT logs of ../shared/data, and small synthetic logs for each
// message type and rule (beam angles, PARAM overrides, mounting, ODOM interpolation, TRUEPOS,
// the automatic pose decision, repeated times).

#include <gtest/gtest.h>

#include <ostream>

#include <cctype>
#include <cmath>
#include <limits>
#include <numbers>
#include <string>
#include <vector>

#include "lidar2d/core/error.hpp"
#include "lidar2d/io/frame_source.hpp"
#include "src/io/internal/readers.hpp"
#include "support/test_support.hpp"

namespace lidar2d::test {
namespace {

using io::CarmenPoses;
using io::ReaderOptions;

constexpr double kDeg = std::numbers::pi / 180.0;

std::vector<Frame> readAll(const std::string& path, const ReaderOptions& options = {}) {
  auto src = io::openLog(path, options);
  std::vector<Frame> frames;
  while (auto f = src->next()) frames.push_back(std::move(*f));
  return frames;
}

struct ReadResult {
  std::vector<Frame> frames;
  io::SourceNotes notes;
};

ReadResult readWithNotes(const std::string& path, const ReaderOptions& options = {}) {
  auto src = io::openLog(path, options);
  ReadResult r;
  while (auto f = src->next()) r.frames.push_back(std::move(*f));
  r.notes = src->notes();
  return r;
}

bool hasWarning(const io::SourceNotes& n, const std::string& text) {
  for (const auto& w : n.warnings)
    if (w.find(text) != std::string::npos) return true;
  return false;
}

// ---------------------------------------------------------------------------------------------
// Real logs. Expected values come from zcat/awk (commands in the comments), never from the reader.

struct ScanSample {
  std::size_t index;
  double r0, r1, r10, r_last;  // ranges of beams 0, 1, 10 and the last beam [m]
  double x, y, theta;          // laser-message pose (truth for corrected logs, odometry for mit-csail)
};
struct OdomSampleExpect {
  std::size_t index;
  double x, y, theta;  // ODOM interpolated at the scan time, by the rule, computed with awk
};
struct RealLog {
  const char* file;
  std::size_t scans, beams;
  double first_t, last_t;
  double angle_min_deg, increment_deg, range_max;
  double mount_x;
  std::size_t valid_beams;  // beams with 0 < r < range_max over the whole log
  bool corrected;
  std::vector<ScanSample> samples;
  std::vector<OdomSampleExpect> odom;
  const char* warning;  // expected SourceNotes warning, or "" for none about time
};
// gtest prints parameters in test listings; a name instead of a byte dump keeps ctest readable.
[[maybe_unused]] void PrintTo(const RealLog&, std::ostream* os) { *os << "RealLog"; }


// Counts, first/last time:
//   zcat F | awk '$1=="FLASER"{n=$2; t=$(n+9); if(c>0){if(t==p)r++; if(t<p)b++};
//                if(c==0)first=$(n+9); c++; p=t; last=t} END{print c, first, last, r+0, b+0}'
// Samples:  zcat F | awk '$1=="FLASER"{n=$2; k=c++; if(k==0||k==500)
//                print k, $3, $4, $13, $(n+2), $(n+3), $(n+4), $(n+5), $(n+9)}'   (and END for the last)
// Valid beams: total beams minus those >= range_max (no range is <= 0 in these logs):
//   zcat F | awk '$1=="FLASER"{n=$2; for(i=3;i<n+3;i++){if($i+0>=80)big++; t++}} END{print t-big}'
// ODOM at the scan time: /tmp awk script applying the same rule (previous ODOM line in file order
// and the next one; bracket -> interpolate, else the closer in time, ties -> previous). In these
// corrected logs an ODOM line with the scan's own timestamp always precedes the FLASER line.
const std::vector<RealLog>& realLogs() {
  static const std::vector<RealLog> logs = {
      {"corrected/intel.log.gz", 910, 180, 32.9068, 2683.77, -90.0, 1.0, 80.0, 0.0, 163800 - 4172, true,
       {{0, 1.09, 1.08, 1.03, 1.23, 0.600266, -0.0320327, -0.354665},
        {500, 3.03, 2.99, 2.74, 1.79, -4.19744, -19.0478, 2.56368},
        {909, 1.01, std::nan(""), std::nan(""), 1.11, -0.596494, -0.101202, 0.0119294}},
       {{0, 0.698035, -0.0132843, -0.460915}, {500, -4.17059, -19.0073, 2.54337}},
       "timestamps repeat 0 times; go backwards 4 times"},
      // PARAM robot_frontlaser_offset -0.04, PARAM robot_front_laser_max 80.99,
      // PARAM laser_front_laser_resolution 0.5 (zcat F | grep PARAM | grep laser).
      {"corrected/freiburg-079.log.gz", 4791, 360, 0.227623, 1061.5, -90.0, 0.5, 80.99, -0.04, 1724760 - 36004, true,
       {{0, 1.65, 1.66, 6.96, 1.0, 0.00123601, -0.00106807, 2.85e-05},
        {500, 2.99, 2.99, 1.52, 0.99, -23.1519, 1.87813, -0.220839},
        {4790, 6.5, std::nan(""), std::nan(""), 4.25, 0.0319692, -0.94701, -1.8314}},
       {{0, 0.000485382, 6.20016e-05, -0.001534}, {500, -23.1503, 1.93928, -0.213026}},
       ""},
      {"corrected/infinite-corridor.log.gz", 1941, 180, -0.445999, 4.29497e+09, -90.0, 1.0, 80.0, 0.0, 349380, true,
       {{0, 1.33, 1.38, 1.02, 1.23, 1.00824, -0.0167813, 0.00595701},
        {500, 1.24, 1.29, 1.29, 1.42, -75.248, -35.3595, 1.46392},
        {1940, 4.76, std::nan(""), std::nan(""), 4.31, -1.71147, 2.5674, 0.628658}},
       {{0, 1.02945, -0.007331, -0.003418}, {500, -75.2638, -35.3925, 1.46439}},
       "timestamps repeat 1936 times; go backwards 3 times"},
      {"raw/mit-csail.clf.gz", 1988, 361, 1134864629.895182, 1134865053.892206, -90.0, 0.5, 80.0, 0.0,
       717668 - 23711, false,
       {{0, 1.40, 1.39, 1.34, 2.70, 576.536523, 0.106594, -2.255213},
        {500, 0.96, 0.96, 0.98, 0.74, 563.200786, -2.238200, -0.594184},
        {1987, 3.98, std::nan(""), std::nan(""), 2.21, 597.816512, -3.220376, -1.412351}},
       {},
       ""},
  };
  return logs;
}

class RealLogTest : public ::testing::TestWithParam<RealLog> {};

TEST_P(RealLogTest, MatchesAwk) {
  const RealLog& e = GetParam();
  LIDAR2D_REQUIRE_DATA(e.file);
  const std::string path = dataFile(e.file).string();
  auto src = io::openLog(path);
  EXPECT_EQ(src->format(), io::LogFormat::kCarmen);
  std::size_t n = 0, valid = 0;
  double first_t = 0, last_t = 0;
  std::size_t next_sample = 0, next_odom = 0;
  while (auto f = src->next()) {
    ASSERT_EQ(f->index, n);
    if (n == 0) first_t = f->time;
    last_t = f->time;
    EXPECT_EQ(f->scan.time(), f->time);
    ASSERT_EQ(f->scan.size(), e.beams) << "scan " << n;
    valid += f->scan.numValid();
    EXPECT_NEAR(f->scan.angleMin(), e.angle_min_deg * kDeg, 1e-12);
    EXPECT_NEAR(f->scan.angleIncrement(), e.increment_deg * kDeg, 1e-12);
    EXPECT_DOUBLE_EQ(f->scan.rangeMax(), e.range_max);
    EXPECT_DOUBLE_EQ(f->scan.rangeMin(), 0.0);
    EXPECT_TRUE(IsNearPose(SE2(e.mount_x, 0, 0), f->T_robot_laser, 1e-12, 1e-9));
    ASSERT_TRUE(f->T_odom_robot.has_value()) << "scan " << n;
    EXPECT_EQ(f->T_world_robot.has_value(), e.corrected) << "scan " << n;
    if (next_sample < e.samples.size() && e.samples[next_sample].index == n) {
      const ScanSample& s = e.samples[next_sample++];
      const auto& r = f->scan.ranges();
      EXPECT_DOUBLE_EQ(r[0], s.r0) << "scan " << n;
      if (!std::isnan(s.r1)) {
        EXPECT_DOUBLE_EQ(r[1], s.r1) << "scan " << n;
      }
      if (!std::isnan(s.r10)) {
        EXPECT_DOUBLE_EQ(r[10], s.r10) << "scan " << n;
      }
      EXPECT_DOUBLE_EQ(r.back(), s.r_last) << "scan " << n;
      // The file's first pose triple is the laser's: the truth is the robot's pose under it.
      const SE2 expected(s.x, s.y, s.theta);
      const SE2 got = e.corrected ? *f->T_world_robot * f->T_robot_laser : *f->T_odom_robot;
      EXPECT_TRUE(IsNearPose(expected, got, 1e-9, 1e-7)) << "scan " << n;
    }
    if (next_odom < e.odom.size() && e.odom[next_odom].index == n) {
      const OdomSampleExpect& o = e.odom[next_odom++];
      EXPECT_TRUE(IsNearPose(SE2(o.x, o.y, o.theta), *f->T_odom_robot, 1e-9, 1e-7)) << "scan " << n;
    }
    ++n;
  }
  EXPECT_EQ(n, e.scans);
  EXPECT_EQ(next_sample, e.samples.size());
  EXPECT_EQ(next_odom, e.odom.size());
  EXPECT_EQ(valid, e.valid_beams);
  EXPECT_DOUBLE_EQ(first_t, e.first_t);
  EXPECT_DOUBLE_EQ(last_t, e.last_t);
  const io::SourceNotes notes = src->notes();
  EXPECT_EQ(notes.scan_source, "FLASER");
  if (e.corrected) {
    // Auto decision: FLASER poses disagree with the ODOM lines (corrected by SLAM) -> truth.
    EXPECT_EQ(notes.truth_source.rfind("FLASER pose less the laser mounting (corrected log", 0), 0u)
        << notes.truth_source;
    EXPECT_EQ(notes.odom_source, "ODOM lines (interpolated)");
  } else {
    EXPECT_EQ(notes.odom_source, "FLASER odometry fields (no ODOM lines)");
    EXPECT_EQ(notes.truth_source, "");
  }
  if (*e.warning) {
    EXPECT_TRUE(hasWarning(notes, e.warning)) << e.warning;
  } else {
    EXPECT_FALSE(hasWarning(notes, "timestamps repeat"));
  }
}

INSTANTIATE_TEST_SUITE_P(Data, RealLogTest, ::testing::ValuesIn(realLogs()),
                         [](const auto& info) {
                           std::string s = info.param.file;
                           for (char& c : s)
                             if (!std::isalnum(static_cast<unsigned char>(c))) c = '_';
                           return s;
                         });

TEST(CarmenReaderData, MitCsailNoReturnIsInvalid) {
  LIDAR2D_REQUIRE_DATA("raw/mit-csail.clf.gz");
  // zcat raw/mit-csail.clf.gz | awk '$1=="FLASER"{k++; n=$2; for(i=3;i<n+3;i++) if($i=="81.91")
  //   {print k-1, i-3; exit}}'  -> scan 0 has no 81.91; first one found is reported below.
  auto src = io::openLog(dataFile("raw/mit-csail.clf.gz").string());
  bool found = false;
  while (auto f = src->next()) {
    for (std::size_t i = 0; i < f->scan.size(); ++i)
      if (f->scan.ranges()[i] == 81.91) {
        EXPECT_FALSE(f->scan.isValid(i));
        found = true;
      } else {
        EXPECT_TRUE(f->scan.isValid(i)) << f->scan.ranges()[i];
      }
    if (found) break;
  }
  EXPECT_TRUE(found);
}

TEST(CarmenReaderData, ForcedPoseModesOnCorrectedLog) {
  LIDAR2D_REQUIRE_DATA("corrected/intel.log.gz");
  const std::string path = dataFile("corrected/intel.log.gz").string();
  ReaderOptions o;
  o.carmen_poses = CarmenPoses::kOdometry;
  auto r = readWithNotes(path, o);
  ASSERT_EQ(r.frames.size(), 910u);
  EXPECT_FALSE(r.frames[0].T_world_robot);
  // The FLASER odometry triple of scan 0 (awk above): 0.600266 -0.0320327 -0.354665.
  EXPECT_TRUE(IsNearPose(SE2(0.600266, -0.0320327, -0.354665), *r.frames[0].T_odom_robot, 1e-9, 1e-7));
  o.carmen_poses = CarmenPoses::kTruth;
  r = readWithNotes(path, o);
  EXPECT_TRUE(IsNearPose(SE2(0.600266, -0.0320327, -0.354665), *r.frames[0].T_world_robot, 1e-9, 1e-7));
  EXPECT_TRUE(IsNearPose(SE2(0.698035, -0.0132843, -0.460915), *r.frames[0].T_odom_robot, 1e-9, 1e-7));
  EXPECT_NE(r.notes.truth_source.find("--carmen-poses truth"), std::string::npos);
}

// ---------------------------------------------------------------------------------------------
// Synthetic logs.

std::string ranges(std::size_t n, double r = 2.0) {
  std::string s;
  for (std::size_t i = 0; i < n; ++i) s.append(" ").append(std::to_string(r));
  return s;
}

std::string flaser(std::size_t n, double t, double x = 0, double y = 0, double th = 0, double ox = 0, double oy = 0,
                   double oth = 0, const char* tag = "FLASER") {
  return std::string(tag) + " " + std::to_string(n) + ranges(n) + " " + std::to_string(x) + " " + std::to_string(y) +
         " " + std::to_string(th) + " " + std::to_string(ox) + " " + std::to_string(oy) + " " + std::to_string(oth) +
         " " + std::to_string(t) + " host " + std::to_string(t) + "\n";
}

std::string odom(double t, double x, double y, double th) {
  return "ODOM " + std::to_string(x) + " " + std::to_string(y) + " " + std::to_string(th) + " 0 0 0 " +
         std::to_string(t) + " host " + std::to_string(t) + "\n";
}

std::string rawlaser(double t, std::size_t n = 4) {
  return "RAWLASER1 0 -1.5 3.0 0.75 30 0.01 0 " + std::to_string(n) + ranges(n, 3.0) + " 0 " + std::to_string(t) +
         " host " + std::to_string(t) + "\n";
}

class CarmenSynthetic : public ::testing::Test {
 protected:
  std::string write(const std::string& content, const std::string& name = "log.log") {
    const auto p = dir_ / name;
    writeFile(p, content);
    return p.string();
  }
  TempDir dir_;
};

TEST_F(CarmenSynthetic, DefaultBeamAnglesFollowTheSickModes) {
  struct Case {
    std::size_t n;
    double min_deg, inc_deg, max_deg;
  };
  for (const Case c : {Case{180, -90, 1, 89}, Case{181, -90, 1, 90}, Case{360, -90, 0.5, 89.5},
                       Case{361, -90, 0.5, 90}, Case{5, -90, 45, 90}, Case{4, -90, 45, 45}}) {
    const auto frames = readAll(write(flaser(c.n, 1.0)));
    ASSERT_EQ(frames.size(), 1u);
    const LaserScan& s = frames[0].scan;
    EXPECT_EQ(s.size(), c.n);
    EXPECT_NEAR(s.angleMin(), c.min_deg * kDeg, 1e-12) << c.n;
    EXPECT_NEAR(s.angleIncrement(), c.inc_deg * kDeg, 1e-12) << c.n;
    EXPECT_NEAR(s.angleMax(), c.max_deg * kDeg, 1e-9) << c.n;
    EXPECT_DOUBLE_EQ(s.rangeMax(), 80.0);
  }
}

TEST_F(CarmenSynthetic, ParamsOverrideAnglesRangeAndMounting) {
  const std::string log =
      "# comment\n\n"
      "PARAM laser_front_laser_resolution 0.5 0 host 0\n"
      "PARAM robot_frontlaser_offset 0.25 0 host 0\n"
      "PARAM robot_frontlaser_side_offset -0.1 0 host 0\n"
      "PARAM robot_front_laser_max 50 0 host 0\n"
      "PARAM laser_rear_laser_fov 100\n"
      "PARAM robot_rearlaser_offset -0.3\n"
      "PARAM some_other_param on 0 host 0\n"
      "NEFF 10\n" +
      flaser(180, 1.0) + flaser(101, 1.0, 0, 0, 0, 0, 0, 0, "RLASER");
  const std::string path = write(log);
  auto r = readWithNotes(path);
  ASSERT_EQ(r.frames.size(), 1u);  // the first laser type found (FLASER) is read
  const LaserScan& s = r.frames[0].scan;
  EXPECT_NEAR(s.angleIncrement(), 0.5 * kDeg, 1e-12);
  EXPECT_NEAR(s.angleMin(), -45.0 * kDeg, 1e-12);  // 180 beams x 0.5 deg centred on x
  EXPECT_DOUBLE_EQ(s.rangeMax(), 50.0);
  EXPECT_TRUE(IsNearPose(SE2(0.25, -0.1, 0), r.frames[0].T_robot_laser, 1e-12, 1e-9));
  EXPECT_TRUE(hasWarning(r.notes, "1 RLASER"));

  ReaderOptions o;
  o.carmen_laser = "RLASER";
  r = readWithNotes(path, o);
  ASSERT_EQ(r.frames.size(), 1u);
  EXPECT_EQ(r.notes.scan_source, "RLASER");
  const LaserScan& rs = r.frames[0].scan;
  EXPECT_EQ(rs.size(), 101u);
  EXPECT_NEAR(rs.angleIncrement(), 1.0 * kDeg, 1e-12);  // fov 100 over 100 steps
  EXPECT_NEAR(rs.angleMin(), -50.0 * kDeg, 1e-12);
  EXPECT_DOUBLE_EQ(rs.rangeMax(), 80.0);  // the front laser's max does not apply
  // Rear laser: mounted backwards at robot_rearlaser_offset.
  EXPECT_TRUE(IsNearPose(SE2(-0.3, 0, std::numbers::pi), r.frames[0].T_robot_laser, 1e-12, 1e-9));
}

TEST_F(CarmenSynthetic, TheLaserMessagesPoseIsTheLasersAndTheRobotIsUnderIt) {
  // CARMEN's FLASER/RLASER: x y theta is the laser's pose, odom_* the robot's odometry. With the
  // laser 0.25 m ahead and 0.1 m left, facing 90 degrees left, a laser at (2, 1) facing +y puts
  // the robot at (1.75, 0.9) facing +x (read as the robot's pose, 0.27 m and 90 degrees off).
  const std::string log =
      "PARAM robot_frontlaser_offset 0.25\n"
      "PARAM robot_frontlaser_side_offset 0.1\n"
      "PARAM robot_frontlaser_angular_offset 1.5707963267948966\n"
      "PARAM robot_rearlaser_offset -0.3\n" +
      flaser(4, 1.0, 2.0, 1.0, std::numbers::pi / 2, 5.0, 6.0, 0.5) +
      flaser(4, 1.0, 2.0, 1.0, -std::numbers::pi / 2, 5.0, 6.0, 0.5, "RLASER");
  const std::string path = write(log);
  ReaderOptions o;
  o.carmen_poses = CarmenPoses::kTruth;
  auto r = readWithNotes(path, o);
  ASSERT_EQ(r.frames.size(), 1u);
  ASSERT_TRUE(r.frames[0].T_world_robot);
  EXPECT_TRUE(IsNearPose(SE2(1.75, 0.9, 0.0), *r.frames[0].T_world_robot, 1e-6, 1e-4));
  EXPECT_TRUE(IsNearPose(SE2(2.0, 1.0, std::numbers::pi / 2), *r.frames[0].T_world_robot * r.frames[0].T_robot_laser,
                         1e-6, 1e-4));
  o.carmen_poses = CarmenPoses::kOdometry;
  r = readWithNotes(path, o);
  ASSERT_EQ(r.frames.size(), 1u);
  EXPECT_TRUE(IsNearPose(SE2(5.0, 6.0, 0.5), *r.frames[0].T_odom_robot, 1e-6, 1e-4));  // the robot's, as it is
  // The rear laser, mounted backwards 0.3 m behind: a laser at (2, 1) facing -y puts the robot at
  // (2, 1.3) facing +y.
  o.carmen_poses = CarmenPoses::kTruth;
  o.carmen_laser = "RLASER";
  r = readWithNotes(path, o);
  ASSERT_EQ(r.frames.size(), 1u);
  EXPECT_TRUE(IsNearPose(SE2(2.0, 1.3, std::numbers::pi / 2), *r.frames[0].T_world_robot, 1e-6, 1e-4));
}

TEST_F(CarmenSynthetic, RangeMaxMarksNoReturn) {
  std::string log = "FLASER 4 1.0 81.91 79.99 0 0 0 0 0 0 0 5.0 host 5.0\n";
  const auto f = readAll(write(log));
  ASSERT_EQ(f.size(), 1u);
  EXPECT_TRUE(f[0].scan.isValid(0));
  EXPECT_FALSE(f[0].scan.isValid(1));  // SICK no return
  EXPECT_TRUE(f[0].scan.isValid(2));
  EXPECT_FALSE(f[0].scan.isValid(3));  // 0 = no measurement (<= range_min)
}

TEST_F(CarmenSynthetic, RobotLaserGivesMountAnglesIntensitiesAndOdometry) {
  // Robot at (1, 2, 90 deg), laser 0.3 m ahead of it -> laser pose (1, 2.3, 90 deg).
  const std::string log =
      "ROBOTLASER1 0 -1.5 3.0 1.0 20 0.01 0 4 1 2 25 0 4 10 20 30 40 1 2.3 1.5707963267948966 1 2 "
      "1.5707963267948966 0 0 0 0 0 7.25 host 7.25\n";
  auto r = readWithNotes(write(log));
  ASSERT_EQ(r.frames.size(), 1u);
  const Frame& f = r.frames[0];
  EXPECT_DOUBLE_EQ(f.time, 7.25);
  EXPECT_DOUBLE_EQ(f.scan.angleMin(), -1.5);
  EXPECT_DOUBLE_EQ(f.scan.angleIncrement(), 1.0);
  EXPECT_DOUBLE_EQ(f.scan.rangeMax(), 20.0);
  EXPECT_TRUE(f.scan.isValid(1));
  EXPECT_FALSE(f.scan.isValid(2));  // 25 >= maximum_range
  EXPECT_FALSE(f.scan.isValid(3));
  ASSERT_TRUE(f.scan.hasIntensities());
  EXPECT_DOUBLE_EQ(f.scan.intensities()[3], 40.0);
  EXPECT_TRUE(IsNearPose(SE2(0.3, 0, 0), f.T_robot_laser, 1e-12, 1e-9));
  ASSERT_TRUE(f.T_odom_robot);
  EXPECT_TRUE(IsNearPose(SE2(1, 2, std::numbers::pi / 2), *f.T_odom_robot, 1e-12, 1e-9));
  EXPECT_FALSE(f.T_world_robot);
  EXPECT_EQ(r.notes.odom_source, "ROBOTLASER1 robot pose (no ODOM lines)");
}

TEST_F(CarmenSynthetic, RawLaserOdometryIsInterpolatedFromOdomLines) {
  // ODOM at t=1 (x=0) and t=3 (x=2, theta 0.2); scans before, between and after.
  const std::string log = rawlaser(0.5) + odom(1, 0, 0, 0) + rawlaser(1.5) + rawlaser(2.5) + odom(3, 2, 0, 0.2) +
                          rawlaser(3.5) + "NEFF 1\n";
  auto r = readWithNotes(write(log));
  ASSERT_EQ(r.frames.size(), 4u);
  EXPECT_EQ(r.notes.scan_source, "RAWLASER1");
  EXPECT_EQ(r.notes.odom_source, "ODOM lines (interpolated)");
  // Before the first ODOM: the first; between: linear; after the last: the last.
  EXPECT_TRUE(IsNearPose(SE2(0, 0, 0), *r.frames[0].T_odom_robot, 1e-9, 1e-7));
  EXPECT_TRUE(IsNearPose(SE2(0.5, 0, 0.05), *r.frames[1].T_odom_robot, 1e-9, 1e-7));
  EXPECT_TRUE(IsNearPose(SE2(1.5, 0, 0.15), *r.frames[2].T_odom_robot, 1e-9, 1e-7));
  EXPECT_TRUE(IsNearPose(SE2(2, 0, 0.2), *r.frames[3].T_odom_robot, 1e-9, 1e-7));
  EXPECT_FALSE(r.frames[0].T_world_robot);
  EXPECT_DOUBLE_EQ(r.frames[0].scan.angleMin(), -1.5);
  EXPECT_DOUBLE_EQ(r.frames[0].scan.angleIncrement(), 0.75);
}

TEST_F(CarmenSynthetic, InterpolationAcrossTheAngleWrap) {
  const std::string log = odom(1, 0, 0, 3.0) + rawlaser(1.5) + odom(2, 0, 0, -3.0);
  const auto f = readAll(write(log));
  ASSERT_EQ(f.size(), 1u);
  // Shorter arc from 3.0 to -3.0 passes through pi.
  EXPECT_TRUE(IsNearPose(SE2(0, 0, std::numbers::pi), *f[0].T_odom_robot, 1e-9, 1e-6));
}

TEST_F(CarmenSynthetic, NonBracketingOdomTimesUseTheCloserLine) {
  // Each scan's previous/next ODOM lines (file order) and the expected rule, see the EXPECTs.
  const std::string log = odom(4.0, 1, 0, 0) + rawlaser(5) + odom(0, 9, 0, 0) + rawlaser(5) + odom(5.5, 3, 0, 0) +
                          rawlaser(8) + odom(10.5, 7, 0, 0) + rawlaser(2) + odom(-1, 5, 0, 0) +
                          rawlaser(20) + odom(21, 12, 0, 0) + odom(19, 13, 0, 0) + rawlaser(20) + odom(21, 14, 0, 0);
  auto r = readWithNotes(write(log));
  ASSERT_EQ(r.frames.size(), 6u);
  EXPECT_NEAR(r.frames[0].T_odom_robot->x(), 1.0, 1e-12);
  EXPECT_NEAR(r.frames[1].T_odom_robot->x(), 9 + (5.0 / 5.5) * (3 - 9), 1e-9);
  EXPECT_NEAR(r.frames[2].T_odom_robot->x(), 5.0, 1e-9);
  EXPECT_NEAR(r.frames[3].T_odom_robot->x(), 5.0, 1e-12);  // next (t=-1) is closer than t=10.5
  // Scan t=20: previous ODOM t=-1 (x=5), next t=21 (x=12): bracketed -> 5 + 21/22 * 7.
  EXPECT_NEAR(r.frames[4].T_odom_robot->x(), 5 + (21.0 / 22.0) * 7, 1e-9);
  // Scan t=20: previous t=19 (x=13), next t=21 (x=14): bracketed -> 13.5.
  EXPECT_NEAR(r.frames[5].T_odom_robot->x(), 13.5, 1e-9);
  EXPECT_TRUE(hasWarning(r.notes, "odometry of 2 scans taken from the nearer ODOM line"));
}

TEST_F(CarmenSynthetic, TieInTimeTakesThePreviousOdomLine) {
  // Scan at t=5: previous ODOM t=6 (x=1), next ODOM t=4 (x=2): not bracketing, both 1 s away.
  const auto f = readAll(write(odom(6, 1, 0, 0) + rawlaser(5) + odom(4, 2, 0, 0)));
  ASSERT_EQ(f.size(), 1u);
  EXPECT_NEAR(f[0].T_odom_robot->x(), 1.0, 1e-12);
}

// A log whose FLASER poses move like the ODOM lines (raw log) or not (corrected log).
std::string autoLog(bool corrected) {
  std::string log;
  for (int k = 0; k < 20; ++k) {
    const double t = k;
    log += odom(t, 0.5 * k, 0, 0.01 * k);
    // Corrected: the pose wanders +-10 cm sideways from the odometry; raw: exactly the odometry.
    const double dy = corrected ? ((k % 2) ? 0.1 : -0.1) : 0.0;
    log += flaser(8, t, 0.5 * k + 3, dy + 1, 0.01 * k, 0.5 * k + 3, dy + 1, 0.01 * k);
  }
  return log;
}

TEST_F(CarmenSynthetic, AutoDetectsCorrectedPoses) {
  auto r = readWithNotes(write(autoLog(true)));
  ASSERT_EQ(r.frames.size(), 20u);
  ASSERT_TRUE(r.frames[3].T_world_robot);
  EXPECT_TRUE(IsNearPose(SE2(4.5, 1.1, 0.03), *r.frames[3].T_world_robot, 1e-6, 1e-4));
  EXPECT_TRUE(IsNearPose(SE2(1.5, 0, 0.03), *r.frames[3].T_odom_robot, 1e-6, 1e-4));
  EXPECT_EQ(r.notes.odom_source, "ODOM lines (interpolated)");
  EXPECT_NE(r.notes.truth_source.find("corrected log"), std::string::npos);
}

TEST_F(CarmenSynthetic, AutoDetectsRawOdometry) {
  auto r = readWithNotes(write(autoLog(false)));
  ASSERT_EQ(r.frames.size(), 20u);
  EXPECT_FALSE(r.frames[3].T_world_robot);
  EXPECT_TRUE(IsNearPose(SE2(4.5, 1, 0.03), *r.frames[3].T_odom_robot, 1e-6, 1e-4));
  EXPECT_NE(r.notes.odom_source.find("FLASER odometry fields (agrees with the ODOM lines"), std::string::npos);
  EXPECT_EQ(r.notes.truth_source, "");
}

TEST_F(CarmenSynthetic, TrueposGivesTruthByTimestamp) {
  const std::string log = flaser(4, 1, 0, 0, 0, 1, 1, 0) + "TRUEPOS 10 20 0.5 1 1 0 1.000000 host 1\n" +
                          // TRUEPOS before its laser message (same time) -> truth of the next one.
                          "TRUEPOS 11 21 0.6 0 0 0 2 host 2\n" + flaser(4, 2, 0, 0, 0, 2, 2, 0) +
                          // Scan without truth, then a TRUEPOS matching nothing.
                          flaser(4, 3, 0, 0, 0, 3, 3, 0) + "TRUEPOS 0 0 0 0 0 0 99 host 99\n";
  auto r = readWithNotes(write(log));
  ASSERT_EQ(r.frames.size(), 3u);
  EXPECT_EQ(r.notes.truth_source, "TRUEPOS");
  ASSERT_TRUE(r.frames[0].T_world_robot);
  EXPECT_TRUE(IsNearPose(SE2(10, 20, 0.5), *r.frames[0].T_world_robot, 1e-12, 1e-9));
  ASSERT_TRUE(r.frames[1].T_world_robot);
  EXPECT_TRUE(IsNearPose(SE2(11, 21, 0.6), *r.frames[1].T_world_robot, 1e-12, 1e-9));
  EXPECT_FALSE(r.frames[2].T_world_robot);
  // Odometry = FLASER odometry triple.
  EXPECT_TRUE(IsNearPose(SE2(3, 3, 0), *r.frames[2].T_odom_robot, 1e-12, 1e-9));
  EXPECT_TRUE(hasWarning(r.notes, "1 TRUEPOS lines matched no laser message"));
}

TEST_F(CarmenSynthetic, RepeatedAndBackwardTimesKeepFileOrder) {
  const std::string log = flaser(4, 5) + flaser(4, 5) + flaser(4, 4) + flaser(4, 6) + flaser(4, 6);
  auto r = readWithNotes(write(log));
  ASSERT_EQ(r.frames.size(), 5u);
  const double expected[] = {5, 5, 4, 6, 6};
  for (std::size_t i = 0; i < 5; ++i) {
    EXPECT_EQ(r.frames[i].index, i);
    EXPECT_DOUBLE_EQ(r.frames[i].time, expected[i]);
  }
  EXPECT_TRUE(hasWarning(r.notes, "timestamps repeat 2 times; go backwards 1 times"));
}

TEST_F(CarmenSynthetic, GzipCrlfAndMissingTrailingNewline) {
  std::string log = flaser(4, 1) + flaser(4, 2);
  std::string crlf;
  for (char c : log) {
    if (c == '\n') crlf += '\r';
    crlf += c;
  }
  crlf.pop_back();  // no final newline
  crlf.pop_back();
  writeGzip(dir_ / "log.gz", crlf);
  const auto f = readAll((dir_ / "log.gz").string());
  ASSERT_EQ(f.size(), 2u);
  EXPECT_DOUBLE_EQ(f[1].time, 2.0);
}

TEST_F(CarmenSynthetic, LookAheadIsBoundedWhenOdomLinesStop) {
  // One ODOM line, then many scans: each scan is emitted without waiting for the end of the file.
  std::string log = odom(0, 1, 2, 0.3);
  for (int k = 0; k < 1500; ++k) log += rawlaser(k + 1.0, 2);
  const std::string path = write(log);
  auto src = io::openLog(path);
  std::size_t n = 0;
  while (auto f = src->next()) {
    ASSERT_TRUE(f->T_odom_robot);
    EXPECT_TRUE(IsNearPose(SE2(1, 2, 0.3), *f->T_odom_robot, 1e-12, 1e-9));
    ++n;
  }
  EXPECT_EQ(n, 1500u);
  EXPECT_TRUE(hasWarning(src->notes(), "had no ODOM line within the next 1000 scans"));
}

TEST_F(CarmenSynthetic, FirstLaserTypeIsReadAndOthersSkipped) {
  const std::string log = rawlaser(1) + flaser(4, 1.5) + rawlaser(2) + "SYNC foo\n";
  auto r = readWithNotes(write(log));
  ASSERT_EQ(r.frames.size(), 2u);
  EXPECT_EQ(r.notes.scan_source, "RAWLASER1");
  EXPECT_FALSE(r.frames[0].T_odom_robot);  // RAWLASER has no pose and there are no ODOM lines
  EXPECT_TRUE(hasWarning(r.notes, "skipped other laser messages: 1 FLASER"));
}

// A declared range max below what the laser measured (edmonton's PARAM robot_front_laser_max 10,
// its SICK reading walls to 45 m and 51.15 m for no return): the readings prove it wrong, so the
// range max becomes 99% of the no-return code, and the notes say so. ReaderOptions::laser_range_max
// replaces either (10 keeps the log's, and openLog then warns of the returns it drops).
TEST_F(CarmenSynthetic, ARangeMaxTheReadingsContradictIsReplaced) {
  const std::string path =
      write("PARAM robot_front_laser_max 10 nohost 0\nFLASER 5 2 12.5 25 51.15 51.15 0 0 0 0 0 0 1 host 1\n");
  auto r = readWithNotes(path);
  ASSERT_EQ(r.frames.size(), 1u);
  EXPECT_DOUBLE_EQ(r.frames[0].scan.rangeMax(), 51.15 * 0.99);
  EXPECT_EQ(r.frames[0].scan.validIndices(), (std::vector<std::size_t>{0, 1, 2}));
  EXPECT_TRUE(hasWarning(r.notes, "the log's range max (10.00 m) is below what its laser measured: 40.0% of the "
                                  "beams of its first 1 scans read beyond it, under the no-return reading 51.15 m; "
                                  "read with the range max 50.64 m (--laser-range-max 10 keeps the log's)"));
  EXPECT_EQ(r.notes.beams_beyond_range_max, 0u);
  ReaderOptions o;
  o.laser_range_max = 10.0;
  r = readWithNotes(path, o);
  EXPECT_DOUBLE_EQ(r.frames[0].scan.rangeMax(), 10.0);
  EXPECT_EQ(r.frames[0].scan.numValid(), 1u);
  EXPECT_EQ(r.notes.beams_beyond_range_max, 2u);
  EXPECT_TRUE(hasWarning(r.notes, "40.0% of the beams read beyond the range max (10.00 m"));
  EXPECT_FALSE(hasWarning(r.notes, "is below what its laser measured"));
}

// Readings beyond the declared range max with no no-return code above them all (here 25 m beyond
// the commonest, 12.5 m) do not say where the laser's range ends: the log's range max is kept and
// openLog warns. A no-return code alone (80.99 declared, 81.91 written: freiburg-079) changes nothing.
TEST_F(CarmenSynthetic, ARangeMaxIsKeptWithoutProofOfTheLasersRange) {
  auto r = readWithNotes(write("PARAM robot_front_laser_max 10 nohost 0\n"
                               "FLASER 4 2 12.5 25 3 0 0 0 0 0 0 1 host 1\nFLASER 4 2 12.5 13 3 0 0 0 0 0 0 2 host 2\n"));
  ASSERT_EQ(r.frames.size(), 2u);
  EXPECT_DOUBLE_EQ(r.frames[0].scan.rangeMax(), 10.0);
  EXPECT_FALSE(hasWarning(r.notes, "is below what its laser measured"));
  EXPECT_TRUE(hasWarning(r.notes, "25.0% of the beams read beyond the range max (10.00 m"));
  r = readWithNotes(write("PARAM robot_front_laser_max 80.99 nohost 0\nFLASER 4 2 81.91 81.91 3 0 0 0 0 0 0 1 host 1\n"));
  EXPECT_DOUBLE_EQ(r.frames[0].scan.rangeMax(), 80.99);
  EXPECT_EQ(r.frames[0].scan.numValid(), 2u);
  EXPECT_TRUE(r.notes.warnings.empty());
}

// ReaderOptions::laser_range_max replaces the log's range max: readings below it become returns,
// the no-return code above it stays none; a value out of range is an invalid argument.
TEST_F(CarmenSynthetic, ARangeMaxFromTheOptionsReplacesTheLogs) {
  const std::string path =
      write("PARAM robot_front_laser_max 10 nohost 0\nFLASER 4 2 12.5 25 51.15 0 0 0 0 0 0 1 host 1\n");
  ReaderOptions o;
  o.laser_range_max = 50.0;
  auto r = readWithNotes(path, o);
  ASSERT_EQ(r.frames.size(), 1u);
  const LaserScan& s = r.frames[0].scan;
  EXPECT_DOUBLE_EQ(s.rangeMax(), 50.0);
  EXPECT_EQ(s.validIndices(), (std::vector<std::size_t>{0, 1, 2}));
  EXPECT_DOUBLE_EQ(s.ranges()[2], 25.0);
  EXPECT_NE(r.notes.scan_source.find("range max 50 m given by the options"), std::string::npos) << r.notes.scan_source;
  for (const double bad : {0.0, -1.0, std::nan(""), 2000.0}) {
    o.laser_range_max = bad;
    try {
      io::openLog(path, o);
      FAIL() << bad << ": no throw";
    } catch (const Error& e) {
      EXPECT_EQ(e.kind(), ErrorKind::kInvalidArgument) << bad;
      EXPECT_NE(std::string(e.what()).find("laser_range_max"), std::string::npos) << e.what();
    }
  }
}

TEST_F(CarmenSynthetic, UnknownLaserOptionIsAnInvalidArgument) {
  ReaderOptions o;
  o.carmen_laser = "LASER9";
  try {
    io::openLog(write(flaser(4, 1)), o);
    FAIL() << "no throw";
  } catch (const Error& e) {
    EXPECT_EQ(e.kind(), ErrorKind::kInvalidArgument);
    EXPECT_NE(std::string(e.what()).find("LASER9"), std::string::npos);
  }
  o.carmen_laser = "robotlaser1";  // case-insensitive
  const std::string path = write(flaser(4, 1));
  try {
    readAll(path, o);
    FAIL() << "no throw";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("no ROBOTLASER1 scans found"), std::string::npos) << e.what();
  }
}

TEST_F(CarmenSynthetic, InternalFactoryMatchesOpenLog) {
  const std::string path = write(flaser(4, 1) + flaser(4, 2));
  auto src = io::internal::openCarmen(path, {});
  EXPECT_EQ(src->path(), path);
  std::size_t n = 0;
  while (src->next()) ++n;
  EXPECT_EQ(n, 2u);
  EXPECT_FALSE(src->next());  // stays at the end
}

}  // namespace
}  // namespace lidar2d::test
