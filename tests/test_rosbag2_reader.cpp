// ROS2 (sqlite3 .db3) bag reader: the bag in ../shared/data/ros2 against facts extracted
// independently with python's sqlite3 + struct, synthetic bags written here with libsqlite3, and
// the CDR decoder on every truncation of a message.

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <sqlite3.h>
#include <zstd.h>

#include <Eigen/Geometry>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <limits>
#include <numbers>
#include <set>
#include <string>
#include <vector>

#include "lidar2d/core/error.hpp"
#include "lidar2d/io/frame_source.hpp"
#include "src/io/internal/readers.hpp"
#include "src/io/internal/ros_messages.hpp"
#include "support/test_support.hpp"

namespace lidar2d::io {
namespace {

namespace fs = std::filesystem;
using ::testing::HasSubstr;
using lidar2d::test::IsNearPose;

constexpr double kInf = std::numeric_limits<double>::infinity();
constexpr double kPi = std::numbers::pi;

/// Writes CDR (encapsulation header + fields aligned to their size after it), as rclcpp does.
class CdrWriter {
 public:
  explicit CdrWriter(bool big_endian = false) : be_(big_endian) { b_ = {0, static_cast<std::uint8_t>(be_ ? 0 : 1), 0, 0}; }
  template <typename T>
  CdrWriter& put(T v) {
    while ((b_.size() - 4) % sizeof(T) != 0) b_.push_back(0);
    std::uint8_t c[sizeof(T)];
    std::memcpy(c, &v, sizeof(T));
    if (be_) std::reverse(c, c + sizeof(T));
    b_.insert(b_.end(), c, c + sizeof(T));
    return *this;
  }
  CdrWriter& str(const std::string& s) {
    put<std::uint32_t>(static_cast<std::uint32_t>(s.size() + 1));
    b_.insert(b_.end(), s.begin(), s.end());
    b_.push_back(0);
    return *this;
  }
  CdrWriter& header(double t, const std::string& frame) {
    const auto ns = static_cast<std::int64_t>(std::llround(t * 1e9));
    put<std::int32_t>(static_cast<std::int32_t>(ns / 1000000000));
    put<std::uint32_t>(static_cast<std::uint32_t>(ns % 1000000000));
    return str(frame);
  }
  CdrWriter& pose(double x, double y, double z, double yaw) { return pose(x, y, z, 0.0, 0.0, yaw); }
  /// A pose with its rotation as roll, pitch, yaw (q = q_yaw * q_pitch * q_roll, as tf's setRPY).
  CdrWriter& pose(double x, double y, double z, double roll, double pitch, double yaw) {
    const Eigen::Quaterniond q = Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()) *
                                 Eigen::AngleAxisd(pitch, Eigen::Vector3d::UnitY()) *
                                 Eigen::AngleAxisd(roll, Eigen::Vector3d::UnitX());
    for (double v : {x, y, z, q.x(), q.y(), q.z(), q.w()}) put<double>(v);
    return *this;
  }
  const std::vector<std::uint8_t>& bytes() const { return b_; }

