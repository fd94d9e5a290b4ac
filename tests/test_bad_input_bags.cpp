// Bad ROS bags: each must give one lidar2d::Error naming the file (never a crash, never a partial
// read passed off as complete), and through the CLI exit code 1 with one stderr line naming the
// file and nothing on stdout.

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <sqlite3.h>

#include <filesystem>
#include <fstream>
#include <functional>
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

std::string fixture(const std::string& name) {
  return (fs::path(__FILE__).parent_path() / "data" / name).string();
}

/// Reads the whole source: errors may come at open time or while streaming.
void readAll(const std::function<std::unique_ptr<FrameSource>()>& open) {
  auto src = open();
  while (src->next()) {
  }
}

/// Expects a lidar2d::Error whose message names `file` and contains `text`.
void expectError(const std::function<std::unique_ptr<FrameSource>()>& open, const std::string& file,
                 const std::string& text) {
  try {
    readAll(open);
    ADD_FAILURE() << "no error for " << file;
  } catch (const Error& e) {
    EXPECT_THAT(e.what(), HasSubstr(file));
    EXPECT_THAT(e.what(), HasSubstr(text));
  }
}

/// `lidar2d info PATH [args]` fails with exit 1, one stderr line naming `file` and containing
/// `text`, and no stdout.
void expectCliError(const std::vector<std::string>& args, const std::string& file, const std::string& text) {
  const auto r = test::runCli(args);
  EXPECT_EQ(r.exit_code, 1) << r.err;
  EXPECT_EQ(r.out, "");
  EXPECT_THAT(r.err, HasSubstr(file));
  EXPECT_THAT(r.err, HasSubstr(text));
  ASSERT_FALSE(r.err.empty());
  EXPECT_EQ(r.err.find('\n'), r.err.size() - 1) << "more than one line: " << r.err;
}

void copyPrefix(const fs::path& from, const fs::path& to, std::size_t bytes) {
  std::ifstream in(from, std::ios::binary);
  std::string data(bytes, '\0');
  in.read(data.data(), static_cast<std::streamsize>(bytes));
  data.resize(static_cast<std::size_t>(in.gcount()));
  test::writeFile(to, data);
}

void sql(const fs::path& db_path, const std::string& statements) {
  sqlite3* db = nullptr;
  ASSERT_EQ(sqlite3_open(db_path.c_str(), &db), SQLITE_OK);
  char* err = nullptr;
  const int rc = sqlite3_exec(db, statements.c_str(), nullptr, nullptr, &err);
  EXPECT_EQ(rc, SQLITE_OK) << (err ? err : "");
  sqlite3_free(err);
  sqlite3_close(db);
}

const char* kSchema =
    "CREATE TABLE topics(id INTEGER PRIMARY KEY,name TEXT NOT NULL,type TEXT NOT NULL,"
    "serialization_format TEXT NOT NULL,offered_qos_profiles TEXT NOT NULL);"
    "CREATE TABLE messages(id INTEGER PRIMARY KEY,topic_id INTEGER NOT NULL,timestamp INTEGER NOT NULL,"
    "data BLOB NOT NULL);"
    "INSERT INTO topics VALUES(1,'/scan','sensor_msgs/msg/LaserScan','cdr','');";

// ---- through the CLI ----

TEST(BadBagsCli, NoLaserScanTopic) {
  const std::string f = fixture("no_scan.bag");
  expectCliError({"info", f}, f, "no sensor_msgs/LaserScan topic in the bag (topics: /odom (nav_msgs/Odometry), "
                                 "/chatter (std_msgs/String))");
}

TEST(BadBagsCli, TruncatedBag) {
  LIDAR2D_REQUIRE_DATA("raw/mit-csail.orig.bag");
  test::TempDir tmp;
  const fs::path f = tmp / "cut.bag";
  copyPrefix(test::dataFile("raw/mit-csail.orig.bag"), f, 64 * 1024);
  expectCliError({"info", f.string()}, f.string(), "truncated bag");
}

TEST(BadBagsCli, CorruptFileHeader) {
  LIDAR2D_REQUIRE_DATA("bags/laser_scan_matcher_demo.bag");
  test::TempDir tmp;
  const fs::path f = tmp / "header.bag";
  fs::copy_file(test::dataFile("bags/laser_scan_matcher_demo.bag"), f);
  {
    std::fstream io(f, std::ios::binary | std::ios::in | std::ios::out);
    io.seekp(13);  // just after "#ROSBAG V2.0\n": the file header record's lengths and fields
    const std::string junk(27, '\xff');
    io.write(junk.data(), static_cast<std::streamsize>(junk.size()));
  }
  expectCliError({"info", f.string()}, f.string(), "not a readable ROS1 bag");
}

TEST(BadBagsCli, UnknownScanTopic) {
  const std::string f = fixture("tf_chain.bag");
  expectCliError({"info", f, "--scan-topic", "/nope"}, f,
                 "--scan-topic: no LaserScan topic named '/nope'; LaserScan topics: /scan_front (10 messages), "
                 "/scan_rear (4 messages)");
}

TEST(BadBagsCli, ZeroLengthBag) {
  test::TempDir tmp;
  const fs::path f = tmp / "empty.bag";
  test::writeFile(f, "");
  expectCliError({"info", f.string()}, f.string(), "empty");
}

TEST(BadBagsCli, Ros2FolderWithoutDb3) {
  test::TempDir tmp;
  const fs::path dir = tmp / "bag";
  fs::create_directory(dir);
  test::writeFile(dir / "metadata.yaml", "rosbag2_bagfile_information:\n  version: 4\n  storage_identifier: sqlite3\n");
  expectCliError({"info", dir.string()}, dir.string(), "ROS2 bag folder holds no .db3 file");
}

