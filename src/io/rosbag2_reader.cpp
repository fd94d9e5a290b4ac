// ROS2 bag reader for the sqlite3 storage (rosbag2's default before Iron): Debian 12 packages no
// rosbag2 library, so the .db3 database is read with libsqlite3 and the CDR messages are decoded by
// internal/ros_messages.cpp. Tables (rosbag2_storage_default_plugins, sqlite_statements):
//   topics(id, name, type, serialization_format, offered_qos_profiles)
//   messages(id, topic_id, timestamp, data)   -- timestamp: receive time [ns], data: CDR blob
// The database is opened read-only with the URI parameter immutable=1: the recorder leaves bags in
// WAL mode, and a plain read-only open would still create -wal/-shm files beside them (or fail in a
// read-only folder).

#include <fmt/format.h>
#include <sqlite3.h>
#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <filesystem>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "lidar2d/core/error.hpp"
#include "src/io/internal/readers.hpp"
#include "src/io/internal/ros_frames.hpp"
#include "src/io/internal/ros_messages.hpp"

namespace lidar2d::io::internal {
namespace {

namespace fs = std::filesystem;

constexpr const char* kLaserScanType = "sensor_msgs/msg/LaserScan";
constexpr const char* kOdometryType = "nav_msgs/msg/Odometry";
constexpr const char* kTfType = "tf2_msgs/msg/TFMessage";
constexpr double kTfSearchWindowS = 30.0;  // how much of /tf to search for the mounting (see ROS1)
constexpr int kMaxTfMessages = 100000;

/// The .db3 file of a bag given as a folder (metadata.yaml) or directly as the database file.
fs::path findDatabase(const std::string& path) {
  std::error_code ec;
  if (!fs::is_directory(path, ec)) return path;
  std::vector<fs::path> files;
  const fs::path meta = fs::path(path) / "metadata.yaml";
  if (fs::exists(meta, ec)) {
    try {
      const YAML::Node info = YAML::LoadFile(meta.string())["rosbag2_bagfile_information"];
      if (info) {
        const std::string storage = info["storage_identifier"] ? info["storage_identifier"].as<std::string>() : "";
        if (!storage.empty() && storage != "sqlite3")
          throw Error(ErrorKind::kUnsupported,
                      fmt::format("ROS2 bag storage '{}' is not supported (only sqlite3 .db3 bags)", storage),
                      {meta.string(), 0, "storage_identifier"});
        const std::string compression =
            info["compression_format"] ? info["compression_format"].as<std::string>() : "";
        if (!compression.empty())
          throw Error(ErrorKind::kUnsupported,
                      fmt::format("compressed ROS2 bags ({}) are not supported; decompress with 'ros2 bag convert'",
                                  compression),
                      {meta.string(), 0, "compression_format"});
        for (const auto& f : info["relative_file_paths"]) files.push_back(fs::path(path) / f.as<std::string>());
      }
    } catch (const YAML::Exception&) {
      files.clear();  // unreadable metadata: fall back to the folder's .db3 files
    }
  }
  if (files.empty()) {
    for (const auto& e : fs::directory_iterator(path, ec))
      if (e.path().extension() == ".db3") files.push_back(e.path());
    std::sort(files.begin(), files.end());
  }
  if (files.empty()) throw badInput("ROS2 bag folder holds no .db3 file", {path});
  if (files.size() > 1)
    throw Error(ErrorKind::kUnsupported,
                fmt::format("ROS2 bag split into {} files is not supported (only single-file bags)", files.size()),
                {path});
  if (!fs::exists(files.front(), ec)) throw ioError("no such file (listed in metadata.yaml)", {files.front().string()});
  return files.front();
}

/// "file:" URI of a path with immutable=1 (RFC 3986 escaping of the characters SQLite's URI parser
/// treats specially).
std::string immutableUri(const fs::path& file) {
  std::string uri = "file:";
  for (const unsigned char c : fs::absolute(file).string()) {
    if (c == '%' || c == '?' || c == '#' || c < 0x20 || c >= 0x7f)
      uri += fmt::format("%{:02X}", c);
    else
      uri += static_cast<char>(c);
  }
  uri += "?immutable=1";
  return uri;
}

struct DbCloser {
  void operator()(sqlite3* db) const { sqlite3_close_v2(db); }
};
struct StmtCloser {
  void operator()(sqlite3_stmt* s) const { sqlite3_finalize(s); }
};
using DbPtr = std::unique_ptr<sqlite3, DbCloser>;
using StmtPtr = std::unique_ptr<sqlite3_stmt, StmtCloser>;

class Ros2Source final : public RosMessageSource {
 public:
  Ros2Source(std::string path, const ReaderOptions& options)
      : RosMessageSource(std::move(path)), db_file_(findDatabase(path_).string()) {
    std::error_code ec;
    if (fs::exists(db_file_ + "-wal", ec) && fs::file_size(db_file_ + "-wal", ec) > 0)
      notes_.warnings.push_back(
          "a -wal file lies beside the database; its messages (not yet checkpointed) are not read");
    sqlite3* db = nullptr;
    const int rc = sqlite3_open_v2(immutableUri(db_file_).c_str(), &db, SQLITE_OPEN_READONLY | SQLITE_OPEN_URI, nullptr);
    db_.reset(db);
    if (rc != SQLITE_OK)
      throw ioError(fmt::format("cannot open as SQLite database: {}", db ? sqlite3_errmsg(db) : sqlite3_errstr(rc)),
                    {db_file_});
    setUp(options);
  }

