// rosbag2's sqlite3 storage (rosbag2's default before Iron): Debian 12 packages no rosbag2 library,
// so the .db3 database is read with libsqlite3. Tables (rosbag2_storage_default_plugins,
// sqlite_statements):
//   topics(id, name, type, serialization_format, offered_qos_profiles)
//   messages(id, topic_id, timestamp, data)   -- timestamp: receive time [ns], data: CDR blob
// The database is opened read-only with the URI parameter immutable=1: the recorder leaves bags in
// WAL mode, and a plain read-only open would still create -wal/-shm files beside them (or fail in a
// read-only folder).

#include <fmt/format.h>
#include <sqlite3.h>

#include <filesystem>
#include <memory>

#include "lidar2d/core/error.hpp"
#include "src/io/internal/ros2_storage.hpp"

namespace lidar2d::io::internal {
namespace {

namespace fs = std::filesystem;

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

class SqliteStorage final : public Ros2Storage {
 public:
  SqliteStorage(const std::string& path, const std::string& display) : display_(display) {
    sqlite3* db = nullptr;
    const int rc = sqlite3_open_v2(immutableUri(path).c_str(), &db, SQLITE_OPEN_READONLY | SQLITE_OPEN_URI, nullptr);
    db_.reset(db);
    if (rc != SQLITE_OK)
      throw ioError(fmt::format("cannot open as SQLite database: {}", db ? sqlite3_errmsg(db) : sqlite3_errstr(rc)),
                    {display_});
    listTopics();
  }

  const std::string& file() const override { return display_; }
  const std::vector<Ros2Topic>& topics() const override { return topics_; }

  void start(const std::vector<std::size_t>& topics) override {
    // The recorder's index on timestamp (timestamp_idx) lets SQLite stream this in order without
    // sorting; ties keep insertion order through the id.
    std::string ids;
    for (const std::size_t t : topics) {
      if (!ids.empty()) ids += ',';
      ids += std::to_string(ids_.at(t));
    }
    stream_ = prepare("SELECT id, topic_id, timestamp, data FROM messages WHERE topic_id IN (" + ids +
                          ") ORDER BY timestamp, id",
                      "reading messages");
  }

  bool next(Ros2Message& m) override {
    if (!stream_) return false;
    const int rc = sqlite3_step(stream_.get());
    if (rc == SQLITE_DONE) {
      stream_.reset();
      return false;
    }
    if (rc != SQLITE_ROW) fail("reading messages");
    sqlite3_stmt* s = stream_.get();
    id_ = sqlite3_column_int64(s, 0);
    const std::int64_t topic_id = sqlite3_column_int64(s, 1);
    m.topic = topics_.size();
    for (std::size_t i = 0; i < ids_.size(); ++i)
      if (ids_[i] == topic_id) m.topic = i;
    m.time = sqlite3_column_int64(s, 2);
    m.data = blob(s, 3);
    return true;
  }

  std::string where(const Ros2Message& m) const override {
    return fmt::format("message id {} on {}", id_, topics_.at(m.topic).info.name);
  }

 private:
  [[noreturn]] void fail(const char* doing) const {
    const int code = sqlite3_errcode(db_.get());
    const std::string msg = fmt::format("{}: {}", doing, sqlite3_errmsg(db_.get()));
    if (code == SQLITE_NOTADB || code == SQLITE_CORRUPT || code == SQLITE_ERROR)
      throw badInput(fmt::format("not a readable ROS2 bag database ({})", msg), {display_});
    throw ioError(msg, {display_});
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

  void listTopics() {
    // A database without the rosbag2 tables is reported as such rather than as an SQL error.
    {
      auto s = prepare("SELECT name FROM sqlite_master WHERE type='table' AND name IN ('topics','messages')",
                       "reading the schema");
      int tables = 0;
      int rc;
      while ((rc = sqlite3_step(s.get())) == SQLITE_ROW) ++tables;
      if (rc != SQLITE_DONE) fail("reading the schema");
      if (tables < 2) throw badInput("not a ROS2 bag: the database has no 'topics' and 'messages' tables", {display_});
    }
    auto s = prepare("SELECT id, name, type, serialization_format FROM topics ORDER BY id", "reading the topics");
    int rc;
    while ((rc = sqlite3_step(s.get())) == SQLITE_ROW) {
      ids_.push_back(sqlite3_column_int64(s.get(), 0));
      Ros2Topic topic;
      topic.info.name = text(s.get(), 1);
      topic.info.type = text(s.get(), 2);
      topic.serialization = text(s.get(), 3);
      topics_.push_back(std::move(topic));
    }
    if (rc != SQLITE_DONE) fail("reading the topics");
    // One pass over the messages table's topic ids (blobs stay on their overflow pages).
    auto c = prepare("SELECT topic_id, COUNT(*) FROM messages GROUP BY topic_id", "counting messages");
    while ((rc = sqlite3_step(c.get())) == SQLITE_ROW) {
      const std::int64_t id = sqlite3_column_int64(c.get(), 0);
      for (std::size_t i = 0; i < ids_.size(); ++i)
        if (ids_[i] == id) topics_[i].info.count = static_cast<std::uint64_t>(sqlite3_column_int64(c.get(), 1));
    }
    if (rc != SQLITE_DONE) fail("counting messages");
  }

  std::string display_;
  DbPtr db_;
  StmtPtr stream_;
  std::vector<Ros2Topic> topics_;
  std::vector<std::int64_t> ids_;  // topic id of each entry of topics_
  std::int64_t id_ = 0;            // message id of the last message
};

}  // namespace

std::unique_ptr<Ros2Storage> openSqliteStorage(const std::string& path, const std::string& display) {
  return std::make_unique<SqliteStorage>(path, display);
}

}  // namespace lidar2d::io::internal
