// ROS2 bags in MCAP (and split / rosbag2-compressed bags): the fixtures in tests/fixtures/mcap were
// written by the reference MCAP writer (@mcap/core, tools/mcap-fixtures/make-fixtures.mjs), and
// every frame is checked against that script's inputs (expected.json), not against our reader.

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <limits>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "lidar2d/core/error.hpp"
#include "lidar2d/io/frame_source.hpp"
#include "src/io/internal/readers.hpp"
#include "support/test_support.hpp"

namespace lidar2d::io {
namespace {

namespace fs = std::filesystem;
using ::testing::HasSubstr;
using lidar2d::test::IsNearPose;

fs::path fixtureDir() { return test::sourceFile("tests/fixtures/mcap"); }

const nlohmann::json& expected() {
  static const nlohmann::json j = nlohmann::json::parse(test::readFile(fixtureDir() / "expected.json"));
  return j;
}

double wrap(double a) { return std::atan2(std::sin(a), std::cos(a)); }

/// The odometry pose at time offset `ns` by the interpolation rule of RosFrameAssembler
/// (ros_frames.hpp): linear in x, y and in the wrapped yaw difference.
SE2 odomAt(std::int64_t ns) {
  const auto& odom = expected()["odom"];
  for (std::size_t k = 0; k + 1 < odom.size(); ++k) {
    const auto t0 = odom[k]["offset_ns"].get<std::int64_t>(), t1 = odom[k + 1]["offset_ns"].get<std::int64_t>();
    if (ns < t0 || ns > t1) continue;
    const double a = static_cast<double>(ns - t0) / static_cast<double>(t1 - t0);
    const double yaw0 = odom[k]["yaw"].get<double>(), yaw1 = odom[k + 1]["yaw"].get<double>();
    return SE2(odom[k]["x"].get<double>() + a * (odom[k + 1]["x"].get<double>() - odom[k]["x"].get<double>()),
               odom[k]["y"].get<double>() + a * (odom[k + 1]["y"].get<double>() - odom[k]["y"].get<double>()),
               yaw0 + a * wrap(yaw1 - yaw0));
  }
  ADD_FAILURE() << "no odometry around " << ns;
  return SE2();
}

/// Reads every frame of `src` and compares it with the script's inputs.
void checkAgainstScript(FrameSource& src) {
  const auto& j = expected();
  const auto& scans = j["scans"];
  const auto& mount = j["mount"];
  const auto& meta = j["scan"];
  std::size_t n = 0;
  while (auto f = src.next()) {
    ASSERT_LT(n, scans.size());
    SCOPED_TRACE(n);
    const auto ns = scans[n]["offset_ns"].get<std::int64_t>();
    EXPECT_NEAR(f->time, j["t0_s"].get<double>() + static_cast<double>(ns) * 1e-9, 1e-6);
    const auto& ranges = scans[n]["ranges"];
    ASSERT_EQ(f->scan.size(), ranges.size());
    for (std::size_t i = 0; i < ranges.size(); ++i) {
      const double r = ranges[i].is_string() ? std::numeric_limits<double>::infinity() : ranges[i].get<double>();
      EXPECT_EQ(f->scan.ranges()[i], r) << "beam " << i;
    }
    EXPECT_FLOAT_EQ(static_cast<float>(f->scan.angleMin()), meta["angle_min"].get<float>());
    EXPECT_FLOAT_EQ(static_cast<float>(f->scan.angleIncrement()), meta["angle_increment"].get<float>());
    EXPECT_FLOAT_EQ(static_cast<float>(f->scan.rangeMin()), meta["range_min"].get<float>());
    EXPECT_FLOAT_EQ(static_cast<float>(f->scan.rangeMax()), meta["range_max"].get<float>());
    EXPECT_TRUE(IsNearPose(SE2(mount["x"].get<double>(), mount["y"].get<double>(), mount["yaw"].get<double>()),
                           f->T_robot_laser, 1e-12, 1e-9));
    ASSERT_TRUE(f->T_odom_robot.has_value());
    // The reader interpolates in seconds since the epoch: a double resolves 2.4e-7 s at 1.7e9 s,
    // which at the script's speeds (< 1 m/s, 0.3 rad/s) is below 1e-6 m and 1e-5 deg.
    EXPECT_TRUE(IsNearPose(odomAt(ns), *f->T_odom_robot, 1e-6, 1e-5));
    EXPECT_FALSE(f->T_world_robot.has_value());
    ++n;
  }
  EXPECT_EQ(n, scans.size());
  EXPECT_EQ(src.sizeHint(), scans.size());
  const SourceNotes notes = src.notes();
  EXPECT_THAT(notes.scan_source, HasSubstr("/scan"));
  EXPECT_THAT(notes.scan_source, HasSubstr("base_link -> laser from /tf_static"));
  EXPECT_THAT(notes.odom_source, HasSubstr("/odom"));
  EXPECT_TRUE(notes.warnings.empty()) << notes.warnings.front();
}

struct Layout {
  const char* path;       // under tests/fixtures/mcap
  const char* container;  // SourceNotes::container
};

class McapLayouts : public ::testing::TestWithParam<Layout> {};

TEST_P(McapLayouts, FramesAreTheWritersInputs) {
  const fs::path p = fixtureDir() / GetParam().path;
  auto src = openLog(p.string());
  EXPECT_EQ(src->format(), LogFormat::kRosbag2);
  checkAgainstScript(*src);
  EXPECT_EQ(src->notes().container, GetParam().container);
}

INSTANTIATE_TEST_SUITE_P(
    Fixtures, McapLayouts,
    ::testing::Values(Layout{"unchunked_nosummary.mcap", "mcap storage"}, Layout{"unchunked.mcap", "mcap storage"},
                      Layout{"chunked.mcap", "mcap storage"}, Layout{"chunked_zstd.mcap", "mcap storage"},
                      Layout{"chunked_lz4.mcap", "mcap storage"}, Layout{"chunked_zstd_noindex.mcap", "mcap storage"},
                      Layout{"split", "mcap storage, 2 files"},
                      Layout{"compressed_file", "mcap storage, 2 files, zstd-compressed by file"},
                      Layout{"compressed_message", "mcap storage, zstd-compressed by message"}),
    [](const auto& info) {
      std::string name = info.param.path;
      for (char& c : name)
        if (!std::isalnum(static_cast<unsigned char>(c))) c = '_';
      return name;
    });

TEST(McapReader, FileCompressedBagLeavesNoDecompressedCopies) {
  // The decompressed copies go to the temporary folder ($TMPDIR), here one of the test's own.
  test::TempDir tmp;
  const char* old = std::getenv("TMPDIR");
  const std::string saved = old ? old : "";
  setenv("TMPDIR", tmp.path().c_str(), 1);
  {
    auto src = openLog((fixtureDir() / "compressed_file").string());
    EXPECT_EQ(std::distance(fs::directory_iterator(tmp.path()), fs::directory_iterator()), 1);  // while open
    while (src->next()) {
    }
  }
  EXPECT_TRUE(fs::is_empty(tmp.path()));
  if (old)
    setenv("TMPDIR", saved.c_str(), 1);
  else
    unsetenv("TMPDIR");
}

TEST(McapReader, InfoSummarisesAnMcapBag) {
  const auto& j = expected();
  const auto r = test::runCli({"info", (fixtureDir() / "chunked_zstd.mcap").string(), "--json"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto info = nlohmann::json::parse(r.out);
  EXPECT_EQ(info["format"], "rosbag2");
  EXPECT_EQ(info["container"], "mcap storage");
  EXPECT_EQ(info["scans"], j["scans"].size());
  EXPECT_EQ(info["beams"], j["scans"][0]["ranges"].size());
  EXPECT_EQ(info["has_odometry"], true);
  EXPECT_EQ(info["has_truth"], false);
  const double first = static_cast<double>(j["scans"].front()["offset_ns"].get<std::int64_t>()) * 1e-9;
  const double last = static_cast<double>(j["scans"].back()["offset_ns"].get<std::int64_t>()) * 1e-9;
  EXPECT_NEAR(info["duration_s"].get<double>(), last - first, 1e-6);
  const auto text = test::runCli({"info", (fixtureDir() / "split").string()});
  ASSERT_EQ(text.exit_code, 0) << text.err;
  EXPECT_THAT(text.out, HasSubstr("(rosbag2: mcap storage, 2 files)"));
  EXPECT_THAT(text.out, HasSubstr("scans:       8 from /scan"));
}

TEST(McapReader, ScanTopicOverrideAndOdometryNone) {
  ReaderOptions opt;
  opt.odom_topic = "none";
  auto src = openLog((fixtureDir() / "chunked_lz4.mcap").string(), opt);
  std::size_t n = 0;
  while (auto f = src->next()) {
    EXPECT_FALSE(f->T_odom_robot.has_value());
    ++n;
  }
  EXPECT_EQ(n, expected()["scans"].size());
  opt = {};
  opt.scan_topic = "/cmd_vel";
  EXPECT_TRUE(test::throwsError([&] { (void)openLog((fixtureDir() / "chunked.mcap").string(), opt); },
                                ErrorKind::kBadInput, {"chunked.mcap", "/cmd_vel", "geometry_msgs/msg/Twist"}));
}

// The shared .db3 bag's messages converted to MCAP by the reference writer (in the same order):
// every frame read from both must be identical, bit for bit.
TEST(McapReader, RealBagConvertedToMcapGivesTheSameFramesAsTheDb3) {
  LIDAR2D_REQUIRE_DATA("ros2/macfirst_floor_take_2");
  const fs::path mcap = lidar2d::test::fixtureDir() / "macfirst_floor_take_2.mcap";
  if (!fs::exists(mcap))
    GTEST_SKIP() << mcap << " is missing: the build makes it where node, zstd and tools/mcap-fixtures/node_modules "
                 << "(npm ci there) are installed";
  auto db3 = openLog(test::dataFile("ros2/macfirst_floor_take_2").string());
  auto mc = openLog(mcap.string());
  std::size_t n = 0;
  for (;;) {
    auto a = db3->next();
    auto b = mc->next();
    ASSERT_EQ(a.has_value(), b.has_value()) << "frame " << n;
    if (!a) break;
    SCOPED_TRACE(n);
    EXPECT_EQ(a->time, b->time);
    EXPECT_EQ(a->scan.ranges(), b->scan.ranges());
    EXPECT_EQ(a->scan.angleMin(), b->scan.angleMin());
    EXPECT_EQ(a->scan.angleIncrement(), b->scan.angleIncrement());
    EXPECT_EQ(a->scan.rangeMin(), b->scan.rangeMin());
    EXPECT_EQ(a->scan.rangeMax(), b->scan.rangeMax());
    EXPECT_EQ(a->T_robot_laser.x(), b->T_robot_laser.x());
    EXPECT_EQ(a->T_robot_laser.theta(), b->T_robot_laser.theta());
    ASSERT_TRUE(a->T_odom_robot && b->T_odom_robot);
    EXPECT_EQ(a->T_odom_robot->x(), b->T_odom_robot->x());
    EXPECT_EQ(a->T_odom_robot->y(), b->T_odom_robot->y());
    EXPECT_EQ(a->T_odom_robot->theta(), b->T_odom_robot->theta());
    ++n;
  }
  EXPECT_EQ(n, 357u);  // the .db3's scan count (test_rosbag2_reader checks it against python's sqlite3)
  EXPECT_EQ(db3->notes().scan_source, mc->notes().scan_source);
  EXPECT_EQ(db3->notes().odom_source, mc->notes().odom_source);
}

}  // namespace
}  // namespace lidar2d::io