  LogFormat format() const override { return LogFormat::kRosbag2; }

 private:
  bool feed() override {
    const int rc = sqlite3_step(stream_.get());
    if (rc == SQLITE_DONE) {
      stream_.reset();
      return false;
    }
    if (rc != SQLITE_ROW) fail("reading messages");
    consume(stream_.get());
    return true;
  }

  struct Topic {
    std::int64_t id = 0;
    RosTopicInfo info;
    std::string serialization;
  };

  [[noreturn]] void fail(const char* doing) const {
    const int code = sqlite3_errcode(db_.get());
    const std::string msg = fmt::format("{}: {}", doing, sqlite3_errmsg(db_.get()));
    if (code == SQLITE_NOTADB || code == SQLITE_CORRUPT || code == SQLITE_ERROR)
      throw badInput(fmt::format("not a readable ROS2 bag database ({})", msg), {db_file_});
    throw ioError(msg, {db_file_});
  }

  StmtPtr prepare(const std::string& sql, const char* doing) {
    sqlite3_stmt* s = nullptr;
    if (sqlite3_prepare_v2(db_.get(), sql.c_str(), -1, &s, nullptr) != SQLITE_OK) {
      sqlite3_finalize(s);
      fail(doing);
    }
    return StmtPtr(s);
  }

  static std::string text(sqlite3_stmt* s, int col) {
    const auto* p = sqlite3_column_text(s, col);
    return p ? reinterpret_cast<const char*>(p) : "";
  }

  static std::span<const std::uint8_t> blob(sqlite3_stmt* s, int col) {
    const void* p = sqlite3_column_blob(s, col);
    const int n = sqlite3_column_bytes(s, col);
    if (!p || n <= 0) return {};
    return {static_cast<const std::uint8_t*>(p), static_cast<std::size_t>(n)};
  }

  std::vector<Topic> listTopics() {
    // A database without the rosbag2 tables is reported as such rather than as an SQL error.
    {
      auto s = prepare("SELECT name FROM sqlite_master WHERE type='table' AND name IN ('topics','messages')",
                       "reading the schema");
      int tables = 0;
      int rc;
      while ((rc = sqlite3_step(s.get())) == SQLITE_ROW) ++tables;
      if (rc != SQLITE_DONE) fail("reading the schema");
      if (tables < 2) throw badInput("not a ROS2 bag: the database has no 'topics' and 'messages' tables", {db_file_});
    }
    std::vector<Topic> topics;
    auto s = prepare("SELECT id, name, type, serialization_format FROM topics ORDER BY id", "reading the topics");
    int rc;
    while ((rc = sqlite3_step(s.get())) == SQLITE_ROW)
      topics.push_back({sqlite3_column_int64(s.get(), 0), {text(s.get(), 1), text(s.get(), 2), 0}, text(s.get(), 3)});
    if (rc != SQLITE_DONE) fail("reading the topics");
    // One pass over the messages table's topic ids (blobs stay on their overflow pages).
    auto c = prepare("SELECT topic_id, COUNT(*) FROM messages GROUP BY topic_id", "counting messages");
    while ((rc = sqlite3_step(c.get())) == SQLITE_ROW) {
      const std::int64_t id = sqlite3_column_int64(c.get(), 0);
      for (auto& t : topics)
        if (t.id == id) t.info.count = static_cast<std::uint64_t>(sqlite3_column_int64(c.get(), 1));
    }
    if (rc != SQLITE_DONE) fail("counting messages");
    return topics;
  }

  void checkCdr(const Topic& t) const {
    if (t.serialization != "cdr")
      throw Error(ErrorKind::kUnsupported,
                  fmt::format("topic {} is serialized as '{}'; only cdr is supported", t.info.name, t.serialization),
                  {db_file_});
  }

  RosMessageRef ref(std::int64_t id, const std::string& topic) const {
    return {db_file_, fmt::format("message id {} on {}", id, topic)};
  }

  /// Runs `f(id, timestamp, data)` on the messages of one topic in time order, at most `limit`,
  /// until f returns false.
  template <typename F>
  void forEachMessage(const Topic& t, int limit, F&& f) {
    auto s = prepare("SELECT id, timestamp, data FROM messages WHERE topic_id = ?1 ORDER BY timestamp, id LIMIT ?2",
                     "reading messages");
    sqlite3_bind_int64(s.get(), 1, t.id);
    sqlite3_bind_int(s.get(), 2, limit);
    int rc;
    while ((rc = sqlite3_step(s.get())) == SQLITE_ROW)
      if (!f(sqlite3_column_int64(s.get(), 0), sqlite3_column_int64(s.get(), 1), blob(s.get(), 2))) return;
    if (rc != SQLITE_DONE) fail("reading messages");
  }

