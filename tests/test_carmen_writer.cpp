// CARMEN writer: what it writes reads back (through the CARMEN reader) to equal frames, and it is
// atomic (nothing at the path before commit(), an unwritable path throws).

#include <gtest/gtest.h>

#include <ostream>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <numbers>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include "lidar2d/core/error.hpp"
#include "lidar2d/io/carmen_writer.hpp"
#include "lidar2d/io/frame_source.hpp"
#include "support/test_support.hpp"

namespace lidar2d::test {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr double kInf = std::numeric_limits<double>::infinity();

std::vector<Frame> readAll(const std::string& path, io::SourceNotes* notes = nullptr) {
  auto src = io::openLog(path);
  std::vector<Frame> frames;
  while (auto f = src->next()) frames.push_back(std::move(*f));
  if (notes) *notes = src->notes();
  return frames;
}

// Seeded random frames with odometry, truth, a mounted laser, intensities and invalid beams of every
// kind (NaN, inf, 0, beyond range_max, below range_min).
std::vector<Frame> makeFrames(std::size_t count, bool odom, bool truth, bool intensities, std::uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  std::vector<Frame> frames;
  for (std::size_t k = 0; k < count; ++k) {
    LaserScanFields s;
    s.time = 1000.123456789 + 0.1 * static_cast<double>(k);
    s.angle_min = -2.0943951023931953;
    s.angle_increment = 0.0061359231515425647;
    s.range_min = 0.1;
    s.range_max = 30.0;
    const std::size_t n = 683;
    for (std::size_t i = 0; i < n; ++i) {
      double r = 0.05 + 35.0 * u(rng);  // some below range_min, some beyond range_max
      if (i == 3) r = kNaN;
      if (i == 4) r = kInf;
      if (i == 5) r = 0.0;
      if (i == 6) r = 30.0;          // == range_max: invalid
      if (i == 7) r = 29.99996;      // valid, rounds to 30.0000 at 4 decimals
      if (i == 8) r = 0.10001;       // valid, just above range_min
      s.ranges.push_back(r);
      if (intensities) s.intensities.push_back(std::floor(100 * u(rng)));
    }
    Frame f;
    f.index = k;
    f.time = s.time;
    f.scan = LaserScan::create(std::move(s));
    f.T_robot_laser = SE2(0.2, -0.05, 0.01);
    if (odom) f.T_odom_robot = SE2(10 * u(rng) - 5, 10 * u(rng) - 5, 6 * u(rng) - 3);
    if (truth) f.T_world_robot = SE2(100 * u(rng), -100 * u(rng), 6 * u(rng) - 3);
    frames.push_back(std::move(f));
  }
  return frames;
}

void expectEqualFrames(const std::vector<Frame>& want, const std::vector<Frame>& got) {
  ASSERT_EQ(want.size(), got.size());
  for (std::size_t k = 0; k < want.size(); ++k) {
    const Frame& a = want[k];
    const Frame& b = got[k];
    SCOPED_TRACE("frame " + std::to_string(k));
    EXPECT_EQ(b.index, a.index);
    EXPECT_EQ(b.time, a.time);  // times are written exactly
    EXPECT_EQ(b.scan.time(), a.time);
    ASSERT_EQ(b.scan.size(), a.scan.size());
    EXPECT_EQ(b.scan.angleMin(), a.scan.angleMin());
    EXPECT_EQ(b.scan.angleIncrement(), a.scan.angleIncrement());
    EXPECT_EQ(b.scan.rangeMax(), a.scan.rangeMax());
    EXPECT_EQ(b.scan.numValid(), a.scan.numValid());
    for (std::size_t i = 0; i < a.scan.size(); ++i) {
      ASSERT_EQ(b.scan.isValid(i), a.scan.isValid(i)) << "beam " << i << " " << a.scan.ranges()[i];
      if (a.scan.isValid(i)) {
        EXPECT_NEAR(b.scan.ranges()[i], a.scan.ranges()[i], 1e-4) << "beam " << i;
      }
    }
    EXPECT_EQ(b.scan.intensities(), a.scan.intensities());
    EXPECT_TRUE(IsNearPose(a.T_robot_laser, b.T_robot_laser, 1e-9, 1e-7));
    ASSERT_EQ(b.T_odom_robot.has_value(), a.T_odom_robot.has_value());
    if (a.T_odom_robot) {
      EXPECT_TRUE(IsNearPose(*a.T_odom_robot, *b.T_odom_robot, 1e-12, 1e-10));
    }
    ASSERT_EQ(b.T_world_robot.has_value(), a.T_world_robot.has_value());
    if (a.T_world_robot) {
      EXPECT_TRUE(IsNearPose(*a.T_world_robot, *b.T_world_robot, 1e-12, 1e-10));
    }
  }
}

struct RoundTripCase {
  bool odom, truth, intensities, gzip_name;
};
// gtest prints parameters in test listings; a name instead of a byte dump keeps ctest readable.
[[maybe_unused]] void PrintTo(const RoundTripCase&, std::ostream* os) { *os << "RoundTripCase"; }


class CarmenRoundTrip : public ::testing::TestWithParam<RoundTripCase> {};

TEST_P(CarmenRoundTrip, ReadsBackEqualFrames) {
  const RoundTripCase c = GetParam();
  TempDir dir;
  const std::string path = (dir / "out.log").string();
  const auto frames = makeFrames(25, c.odom, c.truth, c.intensities, 7);
  {
    io::CarmenWriter w(path);
    w.comment("made by test_carmen_writer\nsecond line");
    for (const auto& f : frames) w.write(f);
    w.commit();
  }
  io::SourceNotes notes;
  const auto back = readAll(path, &notes);
  expectEqualFrames(frames, back);
  EXPECT_EQ(notes.scan_source, "ROBOTLASER1");
  EXPECT_EQ(notes.truth_source, "TRUEPOS");
  EXPECT_TRUE(notes.warnings.empty()) << notes.warnings.front();
}

INSTANTIATE_TEST_SUITE_P(Cases, CarmenRoundTrip,
                         ::testing::Values(RoundTripCase{true, true, false, false}, RoundTripCase{true, false, true, false},
                                           RoundTripCase{false, true, false, false},
                                           RoundTripCase{false, false, true, false}));

TEST(CarmenWriter, MixedFramesKeepTheirOwnPoses) {
  // Odometry and truth present on some frames only: each frame reads back with exactly its own.
  auto frames = makeFrames(6, true, true, false, 3);
  frames[1].T_odom_robot.reset();
  frames[2].T_world_robot.reset();
  frames[4].T_odom_robot.reset();
  frames[4].T_world_robot.reset();
  TempDir dir;
  const std::string path = (dir / "mixed.log").string();
  io::CarmenWriter w(path);
  for (const auto& f : frames) w.write(f);
  w.commit();
  expectEqualFrames(frames, readAll(path));
}

TEST(CarmenWriter, OutputIsPlainCarmenText) {
  auto frames = makeFrames(2, true, true, false, 5);
  TempDir dir;
  const std::string path = (dir / "plain.log").string();
  io::CarmenWriter w(path);
  for (const auto& f : frames) w.write(f);
  w.commit();
  std::ifstream in(path);
  std::string line;
  std::vector<std::string> tags;
  while (std::getline(in, line)) {
    std::istringstream ss(line);
    std::string tag;
    ss >> tag;
    tags.push_back(tag);
    if (tag == "ROBOTLASER1") {
      // tag, 7 header fields, count, 683 ranges, 0 remissions, 12 pose/velocity/time fields, host, logger time.
      std::size_t n = 1;
      while (ss >> tag) ++n;
      EXPECT_EQ(n, 1u + 7 + 1 + 683 + 1 + 12 + 2);
    }
  }
  const std::vector<std::string> expected{"ROBOTLASER1", "ODOM", "TRUEPOS", "ROBOTLASER1", "ODOM", "TRUEPOS"};
  std::vector<std::string> messages;
  for (const auto& t : tags)
    if (t != "#") messages.push_back(t);
  EXPECT_EQ(messages, expected);
  ASSERT_FALSE(tags.empty());
  EXPECT_EQ(tags.front(), "#");
}

TEST(CarmenWriter, UncommittedWriterLeavesNoFile) {
  TempDir dir;
  const auto path = dir / "never.log";
  {
    io::CarmenWriter w(path.string());
    for (const auto& f : makeFrames(3, true, false, false, 1)) w.write(f);
  }
  EXPECT_FALSE(std::filesystem::exists(path));
  EXPECT_TRUE(std::filesystem::is_empty(dir.path()));  // no temporary file left behind either
}

TEST(CarmenWriter, UnwritablePathThrows) {
  TempDir dir;
  try {
    io::CarmenWriter w((dir / "missing-folder" / "x.log").string());
    FAIL() << "no throw";
  } catch (const Error& e) {
    EXPECT_EQ(e.kind(), ErrorKind::kIo);
    EXPECT_NE(std::string(e.what()).find("missing-folder"), std::string::npos);
  }
  EXPECT_THROW(io::CarmenWriter w(dir.path().string()), Error);  // a directory
}

TEST(CarmenWriter, NonFinitePosesAreRejected) {
  TempDir dir;
  io::CarmenWriter w((dir / "bad.log").string());
  auto frames = makeFrames(1, true, false, false, 2);
  frames[0].T_odom_robot = SE2(kNaN, 0, 0);
  EXPECT_THROW(w.write(frames[0]), Error);
  frames[0].T_odom_robot.reset();
  frames[0].time = kInf;
  EXPECT_THROW(w.write(frames[0]), Error);
}

}  // namespace
}  // namespace lidar2d::test