 private:
  bool be_;
  std::vector<std::uint8_t> b_;
};

std::vector<std::uint8_t> cdrScan(double t, const std::string& frame, const std::vector<float>& ranges,
                                  bool big_endian = false, float angle_min = -1.0f) {
  CdrWriter w(big_endian);
  w.header(t, frame);
  for (float v : {angle_min, 0.0f, 0.5f, 0.0f, 0.1f, 0.1f, 20.0f}) w.put<float>(v);
  w.put<std::uint32_t>(static_cast<std::uint32_t>(ranges.size()));
  for (float r : ranges) w.put<float>(r);
  w.put<std::uint32_t>(0);
  return w.bytes();
}

std::vector<std::uint8_t> cdrOdom(double t, double x, double y, double yaw) {
  CdrWriter w;
  w.header(t, "odom").str("base_link").pose(x, y, 0.0, yaw);
  for (int i = 0; i < 36 + 6 + 36; ++i) w.put<double>(0.0);
  return w.bytes();
}

struct Tf {
  std::string parent, child;
  double x, y, z, yaw;
};
std::vector<std::uint8_t> cdrTf(const std::vector<Tf>& tfs) {
  CdrWriter w;
  w.put<std::uint32_t>(static_cast<std::uint32_t>(tfs.size()));
  for (const auto& t : tfs) w.header(1.0, t.parent).str(t.child).pose(t.x, t.y, t.z, t.yaw);
  return w.bytes();
}

/// A rosbag2 sqlite3 database with the recorder's schema.
class TestDb {
 public:
  explicit TestDb(const fs::path& path) {
    if (sqlite3_open(path.c_str(), &db_) != SQLITE_OK) throw std::runtime_error("sqlite3_open");
    exec("CREATE TABLE topics(id INTEGER PRIMARY KEY,name TEXT NOT NULL,type TEXT NOT NULL,"
         "serialization_format TEXT NOT NULL,offered_qos_profiles TEXT NOT NULL);"
         "CREATE TABLE messages(id INTEGER PRIMARY KEY,topic_id INTEGER NOT NULL,timestamp INTEGER NOT NULL, "
         "data BLOB NOT NULL);"
         "CREATE INDEX timestamp_idx ON messages (timestamp ASC);");
  }
  ~TestDb() { sqlite3_close(db_); }
  void exec(const std::string& sql) {
    char* err = nullptr;
    if (sqlite3_exec(db_, sql.c_str(), nullptr, nullptr, &err) != SQLITE_OK) {
      const std::string e = err ? err : "?";
      sqlite3_free(err);
      throw std::runtime_error(e);
    }
  }
  void topic(int id, const std::string& name, const std::string& type) {
    exec("INSERT INTO topics VALUES(" + std::to_string(id) + ",'" + name + "','" + type + "','cdr','')");
  }
  void message(int topic_id, double t, const std::vector<std::uint8_t>& data) {
    sqlite3_stmt* s = nullptr;
    sqlite3_prepare_v2(db_, "INSERT INTO messages(topic_id, timestamp, data) VALUES(?,?,?)", -1, &s, nullptr);
    sqlite3_bind_int(s, 1, topic_id);
    sqlite3_bind_int64(s, 2, std::llround(t * 1e9));
    sqlite3_bind_blob(s, 3, data.data(), static_cast<int>(data.size()), SQLITE_TRANSIENT);
    if (sqlite3_step(s) != SQLITE_DONE) throw std::runtime_error("insert");
    sqlite3_finalize(s);
  }