  void setUp(const ReaderOptions& options) {
    const std::vector<Topic> topics = listTopics();
    const auto pick = pickScanAndOdometry(topics, kLaserScanType, kOdometryType, options, path_, notes_.warnings);
    checkCdr(*pick.scan);
    scan_topic_ = *pick.scan;
    size_hint_ = static_cast<std::size_t>(pick.scan->info.count);
    if (pick.odom) {
      checkCdr(*pick.odom);
      odom_topic_ = *pick.odom;
    }

    std::string laser_frame;
    forEachMessage(scan_topic_, 1, [&](std::int64_t id, std::int64_t, std::span<const std::uint8_t> data) {
      laser_frame = decodeLaserScan(data, RosWire::kCdr, ref(id, scan_topic_.info.name)).frame_id;
      return false;
    });
    std::vector<std::string> robot_frames{"base_link", "base_footprint"};
    if (odom_topic_) {
      forEachMessage(*odom_topic_, 1, [&](std::int64_t id, std::int64_t, std::span<const std::uint8_t> data) {
        const auto m = decodeOdometry(data, RosWire::kCdr, ref(id, odom_topic_->info.name));
        if (!m.child_frame_id.empty()) robot_frames = {m.child_frame_id};
        return false;
      });
    }
    // A mounting given by the options replaces tf's: tf is not read (openLog applies that one).
    const RosMount mount = options.laser_mount ? RosMount() : findMount(topics, robot_frames, laser_frame);
    describeRosSources(notes_, scan_topic_.info.name, kLaserScanType, laser_frame, mount,
                       odom_topic_ ? odom_topic_->info.name : std::string(), kOdometryType, robot_frames.front());
    assembler_ = RosFrameAssembler(rosFrameMount(mount, options, path_, notes_.warnings), odom_topic_.has_value());

    // The recorder's index on timestamp (timestamp_idx) lets SQLite stream this in order without
    // sorting; ties keep insertion order through the id.
    stream_ = prepare("SELECT id, topic_id, timestamp, data FROM messages WHERE topic_id IN (?1, ?2) "
                      "ORDER BY timestamp, id",
                      "reading messages");
    sqlite3_bind_int64(stream_.get(), 1, scan_topic_.id);
    sqlite3_bind_int64(stream_.get(), 2, odom_topic_ ? odom_topic_->id : scan_topic_.id);
  }

  RosMount findMount(const std::vector<Topic>& topics, const std::vector<std::string>& robot_frames,
                     const std::string& laser_frame) {
    RosTfTree tree(path_);
    auto tfTopic = [&](const std::string& name) -> const Topic* {
      for (const auto& t : topics)
        if (t.info.name == name && t.info.type == kTfType && t.serialization == "cdr") return &t;
      return nullptr;
    };
    RosMount mount;
    std::string source;
    if (const Topic* st = tfTopic("/tf_static"); st && !laser_frame.empty()) {
      forEachMessage(*st, kMaxTfMessages, [&](std::int64_t id, std::int64_t, std::span<const std::uint8_t> data) {
        for (const auto& t : decodeTfMessage(data, RosWire::kCdr, ref(id, st->info.name))) tree.add(t);
        return true;
      });
      mount = findRosMount(tree, robot_frames, laser_frame);
      source = "/tf_static";
    }
    if (const Topic* dyn = tfTopic("/tf"); dyn && !mount.found && !laser_frame.empty()) {
      std::optional<std::int64_t> t0;
      forEachMessage(*dyn, kMaxTfMessages, [&](std::int64_t id, std::int64_t ts, std::span<const std::uint8_t> data) {
        if (!t0) t0 = ts;
        if (static_cast<double>(ts - *t0) * 1e-9 > kTfSearchWindowS) return false;
        for (const auto& t : decodeTfMessage(data, RosWire::kCdr, ref(id, dyn->info.name))) tree.add(t);
        mount = findRosMount(tree, robot_frames, laser_frame);
        return !mount.found;
      });
      source = "/tf";
    }
    noteRosMount(mount, source, robot_frames, laser_frame, notes_.warnings);
    return mount;
  }

  void consume(sqlite3_stmt* s) {
    const std::int64_t id = sqlite3_column_int64(s, 0);
    const std::int64_t topic_id = sqlite3_column_int64(s, 1);
    const RosNanos bag_time = sqlite3_column_int64(s, 2);
    const auto data = blob(s, 3);
    if (topic_id == scan_topic_.id) {
      pushScan(data, RosWire::kCdr, ref(id, scan_topic_.info.name), bag_time);
    } else if (odom_topic_ && topic_id == odom_topic_->id) {
      pushOdometry(data, RosWire::kCdr, ref(id, odom_topic_->info.name), bag_time);
    }
  }

  std::string db_file_;
  DbPtr db_;
  StmtPtr stream_;
  Topic scan_topic_;
  std::optional<Topic> odom_topic_;
};

}  // namespace

std::unique_ptr<FrameSource> openRosbag2(const std::string& path, const ReaderOptions& options) {
  return std::make_unique<Ros2Source>(path, options);
}

}  // namespace lidar2d::io::internal
