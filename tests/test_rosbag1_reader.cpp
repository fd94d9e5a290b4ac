// ROS1 bag reader: every bag in ../shared/data against facts extracted independently with Debian's
// python3-rosbag, the fixture bags of tests/data (tools/make-test-bags.py), and the shared pieces
// (ROS1 decoder, tf chains, odometry interpolation, topic choice) on tiny synthetic inputs.

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <ostream>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <limits>
#include <numbers>
#include <string>
#include <vector>

#include "lidar2d/core/error.hpp"
#include "lidar2d/io/frame_source.hpp"
#include "src/io/internal/readers.hpp"
#include "src/io/internal/ros_frames.hpp"
#include "src/io/internal/ros_messages.hpp"
#include "support/test_support.hpp"

namespace lidar2d::io {
namespace {

using ::testing::HasSubstr;
using lidar2d::test::IsNearPose;

constexpr double kInf = std::numeric_limits<double>::infinity();
constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr double kDeg = std::numbers::pi / 180.0;

std::string fixture(const std::string& name) {
  return (std::filesystem::path(__FILE__).parent_path() / "data" / name).string();
}

struct RangeFact {
  std::size_t scan, beam;
  double range;
};
struct OdomFact {
  std::size_t scan;
  double x, y, theta;
};
struct BagFacts {
  const char* file;
  std::size_t scans, beams;
  double t_first, t_last;
  double angle_min, angle_increment, range_min, range_max;
  std::size_t valid_beams;
  SE2 mount;
  std::vector<RangeFact> ranges;
  std::vector<OdomFact> odom;  // empty: the bag has no odometry
  double relation_t1 = 0.0;    // first t1 of the bag's .relations file (0: none)
  bool mount_warning = false;  // no mounting in tf: identity and a warning
};
// gtest prints parameters in test listings; a name instead of a byte dump keeps ctest readable.
[[maybe_unused]] void PrintTo(const BagFacts&, std::ostream* os) { *os << "BagFacts"; }


// Obtained with `/usr/bin/python3 tools/extract-bag-facts.py ../shared/data` (python3-rosbag reads
// the bags; scan time = header stamp; odometry interpolated linearly at the scan stamp, yaw along
// the shorter arc; mounting from /tf_static; ranges are the float32 values widened to double).
// relation_t1 is the first field of the first line of raw/*.relations.
const std::vector<BagFacts> kRos1Bags = {
    // raw/intel.orig.bag: 13631 scans, 2385267 valid beams in total, 0 negative ranges
    {"raw/intel.orig.bag", 13631, 180, 976052857.33753, 976055548.63389,
     -1.5707963705062866, 0.017550798133015633, 0.10000000149011612, 80.0,
     2385267u, SE2(0.0, 0.0, 0.0),
     {{0, 0, 1.0700000524520874}, {0, 60, 2.0}, {0, 90, 17.1200008392334}, {0, 179, 1.0499999523162842},
      {1, 0, 1.0800000429153442}, {1, 60, 2.0}, {1, 90, 17.1200008392334}, {1, 179, 1.0499999523162842},
      {6815, 0, 1.190000057220459}, {6815, 60, 1.059999942779541}, {6815, 90, 1.6399999856948853},
      {6815, 179, 0.6299999952316284}, {13630, 0, 1.0}, {13630, 60, 1.8899999856948853},
      {13630, 90, 17.40999984741211}, {13630, 179, 1.1200000047683716}},
     {{0, 0.0, 0.0, -0.002458},
      {1, 0.0, 0.0, -0.002458},
      {3407, 9.743525184527064, -3.1340603130125753, -2.5454982454551667},
      {6815, 4.989829947220816, -1.994, 0.777103381798777},
      {10223, -6.831729167707241, 14.979586667332635, 2.542102021410852},
      {13630, -50.883999, -35.825001, 2.538102}},
     976052905.167303},
    // raw/fr079.orig.bag: 4934 scans, 1739359 valid beams in total, 0 negative ranges
    {"raw/fr079.orig.bag", 4934, 360, 1211.520329, 2272.970282,
     -1.5707963705062866, 0.008750954642891884, 0.10000000149011612, 80.0,
     1739359u, SE2(0.04, 0.0, 0.0),
     {{0, 0, 1.6699999570846558}, {0, 120, 4.059999942779541}, {0, 180, 10.09000015258789}, {0, 359, 1.0},
      {1, 0, 1.649999976158142}, {1, 120, 4.050000190734863}, {1, 180, 10.09000015258789}, {1, 359, 1.0},
      {2467, 0, 2.0}, {2467, 120, 1.100000023841858}, {2467, 180, 1.3799999952316284}, {2467, 359, 2.0},
      {4933, 0, 6.5}, {4933, 120, 0.9599999785423279}, {4933, 180, 0.7200000286102295}, {4933, 359, 4.25}},
     {{0, -3.034287, 8.291214, -3.120965},
      {1, -3.034772, 8.291204, -3.122499},
      {1233, 12.247968033193382, -13.439504104237423, 2.353300751387593},
      {2467, 30.407568954623873, -7.43703762725235, -2.9874503891754007},
      {3700, 38.725226603479605, -13.07022197665585, 1.8277773277542164},
      {4933, 36.673307, -13.108029, 1.8353100000000002}},
     1216.630413},
    // raw/mit-csail.orig.bag: 1988 scans, 693957 valid beams in total, 0 negative ranges
    {"raw/mit-csail.orig.bag", 1988, 361, 1134864629.895182, 1134865053.892206,
     -1.5707963705062866, 0.008726646192371845, 0.10000000149011612, 80.0,
     693957u, SE2(0.0, 0.0, 0.0),
     {{0, 0, 1.399999976158142}, {0, 120, 3.3499999046325684}, {0, 180, 4.360000133514404},
      {0, 360, 2.700000047683716}, {1, 0, 1.399999976158142}, {1, 120, 3.3499999046325684},
      {1, 180, 4.349999904632568}, {1, 360, 2.700000047683716}, {994, 0, 2.549999952316284},
      {994, 120, 1.3799999952316284}, {994, 180, 1.659999966621399}, {994, 360, 0.44999998807907104},
      {1987, 0, 3.9800000190734863}, {1987, 120, 4.670000076293945}, {1987, 180, 6.360000133514404},
      {1987, 360, 2.2100000381469727}},
     {{0, 576.536523, 0.106594, -2.255213},
      {1, 576.536523, 0.106594, -2.255213},
      {497, 562.662549, -1.877721, -0.5888259999999998},
      {994, 582.553958, -20.760517, 2.744816},
      {1491, 586.140433, -6.612667, -1.071958},
      {1987, 597.816512, -3.220376, -1.412351}},
     1134864645.90321},
    // bags/laser_scan_matcher_demo.bag: 360 scans, 231818 valid beams in total, 0 negative ranges
    // (its index records state a data length that differs from count x 12: all 360 must be read)
    {"bags/laser_scan_matcher_demo.bag", 360, 681, 1282836370.9708765, 1282836406.7867284,
     -2.0862138271331787, 0.006135923322290182, 0.019999999552965164, 5.599999904632568,
     231818u, SE2(0.0, 0.0, 0.0),
     {{0, 0, 3.002000093460083}, {0, 227, 1.1710000038146973}, {0, 340, 0.9419999718666077},
      {0, 680, 2.5759999752044678}, {1, 0, 2.9630000591278076}, {1, 227, 1.184999942779541},
      {1, 340, 0.9419999718666077}, {1, 680, 2.5759999752044678}, {180, 0, 2.6989998817443848},
      {180, 227, 0.007000000216066837}, {180, 340, 5.13700008392334}, {180, 680, 0.8330000042915344},
      {359, 0, 2.88100004196167}, {359, 227, 0.6909999847412109}, {359, 340, 0.4359999895095825},
      {359, 680, 2.117000102996826}},
     {},
     0.0,
     true},
    // bags/laser_scan_sparsifier_demo.bag (bag format 1.2): 123 scans, 61597 valid beams in total
    {"bags/laser_scan_sparsifier_demo.bag", 123, 512, 1275168819.9418864, 1275168832.1100144,
     -1.5707963705062866, 0.006135923322290182, 0.019999999552965164, 5.599999904632568,
     61597u, SE2(0.0, 0.0, 0.0),
     {{0, 0, 2.6459999084472656}, {0, 170, 1.0149999856948853}, {0, 256, 0.9490000009536743},
      {0, 511, 2.3329999446868896}, {1, 0, 2.6489999294281006}, {1, 170, 1.0140000581741333},
      {1, 256, 0.9520000219345093}, {1, 511, 2.3310000896453857}, {61, 0, 2.1630001068115234},
      {61, 170, 0.9890000224113464}, {61, 256, 0.9679999947547913}, {61, 511, 1.8300000429153442},
      {122, 0, 2.128000020980835}, {122, 170, 0.9539999961853027}, {122, 256, 0.949999988079071},
      {122, 511, 1.843000054359436}},
     {},
     0.0,
     true},
};

class Ros1RealBag : public ::testing::TestWithParam<BagFacts> {};

TEST_P(Ros1RealBag, MatchesPythonRosbag) {
  const BagFacts& f = GetParam();
  LIDAR2D_REQUIRE_DATA(f.file);
  const std::string path = test::dataFile(f.file).string();
  auto src = internal::openRosbag1(path, {});
  EXPECT_EQ(src->format(), LogFormat::kRosbag1);
  EXPECT_EQ(src->path(), path);
  std::size_t n = 0, valid = 0;
  double t_last = 0.0;
  bool relation_seen = false;
  while (auto fr = src->next()) {
    ASSERT_EQ(fr->index, n);
    if (n == 0) {
      EXPECT_DOUBLE_EQ(fr->time, f.t_first);
      EXPECT_EQ(fr->scan.size(), f.beams);
      EXPECT_DOUBLE_EQ(fr->scan.angleMin(), f.angle_min);
      EXPECT_DOUBLE_EQ(fr->scan.angleIncrement(), f.angle_increment);
      EXPECT_DOUBLE_EQ(fr->scan.rangeMin(), f.range_min);
      EXPECT_DOUBLE_EQ(fr->scan.rangeMax(), f.range_max);
      EXPECT_TRUE(IsNearPose(f.mount, fr->T_robot_laser, 1e-12, 1e-9));
    }
    EXPECT_DOUBLE_EQ(fr->scan.time(), fr->time);
    EXPECT_FALSE(fr->T_world_robot.has_value());
    EXPECT_EQ(fr->T_odom_robot.has_value(), !f.odom.empty());
    if (f.relation_t1 != 0.0 && std::abs(fr->time - f.relation_t1) < 5e-7) relation_seen = true;
    for (const auto& r : f.ranges) {
      if (r.scan != n) continue;
      ASSERT_LT(r.beam, fr->scan.size());
      if (std::isnan(r.range))
        EXPECT_TRUE(std::isnan(fr->scan.ranges()[r.beam])) << "scan " << n << " beam " << r.beam;
      else
        EXPECT_EQ(fr->scan.ranges()[r.beam], r.range) << "scan " << n << " beam " << r.beam;
    }
    for (const auto& o : f.odom) {
      if (o.scan != n) continue;
      ASSERT_TRUE(fr->T_odom_robot.has_value());
      EXPECT_TRUE(IsNearPose(SE2(o.x, o.y, o.theta), *fr->T_odom_robot, 1e-9, 1e-7)) << "scan " << n;
    }
    valid += fr->scan.numValid();
    t_last = fr->time;
    ++n;
  }
  EXPECT_EQ(n, f.scans);
  EXPECT_DOUBLE_EQ(t_last, f.t_last);
  EXPECT_EQ(valid, f.valid_beams);
  if (f.relation_t1 != 0.0) {
    EXPECT_TRUE(relation_seen) << "no scan at the first relation time " << f.relation_t1;
  }
  EXPECT_FALSE(src->next().has_value());  // stays exhausted

  const SourceNotes notes = src->notes();
  EXPECT_THAT(notes.scan_source, HasSubstr("scan"));
  EXPECT_EQ(notes.odom_source.empty(), f.odom.empty());
  EXPECT_TRUE(notes.truth_source.empty());
  bool mount_warning = false;
  for (const auto& w : notes.warnings) mount_warning |= w.find("identity used") != std::string::npos;
  EXPECT_EQ(mount_warning, f.mount_warning);
  if (!f.mount_warning) {
    EXPECT_THAT(notes.scan_source, HasSubstr("base_link -> laser from /tf_static"));
  }
}

INSTANTIATE_TEST_SUITE_P(SharedData, Ros1RealBag, ::testing::ValuesIn(kRos1Bags),
                         [](const ::testing::TestParamInfo<BagFacts>& info) {
                           std::string name = std::filesystem::path(info.param.file).stem().stem().string();
                           for (auto& c : name)
                             if (!std::isalnum(static_cast<unsigned char>(c))) c = '_';
                           return name;
                         });

TEST(Rosbag1Reader, OpenLogDetectsBothBagFormatVersions) {
  // Bag 2.0 starts with "#ROSBAG V2.0", bag 1.2 with "#ROSRECORD V1.2".
  for (const char* file : {"bags/laser_scan_matcher_demo.bag", "bags/laser_scan_sparsifier_demo.bag"}) {
    if (!std::filesystem::exists(test::dataFile(file))) GTEST_SKIP() << "test data missing";
    EXPECT_EQ(detectFormat(test::dataFile(file).string()), LogFormat::kRosbag1) << file;
  }
}

TEST(Rosbag1Reader, OpenLogReadsAFixture) {
  auto src = openLog(fixture("tf_chain.bag"));
  EXPECT_EQ(src->format(), LogFormat::kRosbag1);
  std::size_t n = 0;
  while (src->next()) ++n;
  EXPECT_EQ(n, 10u);
}

// ---- tests/data/tf_chain.bag (see tools/make-test-bags.py for its exact content) ----

/// Odometry of the fixture at stamp t: x = s, y = 2 s, yaw = 3 + 0.5 s (s = t - 100 in [0, 1]),
/// held at its last value after t = 101.
SE2 fixtureOdometry(double t) {
  const double s = std::min(t - 100.0, 1.0);
  return SE2(s, 2.0 * s, 3.0 + 0.5 * s);
}

TEST(Rosbag1Reader, FixtureChainedTfFromOldStyleTfAndInterpolation) {
  auto src = internal::openRosbag1(fixture("tf_chain.bag"), {});
  std::vector<Frame> frames;
  while (auto f = src->next()) frames.push_back(std::move(*f));
  ASSERT_EQ(frames.size(), 10u);
  for (std::size_t k = 0; k < frames.size(); ++k) {
    const Frame& f = frames[k];
    SCOPED_TRACE(k);
    EXPECT_EQ(f.index, k);
    // Scan 3 has a zero header stamp: its bag time 100.65 is used.
    EXPECT_NEAR(f.time, k == 3 ? 100.65 : 100.04 + 0.2 * static_cast<double>(k), 2e-9);  // 1 ns rounding
    // base_link -> laser_mount (0.10, 0.05, +90 deg) -> laser_front (0.20, 0, -30 deg).
    EXPECT_TRUE(IsNearPose(SE2(0.10, 0.25, 60.0 * kDeg), f.T_robot_laser, 1e-12, 1e-9));
    ASSERT_TRUE(f.T_odom_robot.has_value());
    // Yaw crosses +pi between the odometry messages at 100.2 and 100.3: interpolation must take
    // the short way round.
    EXPECT_TRUE(IsNearPose(fixtureOdometry(f.time), *f.T_odom_robot, 1e-9, 1e-7));
    ASSERT_EQ(f.scan.size(), 8u);
    EXPECT_EQ(f.scan.numValid(), 3u);  // 0.5 + k, 2.0, 3.0
    EXPECT_EQ(f.scan.ranges()[1], -1.0);  // negative: kept, invalid
    EXPECT_FALSE(f.scan.isValid(1));
    EXPECT_TRUE(std::isnan(f.scan.ranges()[2]));
    EXPECT_EQ(f.scan.ranges()[3], kInf);
    EXPECT_FALSE(f.scan.isValid(5));  // == range_max
    EXPECT_DOUBLE_EQ(f.scan.ranges()[0], 0.5 + static_cast<double>(k));
  }
  const SourceNotes notes = src->notes();
  EXPECT_THAT(notes.scan_source, HasSubstr("/scan_front"));
  EXPECT_THAT(notes.scan_source, HasSubstr("base_link -> laser_mount -> laser_front from /tf"));
  EXPECT_THAT(notes.odom_source, HasSubstr("/odom"));
  std::string all;
  for (const auto& w : notes.warnings) all += w + "\n";
  EXPECT_THAT(all, HasSubstr("several LaserScan topics"));
  EXPECT_THAT(all, HasSubstr("/scan_rear (4 messages)"));
  EXPECT_THAT(all, HasSubstr("2 scans are more than 0.5 s"));  // stamps 101.64 and 101.84
  EXPECT_THAT(all, HasSubstr("10 negative ranges"));
  EXPECT_THAT(all, HasSubstr("1 messages have a zero header stamp"));
}

TEST(Rosbag1Reader, FixtureTopicOverrides) {
  ReaderOptions opt;
  opt.scan_topic = "/scan_rear";
  opt.odom_topic = "none";
  auto src = internal::openRosbag1(fixture("tf_chain.bag"), opt);
  std::size_t n = 0;
  while (auto f = src->next()) {
    EXPECT_FALSE(f->T_odom_robot.has_value());
    EXPECT_TRUE(IsNearPose(SE2(), f->T_robot_laser, 0.0, 0.0));
    EXPECT_EQ(f->scan.numValid(), 8u);
    ++n;
  }
  EXPECT_EQ(n, 4u);
  const SourceNotes notes = src->notes();
  EXPECT_THAT(notes.scan_source, HasSubstr("/scan_rear"));
  EXPECT_TRUE(notes.odom_source.empty());
  ASSERT_FALSE(notes.warnings.empty());
  // Without odometry the robot frame is looked up as base_link or base_footprint.
  EXPECT_THAT(notes.warnings.back(), HasSubstr("no transform from 'base_link' or 'base_footprint' to the scans' "
                                               "frame 'laser_rear'"));
}

// ---- shared pieces on synthetic input ----

std::vector<std::uint8_t> ros1Scan() {
  std::vector<std::uint8_t> b;
  auto put = [&](const void* p, std::size_t n) {
    const auto* c = static_cast<const std::uint8_t*>(p);
    b.insert(b.end(), c, c + n);
  };
  auto u32 = [&](std::uint32_t v) { put(&v, 4); };
  auto f32 = [&](float v) { put(&v, 4); };
  u32(7);           // seq
  u32(12);          // sec
  u32(500000000);   // nsec
  u32(6);
  put("/laser", 6);
  for (float v : {-1.0f, 1.0f, 0.5f, 0.0f, 0.1f, 0.05f, 30.0f}) f32(v);
  u32(3);
  for (float v : {1.0f, 2.0f, 3.0f}) f32(v);
  u32(3);
  for (float v : {10.0f, 20.0f, 30.0f}) f32(v);
  return b;
}

TEST(RosMessages, DecodesRos1LaserScan) {
  const auto b = ros1Scan();
  const auto m = internal::decodeLaserScan(b, internal::RosWire::kRos1, {"x.bag", "message 1 on /scan"});
  EXPECT_EQ(m.stamp, 12500000000);
  EXPECT_DOUBLE_EQ(internal::rosSeconds(m.stamp), 12.5);
  EXPECT_EQ(m.frame_id, "laser");  // leading '/' dropped, as tf2 does
  EXPECT_EQ(m.angle_min, -1.0f);
  EXPECT_EQ(m.angle_increment, 0.5f);
  EXPECT_EQ(m.range_max, 30.0f);
  EXPECT_EQ(m.ranges, (std::vector<float>{1.0f, 2.0f, 3.0f}));
  EXPECT_EQ(m.intensities, (std::vector<float>{10.0f, 20.0f, 30.0f}));
}

TEST(RosMessages, EveryTruncationOfARos1ScanIsAnError) {
  const auto b = ros1Scan();
  for (std::size_t n = 0; n < b.size(); ++n) {
    const std::vector<std::uint8_t> cut(b.begin(), b.begin() + static_cast<std::ptrdiff_t>(n));
    try {
      (void)internal::decodeLaserScan(cut, internal::RosWire::kRos1, {"x.bag", "message 4 on /scan"});
      ADD_FAILURE() << "no error for " << n << " bytes";
    } catch (const Error& e) {
      EXPECT_EQ(e.where().file, "x.bag");
      EXPECT_THAT(e.what(), HasSubstr("message 4 on /scan"));
      EXPECT_THAT(e.where().field, HasSubstr("LaserScan."));
    }
  }
}

TEST(RosMessages, HugeArrayLengthIsRejectedBeforeAllocating) {
  auto b = ros1Scan();
  const std::uint32_t huge = 0xFFFFFFF0u;
  std::memcpy(b.data() + 4 * 4 + 6 + 7 * 4, &huge, 4);  // the ranges count
  try {
    (void)internal::decodeLaserScan(b, internal::RosWire::kRos1, {"x.bag", "message 1 on /scan"});
    FAIL() << "no error";
  } catch (const Error& e) {
    EXPECT_EQ(e.where().field, "LaserScan.ranges");
    EXPECT_THAT(e.what(), HasSubstr("states 4294967280 elements"));
  }
}

internal::RosTransformStamped edge(const std::string& parent, const std::string& child, double x, double y,
                                   double yaw, double roll = 0.0) {
  internal::RosTransformStamped t;
  t.parent = parent;
  t.child = child;
  t.transform.tx = x;
  t.transform.ty = y;
  // q = q_yaw * q_roll
  const double cy = std::cos(yaw / 2), sy = std::sin(yaw / 2), cr = std::cos(roll / 2), sr = std::sin(roll / 2);
  t.transform.qw = cy * cr;
  t.transform.qx = cy * sr;
  t.transform.qy = sy * sr;
  t.transform.qz = sy * cr;
  return t;
}

TEST(RosTfTree, ComposesChainsThroughTheCommonAncestor) {
  internal::RosTfTree tree;
  tree.add(edge("odom", "base_link", 5.0, 5.0, 1.0));
  tree.add(edge("base_link", "plate", 0.1, 0.0, std::numbers::pi / 2));
  tree.add(edge("plate", "laser", 0.2, 0.0, -std::numbers::pi / 6));
  tree.add(edge("base_link", "camera", -0.3, 0.1, std::numbers::pi));
  const SE2 T_base_plate(0.1, 0.0, std::numbers::pi / 2), T_plate_laser(0.2, 0.0, -std::numbers::pi / 6),
      T_base_camera(-0.3, 0.1, std::numbers::pi);
  auto l = tree.lookup("base_link", "laser");
  ASSERT_TRUE(l.has_value());
  EXPECT_TRUE(IsNearPose(T_base_plate * T_plate_laser, l->T_from_to, 1e-12, 1e-9));
  EXPECT_EQ(l->chain, (std::vector<std::string>{"base_link", "plate", "laser"}));
  // Reverse direction and a sibling branch (laser -> plate -> base_link -> camera).
  l = tree.lookup("laser", "base_link");
  ASSERT_TRUE(l.has_value());
  EXPECT_TRUE(IsNearPose((T_base_plate * T_plate_laser).inverse(), l->T_from_to, 1e-12, 1e-9));
  l = tree.lookup("laser", "camera");
  ASSERT_TRUE(l.has_value());
  EXPECT_TRUE(IsNearPose((T_base_plate * T_plate_laser).inverse() * T_base_camera, l->T_from_to, 1e-12, 1e-9));
  EXPECT_EQ(l->chain, (std::vector<std::string>{"laser", "plate", "base_link", "camera"}));
  EXPECT_FALSE(tree.lookup("base_link", "nowhere").has_value());
  // A later transform of the same child replaces the earlier one (tf2's static buffer).
  tree.add(edge("plate", "laser", 0.0, 0.0, 0.0));
  EXPECT_TRUE(IsNearPose(T_base_plate, tree.lookup("base_link", "laser")->T_from_to, 1e-12, 1e-9));
}

TEST(RosTfTree, CyclesDoNotHang) {
  internal::RosTfTree tree;
  tree.add(edge("a", "b", 1, 0, 0));
  tree.add(edge("b", "c", 1, 0, 0));
  tree.add(edge("c", "a", 1, 0, 0));
  EXPECT_FALSE(tree.lookup("a", "zzz").has_value());
  EXPECT_TRUE(tree.lookup("a", "c").has_value());
}

TEST(RosTfTree, MountReportsTilt) {
  internal::RosTfTree tree;
  tree.add(edge("base_link", "laser", 0.1, 0.0, 0.3, 0.5));
  const auto m = internal::findRosMount(tree, {"base_link"}, "laser");
  ASSERT_TRUE(m.found);
  EXPECT_NEAR(m.max_tilt, 0.5, 1e-9);
  EXPECT_NEAR(m.T_robot_laser.theta(), 0.3, 1e-9);
  std::vector<std::string> warnings;
  auto copy = m;
  internal::noteRosMount(copy, "/tf_static", {"base_link"}, "laser", warnings);
  ASSERT_EQ(warnings.size(), 1u);
  EXPECT_THAT(warnings[0], HasSubstr("tilted by 28.6 deg"));
}

LaserScan tinyScan(double t) {
  LaserScanFields f;
  f.time = t;
  f.angle_increment = 0.1;
  f.range_max = 10.0;
  f.ranges = {1.0, 2.0};
  return LaserScan::create(f);
}

TEST(RosFrameAssembler, InterpolatesAndHoldsNearest) {
  internal::RosFrameAssembler a(SE2(0.1, 0.0, 0.0), true);
  a.pushScan(tinyScan(0.5), 0.5);  // before the first odometry message (0.7 s away)
  a.pushScan(tinyScan(1.5), 1.5);
  EXPECT_FALSE(a.pop().has_value());  // waits for odometry at or after 0.5
  a.pushOdometry(1.2, SE2(1.0, 0.0, 3.0));
  auto f = a.pop();
  ASSERT_TRUE(f.has_value());
  EXPECT_EQ(f->index, 0u);
  EXPECT_TRUE(IsNearPose(SE2(1.0, 0.0, 3.0), *f->T_odom_robot, 1e-12, 1e-9));
  EXPECT_FALSE(a.pop().has_value());
  a.pushOdometry(2.2, SE2(2.0, 1.0, -3.0));  // yaw crosses pi: +0.283 rad the short way
  f = a.pop();
  ASSERT_TRUE(f.has_value());
  EXPECT_TRUE(IsNearPose(SE2(1.3, 0.3, 3.0 + 0.3 * (2 * std::numbers::pi - 6.0)), *f->T_odom_robot, 1e-12, 1e-9));
  EXPECT_TRUE(IsNearPose(SE2(0.1, 0.0, 0.0), f->T_robot_laser, 0.0, 0.0));
  a.pushScan(tinyScan(3.0), 3.0);  // 0.8 s after the last odometry message
  EXPECT_FALSE(a.pop().has_value());
  a.finish();
  f = a.pop();
  ASSERT_TRUE(f.has_value());
  EXPECT_TRUE(IsNearPose(SE2(2.0, 1.0, -3.0), *f->T_odom_robot, 1e-12, 1e-9));
  EXPECT_FALSE(a.pop().has_value());
  const auto w = a.warnings();
  ASSERT_EQ(w.size(), 1u);
  EXPECT_THAT(w[0], HasSubstr("2 scans are more than 0.5 s (up to 0.800 s)"));
}

TEST(RosFrameAssembler, LookAheadIsBounded) {
  internal::RosFrameAssembler a(SE2(), true);
  a.pushOdometry(0.0, SE2());
  for (std::size_t i = 0; i < internal::RosFrameAssembler::kMaxPendingScans; ++i) {
    a.pushScan(tinyScan(1.0 + static_cast<double>(i)), 1.0 + static_cast<double>(i));
    ASSERT_FALSE(a.pop().has_value());
  }
  a.pushScan(tinyScan(1e4), 1e4);
  auto f = a.pop();
  ASSERT_TRUE(f.has_value());  // the oldest waiting scan is completed with the nearest odometry
  EXPECT_EQ(f->index, 0u);
  EXPECT_TRUE(f->T_odom_robot.has_value());
  EXPECT_FALSE(a.pop().has_value());
}

TEST(RosFrameAssembler, OutOfOrderOdometryIsSorted) {
  internal::RosFrameAssembler a(SE2(), true);
  a.pushOdometry(2.0, SE2(2.0, 0.0, 0.0));
  a.pushOdometry(1.0, SE2(1.0, 0.0, 0.0));
  a.pushScan(tinyScan(1.5), 1.5);
  auto f = a.pop();
  ASSERT_TRUE(f.has_value());
  EXPECT_TRUE(IsNearPose(SE2(1.5, 0.0, 0.0), *f->T_odom_robot, 1e-12, 1e-9));
  EXPECT_THAT(a.warnings().at(0), HasSubstr("1 odometry messages have a stamp earlier"));
}

TEST(RosTopics, ChoosesTheBusiestAndExplainsErrors) {
  const std::vector<internal::RosTopicInfo> topics = {
      {"/a", "sensor_msgs/LaserScan", 5}, {"/b", "sensor_msgs/LaserScan", 9}, {"/odom", "nav_msgs/Odometry", 3}};
  std::vector<std::string> w;
  auto t = internal::chooseRosTopic(topics, {"sensor_msgs/LaserScan"}, "", false, "LaserScan", "--scan-topic", "f.bag", w);
  ASSERT_TRUE(t.has_value());
  EXPECT_EQ(t->name, "/b");
  ASSERT_EQ(w.size(), 1u);
  EXPECT_THAT(w[0], HasSubstr("reading /b"));
  w.clear();
  t = internal::chooseRosTopic(topics, {"sensor_msgs/LaserScan"}, "/a", false, "LaserScan", "--scan-topic", "f.bag", w);
  EXPECT_EQ(t->name, "/a");
  EXPECT_TRUE(w.empty());
  EXPECT_FALSE(internal::chooseRosTopic(topics, {"nav_msgs/Odometry"}, "none", true, "Odometry", "--odom-topic",
                                        "f.bag", w)
                   .has_value());
  try {
    (void)internal::chooseRosTopic(topics, {"sensor_msgs/LaserScan"}, "/odom", false, "LaserScan", "--scan-topic",
                                   "f.bag", w);
    FAIL() << "no error";
  } catch (const Error& e) {
    EXPECT_EQ(e.where().file, "f.bag");
    EXPECT_THAT(e.what(), HasSubstr("topic '/odom' is not a LaserScan topic (it has type nav_msgs/Odometry)"));
    EXPECT_THAT(e.what(), HasSubstr("/b (9 messages), /a (5 messages)"));
  }
}

}  // namespace
}  // namespace lidar2d::io