 private:
  sqlite3* db_ = nullptr;
};

std::set<std::string> listDir(const fs::path& dir) {
  std::set<std::string> names;
  for (const auto& e : fs::directory_iterator(dir)) names.insert(e.path().filename().string());
  return names;
}

// ---- the real bag ----

constexpr const char* kRos2Bag = "ros2/macfirst_floor_take_2";

// Obtained with `/usr/bin/python3 tools/extract-bag-facts.py ../shared/data` (python sqlite3 +
// struct decode the CDR; scan time = header stamp; odometry interpolated linearly at the scan stamp
// with yaw along the shorter arc; mounting base_link -> rplidar_link from /tf_static, the laser
// turned +90 deg). ros2/macfirst_floor_take_2: 357 scans, 195548 valid beams in total.
struct RangeFact {
  std::size_t scan, beam;
  double range;
};
struct OdomFact {
  std::size_t scan;
  double x, y, theta;
};
const std::vector<RangeFact> kRanges = {
    {0, 0, 3.1480000019073486},   {0, 240, 1.2519999742507935},   {0, 360, 0.6340000033378601},
    {0, 719, 3.1519999504089355}, {1, 0, 3.1440000534057617},     {1, 240, 1.25600004196167},
    {1, 360, 0.6359999775886536}, {1, 719, 3.1480000019073486},   {178, 0, 1.777999997138977},
    {178, 240, 2.9800000190734863}, {178, 360, 2.4760000705718994}, {178, 719, 1.777999997138977},
    {356, 0, 1.3459999561309814}, {356, 240, 1.3700000047683716}, {356, 360, kInf},
    {356, 719, 1.340000033378601}};
const std::vector<OdomFact> kOdom = {{0, 6.539614677429199, -8.85838508605957, 1.7054942739898964},
                                     {1, 6.539614677429199, -8.85838508605957, 1.7054942739898964},
                                     {89, 6.56642346384546, -8.608139911415398, 1.2452776336878277},
                                     {178, 7.689699811263716, -9.290436304792436, -1.5021418676466751},
                                     {267, 8.140245950037174, -12.572652547754295, -1.3030799433057862},
                                     {356, 8.138797760009766, -14.681476593017578, -1.0182747769081066}};

/// Reads a whole source and checks it against the facts above.
void checkRealBag(FrameSource& src) {
  std::size_t n = 0, valid = 0;
  double t_last = 0;
  while (auto f = src.next()) {
    ASSERT_EQ(f->index, n);
    if (n == 0) {
      EXPECT_DOUBLE_EQ(f->time, 1663967375.5436065);
      EXPECT_EQ(f->scan.size(), 720u);
      EXPECT_DOUBLE_EQ(f->scan.angleMin(), -3.1241393089294434);
      EXPECT_DOUBLE_EQ(f->scan.angleIncrement(), 0.008714509196579456);
      EXPECT_DOUBLE_EQ(f->scan.rangeMin(), 0.15000000596046448);
      EXPECT_DOUBLE_EQ(f->scan.rangeMax(), 12.0);
    }
    // The RPLidar is mounted turned +90 degrees (base_link -> rplidar_link in /tf_static).
    EXPECT_TRUE(IsNearPose(SE2(0.00393584, 0.0, 1.5707963267948963), f->T_robot_laser, 1e-9, 1e-7));
    EXPECT_FALSE(f->T_world_robot.has_value());
    ASSERT_TRUE(f->T_odom_robot.has_value());
    for (const auto& r : kRanges) {
      if (r.scan == n) {
        EXPECT_EQ(f->scan.ranges()[r.beam], r.range) << "scan " << n << " beam " << r.beam;
      }
    }
    for (const auto& o : kOdom) {
      if (o.scan == n) {
        EXPECT_TRUE(IsNearPose(SE2(o.x, o.y, o.theta), *f->T_odom_robot, 1e-9, 1e-7)) << "scan " << n;
      }
    }
    valid += f->scan.numValid();
    t_last = f->time;
    ++n;
  }
  EXPECT_EQ(n, 357u);
  EXPECT_DOUBLE_EQ(t_last, 1663967421.6997056);
  EXPECT_EQ(valid, 195548u);
  const SourceNotes notes = src.notes();
  EXPECT_THAT(notes.scan_source, HasSubstr("/scan"));
  EXPECT_THAT(notes.scan_source, HasSubstr("base_link -> rplidar_link from /tf_static"));
  EXPECT_THAT(notes.odom_source, HasSubstr("/odom"));
  EXPECT_TRUE(notes.warnings.empty()) << notes.warnings.front();
}

TEST(Rosbag2Reader, RealBagFolderMatchesPythonSqlite) {
  LIDAR2D_REQUIRE_DATA(kRos2Bag);
  const fs::path dir = test::dataFile(kRos2Bag);
  const auto before = listDir(dir);
  auto src = openLog(dir.string());
  EXPECT_EQ(src->format(), LogFormat::kRosbag2);
  EXPECT_EQ(src->path(), dir.string());
  checkRealBag(*src);
  src.reset();
  EXPECT_EQ(listDir(dir), before);  // no -wal / -shm appeared
}

TEST(Rosbag2Reader, Db3FileInAWritableFolderLeavesNoWalOrShm) {
  LIDAR2D_REQUIRE_DATA(kRos2Bag);
  // In the shared (read-only) folder SQLite could not create files anyway; a writable copy shows
  // that the immutable open really writes nothing.
  test::TempDir tmp;
  const fs::path db = tmp / "bag_0.db3";
  fs::copy_file(test::dataFile(kRos2Bag) / "macfirst_floor_take_2_0.db3", db);
  fs::permissions(db, fs::perms::owner_read | fs::perms::owner_write);
  {
    auto src = internal::openRosbag2(db.string(), {});
    checkRealBag(*src);
    EXPECT_EQ(listDir(tmp.path()), std::set<std::string>{"bag_0.db3"});  // not even while open
  }
  EXPECT_EQ(listDir(tmp.path()), std::set<std::string>{"bag_0.db3"});
}

// ---- synthetic bags ----

TEST(Rosbag2Reader, SyntheticBagChainInterpolationBigEndianAndZeroStamp) {
  test::TempDir tmp;
  const fs::path dir = tmp / "bag";
  fs::create_directory(dir);
  test::writeFile(dir / "metadata.yaml",
                  "rosbag2_bagfile_information:\n  version: 4\n  storage_identifier: sqlite3\n"
                  "  relative_file_paths:\n    - bag_0.db3\n  compression_format: \"\"\n");
  {
    TestDb db(dir / "bag_0.db3");
    db.topic(1, "/cmd_vel", "geometry_msgs/msg/Twist");
    db.topic(2, "/scan", "sensor_msgs/msg/LaserScan");
    db.topic(3, "/odom", "nav_msgs/msg/Odometry");
    db.topic(4, "/tf_static", "tf2_msgs/msg/TFMessage");
    db.message(4, 9.0, cdrTf({{"base_link", "plate", 0.0, 0.1, 0.2, kPi / 2}, {"plate", "laser", 0.2, 0.0, 0.0, kPi / 2}}));
    db.message(3, 10.0, cdrOdom(10.0, 0.0, 0.0, 0.0));
    db.message(2, 10.3, cdrScan(10.25, "laser", {1.0f, 2.0f, -3.0f}));
    db.message(1, 10.4, {0, 1, 0, 0});
    db.message(2, 10.8, cdrScan(10.75, "laser", {4.0f, 5.0f, 6.0f}, /*big_endian=*/true));
    db.message(2, 10.9, cdrScan(0.0, "laser", {7.0f, 8.0f, 9.0f}));  // zero stamp: bag time 10.9
    db.message(3, 11.0, cdrOdom(11.0, 1.0, 2.0, 0.2));
  }
  auto src = openLog(dir.string());
  std::vector<Frame> frames;
  while (auto f = src->next()) frames.push_back(std::move(*f));
  ASSERT_EQ(frames.size(), 3u);
  const double times[] = {10.25, 10.75, 10.9};
  const double first_ranges[] = {1.0, 4.0, 7.0};
  for (std::size_t k = 0; k < 3; ++k) {
    SCOPED_TRACE(k);
    EXPECT_NEAR(frames[k].time, times[k], 1e-9);
    EXPECT_EQ(frames[k].scan.ranges()[0], first_ranges[k]);
    EXPECT_FLOAT_EQ(static_cast<float>(frames[k].scan.angleIncrement()), 0.5f);
    // base_link -> plate (0, 0.1, +90 deg) -> laser (0.2, 0, +90 deg) = (0, 0.3, 180 deg)
    EXPECT_TRUE(IsNearPose(SE2(0.0, 0.3, kPi), frames[k].T_robot_laser, 1e-12, 1e-9));
    const double a = times[k] - 10.0;
    ASSERT_TRUE(frames[k].T_odom_robot.has_value());
    EXPECT_TRUE(IsNearPose(SE2(a, 2 * a, 0.2 * a), *frames[k].T_odom_robot, 1e-9, 1e-7));
  }
  EXPECT_FALSE(frames[0].scan.isValid(2));  // negative range
  std::string all;
  for (const auto& w : src->notes().warnings) all += w + "\n";
  EXPECT_THAT(all, HasSubstr("1 negative ranges"));
  EXPECT_THAT(all, HasSubstr("1 messages have a zero header stamp"));
  EXPECT_EQ(listDir(dir), (std::set<std::string>{"bag_0.db3", "metadata.yaml"}));
}

TEST(Rosbag2Reader, NoOdometryAndNoTf) {
  test::TempDir tmp;
  {
    TestDb db(tmp / "b.db3");
    db.topic(1, "/front", "sensor_msgs/msg/LaserScan");
    db.topic(2, "/rear", "sensor_msgs/msg/LaserScan");
    for (int i = 0; i < 3; ++i) db.message(1, 1.0 + i, cdrScan(1.0 + i, "front_laser", {1.0f}));
    db.message(2, 1.5, cdrScan(1.5, "rear_laser", {1.0f}));
  }
  auto src = internal::openRosbag2((tmp / "b.db3").string(), {});
  std::size_t n = 0;
  while (auto f = src->next()) {
    EXPECT_FALSE(f->T_odom_robot.has_value());
    ++n;
  }
  EXPECT_EQ(n, 3u);
  const auto notes = src->notes();
  EXPECT_THAT(notes.scan_source, HasSubstr("/front"));
  ASSERT_EQ(notes.warnings.size(), 2u);
  EXPECT_THAT(notes.warnings[0], HasSubstr("several LaserScan topics"));
  EXPECT_THAT(notes.warnings[1], HasSubstr("laser mounting unknown, identity used"));

  ReaderOptions opt;
  opt.scan_topic = "/rear";
  src = internal::openRosbag2((tmp / "b.db3").string(), opt);
  n = 0;
  while (src->next()) ++n;
  EXPECT_EQ(n, 1u);
}

// ---- split and compressed bags (rosbag2's FILE and MESSAGE modes, compressed here with libzstd's
// ZSTD_compress as rosbag2's zstd compressor does) ----

std::vector<std::uint8_t> zstdCompress(const std::vector<std::uint8_t>& in) {
  std::vector<std::uint8_t> out(ZSTD_compressBound(in.size()));
  const std::size_t n = ZSTD_compress(out.data(), out.size(), in.data(), in.size(), 1);
  if (ZSTD_isError(n)) throw std::runtime_error("ZSTD_compress");
  out.resize(n);
  return out;
}

enum class Mode { kSingle, kSplit, kFile, kMessage };

/// A bag folder with the same messages in each mode: /tf_static, /odom at 10, 11, 12 s and /scan
/// at 10.5 and 11.5 s; split after the first scan (except kSingle and kMessage).
fs::path writeBag(const fs::path& dir, Mode mode) {
  fs::create_directory(dir);
  auto pack = [&](const std::vector<std::uint8_t>& d) { return mode == Mode::kMessage ? zstdCompress(d) : d; };
  const bool split = mode == Mode::kSplit || mode == Mode::kFile;
  std::vector<std::string> files;
  for (int part = 0; part < (split ? 2 : 1); ++part) {
    const std::string name = "bag_" + std::to_string(part) + ".db3";
    {
      TestDb db(dir / name);
      db.topic(1, "/scan", "sensor_msgs/msg/LaserScan");
      db.topic(2, "/odom", "nav_msgs/msg/Odometry");
      db.topic(3, "/tf_static", "tf2_msgs/msg/TFMessage");
      if (part == 0) {
        db.message(3, 9.0, pack(cdrTf({{"base_link", "laser", 0.1, 0.0, 0.0, kPi / 2}})));
        db.message(2, 10.0, pack(cdrOdom(10.0, 0.0, 0.0, 0.0)));
        db.message(1, 10.5, pack(cdrScan(10.5, "laser", {1.0f, 2.0f})));
      }
      if (part == 1 || !split) {
        db.message(2, 11.0, pack(cdrOdom(11.0, 1.0, 0.0, 0.5)));
        db.message(1, 11.5, pack(cdrScan(11.5, "laser", {3.0f, 4.0f})));
        db.message(2, 12.0, pack(cdrOdom(12.0, 2.0, 1.0, 1.0)));
      }
    }
    if (mode == Mode::kFile) {
      const std::string raw = test::readFile(dir / name);
      const auto z = zstdCompress(std::vector<std::uint8_t>(raw.begin(), raw.end()));
      test::writeFile(dir / (name + ".zstd"), std::string(z.begin(), z.end()));
      fs::remove(dir / name);
      files.push_back(name + ".zstd");
    } else {
      files.push_back(name);
    }
  }
  std::string meta = "rosbag2_bagfile_information:\n  version: 5\n  storage_identifier: sqlite3\n  relative_file_paths:\n";
  for (const auto& f : files) meta += "    - " + f + "\n";
  meta += mode == Mode::kFile      ? "  compression_format: zstd\n  compression_mode: FILE\n"
          : mode == Mode::kMessage ? "  compression_format: zstd\n  compression_mode: MESSAGE\n"
                                   : "  compression_format: \"\"\n  compression_mode: \"\"\n";
  test::writeFile(dir / "metadata.yaml", meta);
  return dir;
}

TEST(Rosbag2Reader, SplitAndCompressedDb3BagsGiveTheSameFrames) {
  test::TempDir tmp;
  const char* containers[] = {"sqlite3 storage", "sqlite3 storage, 2 files",
                              "sqlite3 storage, 2 files, zstd-compressed by file",
                              "sqlite3 storage, zstd-compressed by message"};
  for (const Mode mode : {Mode::kSingle, Mode::kSplit, Mode::kFile, Mode::kMessage}) {
    SCOPED_TRACE(static_cast<int>(mode));
    const fs::path dir = writeBag(tmp / ("bag" + std::to_string(static_cast<int>(mode))), mode);
    auto src = openLog(dir.string());
    std::vector<Frame> frames;
    while (auto f = src->next()) frames.push_back(std::move(*f));
    ASSERT_EQ(frames.size(), 2u);
    EXPECT_EQ(src->notes().container, containers[static_cast<int>(mode)]);
    EXPECT_TRUE(src->notes().warnings.empty());
    // Odometry halfway between (0,0,0)-(1,0,0.5) and (1,0,0.5)-(2,1,1); laser turned +90 deg.
    EXPECT_NEAR(frames[0].time, 10.5, 1e-9);
    EXPECT_EQ(frames[0].scan.ranges()[0], 1.0);
    EXPECT_TRUE(IsNearPose(SE2(0.5, 0.0, 0.25), *frames[0].T_odom_robot, 1e-9, 1e-7));
    EXPECT_NEAR(frames[1].time, 11.5, 1e-9);
    EXPECT_EQ(frames[1].scan.ranges()[1], 4.0);
    EXPECT_TRUE(IsNearPose(SE2(1.5, 0.5, 0.75), *frames[1].T_odom_robot, 1e-9, 1e-7));
    EXPECT_TRUE(IsNearPose(SE2(0.1, 0.0, kPi / 2), frames[1].T_robot_laser, 1e-12, 1e-9));
  }
}

// A laser mounted upside down (tf with roll = pi, or with pitch = pi) that sees the same room as an
// upright one at the same place gives the same robot-frame points. The upright laser's beams are at
// -1, -0.5, .., 1 rad; the rolled one's beam b points at -b, so the same layout sees them in reverse
// order; the pitched one's beam b points at pi - b, so its beams start at pi - 1. A tilted laser is
// refused, or read with its ranges shortened when tilts are allowed.
TEST(Rosbag2Reader, UpsideDownLaserGivesTheUprightRobotFramePoints) {
  const std::vector<float> ranges{1.0f, 2.5f, 4.0f, 3.0f, 1.5f};
  const std::vector<float> reversed(ranges.rbegin(), ranges.rend());
  struct Case {
    std::string name;
    double roll, pitch;
    std::vector<float> ranges;
    float angle_min;
  };
  const std::vector<Case> cases{{"upright", 0.0, 0.0, ranges, -1.0f},
                                {"roll", kPi, 0.0, reversed, -1.0f},
                                {"pitch", 0.0, kPi, reversed, static_cast<float>(kPi - 1.0)},
                                {"tilted", 10.0 * kPi / 180, 0.0, ranges, -1.0f}};
  test::TempDir tmp;
  std::vector<std::vector<Frame>> frames;
  for (const auto& c : cases) {
    SCOPED_TRACE(c.name);
    const fs::path db_path = tmp / (c.name + ".db3");
    {
      TestDb db(db_path);
      db.topic(1, "/scan", "sensor_msgs/msg/LaserScan");
      db.topic(2, "/tf_static", "tf2_msgs/msg/TFMessage");
      CdrWriter tf;
      tf.put<std::uint32_t>(1).header(1.0, "base_link").str("laser").pose(0.2, 0.1, 0.3, c.roll, c.pitch, 0.4);
      db.message(2, 1.0, tf.bytes());
      for (int k = 0; k < 3; ++k) db.message(1, 2.0 + k, cdrScan(2.0 + k, "laser", c.ranges, false, c.angle_min));
    }
    if (c.name == "tilted") {
      EXPECT_TRUE(test::throwsError([&] { (void)openLog(db_path.string()); }, ErrorKind::kBadInput,
                                    {"tf base_link -> laser", "tilted by 10.0 deg", "--allow-tilted"}));
      ReaderOptions o;
      o.allow_tilted_laser = true;
      auto src = openLog(db_path.string(), o);
      const auto f = src->next();
      ASSERT_TRUE(f.has_value());
      EXPECT_NEAR(f->laser_tilt_rad, 10.0 * kPi / 180, 1e-9);
      // Rolled by 10 degrees: beam a's direction leaves the plane by asin(sin a sin 10 deg).
      for (std::size_t i = 0; i < ranges.size(); ++i) {
        const double a = -1.0 + 0.5 * static_cast<double>(i), s = std::sin(a) * std::sin(10.0 * kPi / 180);
        EXPECT_NEAR(f->scan.ranges()[i], ranges[i] * std::sqrt(1.0 - s * s), 1e-6) << i;
      }
      EXPECT_THAT(src->notes().warnings.back(), HasSubstr("projected onto the floor plane"));
      continue;
    }
    auto src = openLog(db_path.string());
    frames.emplace_back();
    while (auto f = src->next()) frames.back().push_back(std::move(*f));
    ASSERT_EQ(frames.back().size(), 3u);
    EXPECT_EQ(frames.back()[0].laser_upside_down, c.name != "upright");
    if (c.name != "upright") {
      EXPECT_THAT(src->notes().scan_source, HasSubstr("upside down"));
    }
  }
  ASSERT_EQ(frames.size(), 3u);
  for (std::size_t c = 1; c < frames.size(); ++c) {
    for (std::size_t k = 0; k < 3; ++k) {
      const Points2 up = frames[0][k].scan.toPoints(frames[0][k].T_robot_laser);
      const Points2 flipped = frames[c][k].scan.toPoints(frames[c][k].T_robot_laser);
      ASSERT_EQ(up.size(), ranges.size());
      ASSERT_EQ(flipped.size(), up.size());
      for (std::size_t i = 0; i < up.size(); ++i)
        EXPECT_LT((up[i] - flipped[i]).norm(), 1e-6) << cases[c].name << " scan " << k << " beam " << i;
    }
  }
}

// Two lasers in a ROS2 bag, the rear one upside down (roll pi) and turned back (yaw pi), in a round
// room of radius 2 m centred on the robot: merged (io/laser_merge.hpp), each through its own tf
// mounting and mirror, every point lies on the circle, and both halves are there.
TEST(Rosbag2Reader, TwoLasersOneUpsideDownMergeOntoTheRoom) {
  constexpr double kR = 2.0;
  // Range from (lx, ly) along the robot-frame bearing b to the circle.
  auto circle = [](double lx, double ly, double b) {
    const double cd = lx * std::cos(b) + ly * std::sin(b);
    return -cd + std::sqrt(cd * cd - (lx * lx + ly * ly) + kR * kR);
  };
  auto scan = [](double t, const std::string& frame, const std::vector<float>& ranges) {
    CdrWriter w;
    w.header(t, frame);
    const float inc = static_cast<float>(kPi / 180);
    for (float v : {static_cast<float>(-kPi / 2), static_cast<float>(kPi / 2), inc, 0.0f, 0.1f, 0.05f, 20.0f})
      w.put<float>(v);
    w.put<std::uint32_t>(static_cast<std::uint32_t>(ranges.size()));
    for (float r : ranges) w.put<float>(r);
    w.put<std::uint32_t>(0);
    return w.bytes();
  };
  test::TempDir tmp;
  const fs::path db_path = tmp / "two.db3";
  {
    TestDb db(db_path);
    db.topic(1, "/scan_front", "sensor_msgs/msg/LaserScan");
    db.topic(2, "/scan_rear", "sensor_msgs/msg/LaserScan");
    db.topic(3, "/tf_static", "tf2_msgs/msg/TFMessage");
    CdrWriter tf;
    tf.put<std::uint32_t>(2);
    tf.header(1.0, "base_link").str("front").pose(0.1, 0.0, 0.2, 0.0, 0.0, 0.0);
    tf.header(1.0, "base_link").str("rear").pose(-0.1, 0.05, 0.2, kPi, 0.0, kPi);
    db.message(3, 1.0, tf.bytes());
    std::vector<float> front, rear;
    for (int j = 0; j < 181; ++j) {
      const double a = -kPi / 2 + j * kPi / 180;
      front.push_back(static_cast<float>(circle(0.1, 0.0, a)));
      rear.push_back(static_cast<float>(circle(-0.1, 0.05, kPi - a)));  // Rz(pi) Rx(pi): beam a points at pi - a
    }
    for (int k = 0; k < 3; ++k) {
      db.message(1, 2.0 + 0.1 * k, scan(2.0 + 0.1 * k, "front", front));
      db.message(2, 2.01 + 0.1 * k, scan(2.01 + 0.1 * k, "rear", rear));
    }
  }
  ReaderOptions o;
  o.lasers = {"/scan_front", "/scan_rear"};
  auto src = openLog(db_path.string(), o);
  std::size_t frames = 0;
  while (auto f = src->next()) {
    ASSERT_EQ(f->scan.size(), 360u);
    std::size_t valid = 0;
    for (std::size_t k = 0; k < f->scan.size(); ++k) {
      if (!f->scan.isValid(k)) continue;
      ++valid;
      EXPECT_NEAR(f->scan.ranges()[k], kR, 1e-5) << "beam " << k;
    }
    EXPECT_GT(valid, 340u);  // one laser alone fills at most 181 beams
    ++frames;
  }
  EXPECT_EQ(frames, 3u);
  EXPECT_THAT(src->notes().scan_source, HasSubstr("upside down"));
  EXPECT_EQ(src->notes().lasers.size(), 2u);
}

// ---- CDR decoder ----

TEST(RosMessages, EveryTruncationOfACdrMessageIsAnError) {
  const auto scan = cdrScan(3.5, "laser", {1.0f, 2.0f});
  const auto odom = cdrOdom(3.5, 1.0, 2.0, 0.3);
  const auto tf = cdrTf({{"a", "b", 1.0, 2.0, 3.0, 0.5}});
  const internal::RosMessageRef ref{"bag.db3", "message id 9 on /x"};
  EXPECT_EQ(internal::decodeLaserScan(scan, internal::RosWire::kCdr, ref).ranges, (std::vector<float>{1.0f, 2.0f}));
  EXPECT_DOUBLE_EQ(internal::decodeOdometry(odom, internal::RosWire::kCdr, ref).pose.ty, 2.0);
  EXPECT_EQ(internal::decodeTfMessage(tf, internal::RosWire::kCdr, ref).at(0).child, "b");
  auto expectError = [&](auto decode, const std::vector<std::uint8_t>& full, const char* type) {
    for (std::size_t n = 0; n < full.size(); ++n) {
      const std::vector<std::uint8_t> cut(full.begin(), full.begin() + static_cast<std::ptrdiff_t>(n));
      try {
        (void)decode(cut);
        ADD_FAILURE() << type << ": no error for " << n << " bytes";
      } catch (const Error& e) {
        EXPECT_EQ(e.where().file, "bag.db3");
        EXPECT_THAT(e.what(), HasSubstr("message id 9 on /x"));
        EXPECT_THAT(e.where().field, HasSubstr(type));
      }
    }
  };
  expectError([&](const auto& b) { return internal::decodeLaserScan(b, internal::RosWire::kCdr, ref); }, scan, "LaserScan.");
  expectError([&](const auto& b) { return internal::decodeOdometry(b, internal::RosWire::kCdr, ref); }, odom, "Odometry.");
  expectError([&](const auto& b) { return internal::decodeTfMessage(b, internal::RosWire::kCdr, ref); }, tf, "TFMessage.");
}

TEST(RosMessages, CdrAlignmentIsRelativeToTheEncapsulationHeader) {
  // A 5-character frame id leaves the stream at offset 4 + 8 + 4 + 6 = 22; the first float of the
  // scan must come at 24 (aligned to 4 counting from byte 4), the odometry pose at 4 + 32.
  const auto scan = cdrScan(1.0, "abcde", {9.0f});
  float angle_min = 0;
  std::memcpy(&angle_min, scan.data() + 24, 4);
  EXPECT_EQ(angle_min, -1.0f);
  EXPECT_EQ(internal::decodeLaserScan(scan, internal::RosWire::kCdr, {"f", "m"}).ranges.at(0), 9.0f);
}

}  // namespace
}  // namespace lidar2d::io