TEST(BadBagsCli, Db3WithoutTopicsTable) {
  test::TempDir tmp;
  const fs::path f = tmp / "other.db3";
  sql(f, "CREATE TABLE something(a INTEGER); INSERT INTO something VALUES(1);");
  expectCliError({"info", f.string()}, f.string(), "not a ROS2 bag: the database has no 'topics' and 'messages' tables");
}

TEST(BadBagsCli, CorruptMessageInRos1Bag) {
  const std::string f = fixture("corrupt_scan.bag");
  expectCliError({"info", f}, f, "LaserScan.ranges: message 2 on /scan (bag time 5.100000): states 1000 elements");
}

// ---- through the library ----

TEST(BadBags, TruncatedCdrBlob) {
  test::TempDir tmp;
  const fs::path f = tmp / "cut.db3";
  // A LaserScan whose header is complete but which ends inside angle_min.
  sql(f, std::string(kSchema) +
             "INSERT INTO messages VALUES(42,1,1000,x'000100000100000000000000060000006c6173657200000000');");
  try {
    readAll([&] { return internal::openRosbag2(f.string(), {}); });
    FAIL() << "no error";
  } catch (const Error& e) {
    EXPECT_EQ(e.kind(), ErrorKind::kBadInput);
    EXPECT_EQ(e.where().file, f.string());
    EXPECT_EQ(e.where().field, "LaserScan.angle_min");
    EXPECT_THAT(e.what(), HasSubstr("message id 42 on /scan: truncated"));
  }
}

TEST(BadBags, UnsupportedCdrEncapsulation) {
  test::TempDir tmp;
  const fs::path f = tmp / "plcdr.db3";
  sql(f, std::string(kSchema) + "INSERT INTO messages VALUES(7,1,1000,x'000300000000');");
  try {
    readAll([&] { return internal::openRosbag2(f.string(), {}); });
    FAIL() << "no error";
  } catch (const Error& e) {
    EXPECT_EQ(e.kind(), ErrorKind::kUnsupported);
    EXPECT_THAT(e.what(), HasSubstr(f.string()));
    EXPECT_THAT(e.what(), HasSubstr("unsupported CDR encapsulation 00 03"));
  }
}

TEST(BadBags, EmptyDb3) {
  test::TempDir tmp;
  const fs::path f = tmp / "empty.db3";
  test::writeFile(f, "");
  // openLog stops at "file is empty"; the reader itself sees an empty database.
  expectError([&] { return openLog(f.string()); }, f.string(), "file is empty");
  expectError([&] { return internal::openRosbag2(f.string(), {}); }, f.string(), "no 'topics' and 'messages' tables");
}

TEST(BadBags, GarbageAfterSqliteMagic) {
  test::TempDir tmp;
  const fs::path f = tmp / "junk.db3";
  test::writeFile(f, std::string("SQLite format 3\0", 16) + std::string(5000, 'x'));
  expectError([&] { return openLog(f.string()); }, f.string(), "not a readable ROS2 bag database");
}

TEST(BadBags, Ros2UnknownOdomTopicAndNoScan) {
  test::TempDir tmp;
  const fs::path f = tmp / "b.db3";
  sql(f, std::string(kSchema) + "INSERT INTO topics VALUES(2,'/tf','tf2_msgs/msg/TFMessage','cdr','');");
  ReaderOptions opt;
  opt.odom_topic = "/odom";
  expectError([&] { return internal::openRosbag2(f.string(), opt); }, f.string(),
              "--odom-topic: no Odometry topic named '/odom'; Odometry topics: none");
  const fs::path g = tmp / "noscan.db3";
  sql(g, std::string(kSchema).replace(std::string(kSchema).find("sensor_msgs/msg/LaserScan"), 25, "std_msgs/msg/String"));
  expectError([&] { return internal::openRosbag2(g.string(), {}); }, g.string(),
              "no sensor_msgs/msg/LaserScan topic in the bag (topics: /scan (std_msgs/msg/String))");
}

TEST(BadBags, CorruptCompressedChunk) {
  LIDAR2D_REQUIRE_DATA("raw/mit-csail.orig.bag");
  test::TempDir tmp;
  const fs::path f = tmp / "chunk.bag";
  fs::copy_file(test::dataFile("raw/mit-csail.orig.bag"), f);
  fs::permissions(f, fs::perms::owner_read | fs::perms::owner_write);
  {
    std::fstream io(f, std::ios::binary | std::ios::in | std::ios::out);
    io.seekp(5000);  // inside the first bz2 chunk
    const std::string zeros(100, '\0');
    io.write(zeros.data(), static_cast<std::streamsize>(zeros.size()));
  }
  expectError([&] { return openLog(f.string()); }, f.string(), "not a readable ROS1 bag");
}

TEST(BadBags, Ros1UnknownOdomTopicAndWrongTypeScanTopic) {
  const std::string f = fixture("tf_chain.bag");
  ReaderOptions opt;
  opt.odom_topic = "/wheel_odom";
  expectError([&] { return internal::openRosbag1(f, opt); }, f, "no Odometry topic named '/wheel_odom'; Odometry topics: /odom (11 messages)");
  opt = {};
  opt.scan_topic = "/tf";
  expectError([&] { return internal::openRosbag1(f, opt); }, f, "topic '/tf' is not a LaserScan topic (it has type tf2_msgs/TFMessage)");
}

TEST(BadBags, MissingFile) {
  expectError([] { return internal::openRosbag1("/nonexistent/x.bag", {}); }, "/nonexistent/x.bag", "not a readable ROS1 bag");
  expectError([] { return internal::openRosbag2("/nonexistent/x.db3", {}); }, "/nonexistent/x.db3", "cannot open");
}

}  // namespace
}  // namespace lidar2d::io
