// ROS2 bag reader: a bag folder (metadata.yaml listing one or more files) or a single .db3 / .mcap
// file. The storage of each file (sqlite3 or MCAP, internal/ros2_storage.hpp) is recognised by its
// first bytes; the files of a split bag are read one after the other in the order metadata.yaml
// lists them (rosbag2 splits by time). Bags compressed by rosbag2 itself (compression_format zstd)
// are read in both modes: FILE (each listed file is a zstd file, decompressed into a temporary
// folder that is removed with the reader) and MESSAGE (each message's data is a zstd frame). The CDR
// messages are decoded by internal/ros_messages.cpp.
//
// metadata.yaml fields relied on (rosbag2_storage's BagMetadata / yaml.hpp, versions 4 to 9), under
// rosbag2_bagfile_information: storage_identifier ("sqlite3", "mcap"), relative_file_paths (relative
// to the folder; bags of version < 4 wrote them with the folder's name in front, so a path that
// does not exist is also tried as a bare file name), compression_format ("" or "zstd") and
// compression_mode ("", NONE, FILE or MESSAGE, any case, as rosbag2_compression parses it).

#include <fmt/format.h>
#include <stdlib.h>
#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "lidar2d/core/error.hpp"
#include "src/io/internal/decompress.hpp"
#include "src/io/internal/readers.hpp"
#include "src/io/internal/ros2_storage.hpp"
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
/// A message decompressed in MESSAGE mode may be at most this large [bytes].
constexpr std::uint64_t kMaxMessageBytes = std::uint64_t{1} << 30;
/// A file decompressed in FILE mode may be at most this many times its compressed size (plus
/// 64 MiB): recorded sensor data compresses by a few times, a zstd bomb by thousands.
constexpr std::uint64_t kMaxFileRatio = 1000;

enum class Compression { kNone, kFile, kMessage };

/// What a bag path names: its files in reading order, and how rosbag2 compressed them.
struct BagLayout {
  std::vector<fs::path> files;
  Compression compression = Compression::kNone;
  std::string storage;  // storage_identifier from metadata.yaml, "" when not stated
};

std::string yamlString(const YAML::Node& info, const char* key, const std::string& meta) {
  const YAML::Node n = info[key];
  if (!n || n.IsNull()) return "";
  if (!n.IsScalar())
    throw badInput(fmt::format("{} must be a string", key), {meta, static_cast<std::size_t>(n.Mark().line + 1), key});
  return n.as<std::string>();
}

BagLayout readLayout(const std::string& path) {
  std::error_code ec;
  BagLayout layout;
  if (!fs::is_directory(path, ec)) {
    layout.files.push_back(path);
    return layout;
  }
  const fs::path meta = fs::path(path) / "metadata.yaml";
  if (fs::exists(meta, ec)) {
    YAML::Node info;
    try {
      info = YAML::LoadFile(meta.string())["rosbag2_bagfile_information"];
    } catch (const YAML::Exception& e) {
      throw badInput(fmt::format("not a readable rosbag2 metadata file: {}", e.msg),
                     {meta.string(), static_cast<std::size_t>(e.mark.line + 1)});
    }
    if (info) {
      try {
        layout.storage = yamlString(info, "storage_identifier", meta.string());
        if (!layout.storage.empty() && layout.storage != "sqlite3" && layout.storage != "mcap")
          throw Error(ErrorKind::kUnsupported,
                      fmt::format("ROS2 bag storage '{}' is not supported (only sqlite3 and mcap)", layout.storage),
                      {meta.string(), 0, "storage_identifier"});
        const std::string format = yamlString(info, "compression_format", meta.string());
        std::string mode = yamlString(info, "compression_mode", meta.string());
        std::transform(mode.begin(), mode.end(), mode.begin(), [](unsigned char c) { return std::toupper(c); });
        if (mode == "FILE")
          layout.compression = Compression::kFile;
        else if (mode == "MESSAGE")
          layout.compression = Compression::kMessage;
        else if (!mode.empty() && mode != "NONE")
          throw badInput(fmt::format("unknown compression_mode '{}' (rosbag2 writes NONE, FILE or MESSAGE)", mode),
                         {meta.string(), 0, "compression_mode"});
        if (layout.compression != Compression::kNone && format != "zstd")
          throw Error(ErrorKind::kUnsupported,
                      fmt::format("ROS2 bag compression '{}' is not supported (only zstd)", format),
                      {meta.string(), 0, "compression_format"});
        if (const YAML::Node files = info["relative_file_paths"]) {
          if (!files.IsSequence())
            throw badInput("relative_file_paths must be a list of file names",
                           {meta.string(), static_cast<std::size_t>(files.Mark().line + 1), "relative_file_paths"});
          for (const auto& f : files) {
            fs::path p = fs::path(path) / f.as<std::string>();
            if (!fs::exists(p, ec) && fs::exists(fs::path(path) / p.filename(), ec)) p = fs::path(path) / p.filename();
            if (!fs::exists(p, ec))
              throw ioError(fmt::format("no such file: {} (listed in relative_file_paths)", p.string()),
                            {meta.string(), static_cast<std::size_t>(f.Mark().line + 1), "relative_file_paths"});
            layout.files.push_back(p);
          }
        }
      } catch (const YAML::Exception& e) {
        throw badInput(fmt::format("not a readable rosbag2 metadata file: {}", e.msg),
                       {meta.string(), static_cast<std::size_t>(e.mark.line + 1)});
      }
    }
  }
  if (layout.files.empty()) {  // no metadata.yaml, or one without relative_file_paths
    for (const auto& e : fs::directory_iterator(path, ec))
      if (e.path().extension() == ".db3" || e.path().extension() == ".mcap") layout.files.push_back(e.path());
    std::sort(layout.files.begin(), layout.files.end());
  }
  if (layout.files.empty()) throw badInput("ROS2 bag folder holds no .db3 or .mcap file", {path});
  return layout;
}

bool startsWithMcapMagic(const fs::path& file) {
  std::ifstream in(file, std::ios::binary);
  char head[5] = {};
  in.read(head, sizeof head);
  return in.gcount() == 5 && std::memcmp(head, "\x89MCAP", 5) == 0;
}

/// A temporary folder for decompressed files, removed with everything in it when destroyed.
class ScratchDir {
 public:
  ScratchDir() {
    std::string t = (fs::temp_directory_path() / "lidar2d-bag-XXXXXX").string();
    if (!mkdtemp(t.data()))
      throw ioError(fmt::format("cannot create a temporary folder for decompressing: {}", std::strerror(errno)), {t});
    path_ = t;
  }
  ~ScratchDir() {
    std::error_code ec;
    fs::remove_all(path_, ec);
  }
  ScratchDir(const ScratchDir&) = delete;
  ScratchDir& operator=(const ScratchDir&) = delete;
  const fs::path& path() const { return path_; }

 private:
  fs::path path_;
};

class Ros2Source final : public RosMessageSource {
 public:
  Ros2Source(std::string path, const ReaderOptions& options) : RosMessageSource(std::move(path)) {
    const BagLayout layout = readLayout(path_);
    compression_ = layout.compression;
    bool mcap = false;
    for (std::size_t i = 0; i < layout.files.size(); ++i) {
      const fs::path& file = layout.files[i];
      fs::path readable = file;
      if (compression_ == Compression::kFile) {
        if (!scratch_) scratch_.emplace();
        std::error_code ec;
        const std::uint64_t size = fs::file_size(file, ec);
        readable = scratch_->path() / fmt::format("{}_{}", i, file.stem().string());
        decompressZstdFile(file, readable, size * kMaxFileRatio + (std::uint64_t{64} << 20),
                           {"not a readable zstd-compressed bag file (compression_mode FILE): ", {file.string()}});
      }
      const bool is_mcap = startsWithMcapMagic(readable);
      mcap = mcap || is_mcap;
      if (!is_mcap) {
        std::error_code ec;
        if (fs::exists(readable.string() + "-wal", ec) && fs::file_size(readable.string() + "-wal", ec) > 0)
          notes_.warnings.push_back(fmt::format(
              "a -wal file lies beside {}; its messages (not yet checkpointed) are not read", file.filename().string()));
      }
      files_.push_back(is_mcap ? openMcapStorage(readable.string(), file.string())
                               : openSqliteStorage(readable.string(), file.string()));
    }
    const char* how[] = {"", ", zstd-compressed by file", ", zstd-compressed by message"};
    notes_.container = fmt::format("{} storage{}{}", mcap ? "mcap" : "sqlite3",
                                   files_.size() > 1 ? fmt::format(", {} files", files_.size()) : "",
                                   how[static_cast<int>(compression_)]);
    mergeTopics();
    setUp(options);
  }

  LogFormat format() const override { return LogFormat::kRosbag2; }

 private:
  /// A topic over all files of the bag: its index in each file's topics (nullopt where absent).
  struct Topic {
    RosTopicInfo info;
    std::string serialization;
    std::vector<std::optional<std::size_t>> in_file;
  };

  void mergeTopics() {
    for (std::size_t f = 0; f < files_.size(); ++f) {
      const auto& topics = files_[f]->topics();
      for (std::size_t i = 0; i < topics.size(); ++i) {
        const Ros2Topic& t = topics[i];
        auto it = std::find_if(topics_.begin(), topics_.end(), [&](const Topic& m) { return m.info.name == t.info.name; });
        if (it == topics_.end()) {
          topics_.push_back({{t.info.name, t.info.type, 0}, t.serialization, std::vector<std::optional<std::size_t>>(files_.size())});
          it = topics_.end() - 1;
        } else if (it->info.type != t.info.type) {
          throw badInput(fmt::format("topic {} has type {} here but {} in an earlier file of the bag", t.info.name,
                                     t.info.type, it->info.type),
                         {files_[f]->file()});
        }
        it->info.count += t.info.count;
        it->in_file[f] = i;
      }
    }
  }

  void checkCdr(const Topic& t) const {
    if (t.serialization != "cdr")
      throw Error(ErrorKind::kUnsupported,
                  fmt::format("topic {} is serialized as '{}'; only cdr is supported", t.info.name, t.serialization),
                  {path_});
  }

  /// The message's bytes, decompressed in MESSAGE mode (into buffer_).
  std::span<const std::uint8_t> payload(const Ros2Storage& file, const Ros2Message& m) {
    if (compression_ != Compression::kMessage) return m.data;
    buffer_ = decompress(Codec::kZstd, m.data, kMaxMessageBytes, /*exact=*/false,
                         {fmt::format("not a readable zstd-compressed message (compression_mode MESSAGE): the {}: ",
                                      file.where(m)),
                          {file.file()}});
    return buffer_;
  }

  RosMessageRef ref(const Ros2Storage& file, const Ros2Message& m) const { return {file.file(), file.where(m)}; }

  /// Runs `f(ref, time, data)` on the messages of the topics `wanted` (indices into topics_), file
  /// after file, at most `limit`, until f returns false.
  template <typename F>
  void forEachMessage(const std::vector<std::size_t>& wanted, int limit, F&& f) {
    int n = 0;
    for (std::size_t i = 0; i < files_.size(); ++i) {
      Ros2Storage& file = *files_[i];
      std::vector<std::size_t> ids;
      for (const std::size_t t : wanted)
        if (topics_[t].in_file[i]) ids.push_back(*topics_[t].in_file[i]);
      if (ids.empty()) continue;
      file.start(ids);
      Ros2Message m;
      while (file.next(m)) {
        if (n++ >= limit || !f(ref(file, m), m.time, payload(file, m))) return;
      }
    }
  }

  std::size_t indexOf(const Topic& t) const { return static_cast<std::size_t>(&t - topics_.data()); }

  void setUp(const ReaderOptions& options) {
    const auto pick = pickScanAndOdometry(topics_, kLaserScanType, kOdometryType, options, path_, notes_.warnings, notes_.lasers);
    checkCdr(*pick.scan);
    scan_topic_ = indexOf(*pick.scan);
    size_hint_ = static_cast<std::size_t>(pick.scan->info.count);
    if (pick.odom) {
      checkCdr(*pick.odom);
      odom_topic_ = indexOf(*pick.odom);
    }

    std::string laser_frame;
    forEachMessage({scan_topic_}, 1, [&](const RosMessageRef& r, RosNanos, std::span<const std::uint8_t> data) {
      laser_frame = decodeLaserScan(data, RosWire::kCdr, r).frame_id;
      return false;
    });
    std::vector<std::string> robot_frames{"base_link", "base_footprint"};
    if (odom_topic_) {
      forEachMessage({*odom_topic_}, 1, [&](const RosMessageRef& r, RosNanos, std::span<const std::uint8_t> data) {
        const auto m = decodeOdometry(data, RosWire::kCdr, r);
        if (!m.child_frame_id.empty()) robot_frames = {m.child_frame_id};
        return false;
      });
    }
    // A mounting given by the options replaces tf's: tf is not read (openLog applies that one).
    const RosMount mount = options.laser_mount ? RosMount() : findMount(robot_frames, laser_frame);
    describeRosSources(notes_, topics_[scan_topic_].info.name, kLaserScanType, laser_frame, mount,
                       odom_topic_ ? topics_[*odom_topic_].info.name : std::string(), kOdometryType,
                       robot_frames.front());
    assembler_ = RosFrameAssembler(rosFrameMount(mount, options, path_, notes_.warnings), odom_topic_.has_value());
  }

  RosMount findMount(const std::vector<std::string>& robot_frames, const std::string& laser_frame) {
    RosTfTree tree(path_);
    auto tfTopic = [&](const std::string& name) -> std::optional<std::size_t> {
      for (const auto& t : topics_)
        if (t.info.name == name && t.info.type == kTfType && t.serialization == "cdr") return indexOf(t);
      return std::nullopt;
    };
    RosMount mount;
    std::string source;
    if (const auto st = tfTopic("/tf_static"); st && !laser_frame.empty()) {
      forEachMessage({*st}, kMaxTfMessages, [&](const RosMessageRef& r, RosNanos, std::span<const std::uint8_t> data) {
        for (const auto& t : decodeTfMessage(data, RosWire::kCdr, r)) tree.add(t);
        return true;
      });
      mount = findRosMount(tree, robot_frames, laser_frame);
      source = "/tf_static";
    }
    if (const auto dyn = tfTopic("/tf"); dyn && !mount.found && !laser_frame.empty()) {
      std::optional<RosNanos> t0;
      forEachMessage({*dyn}, kMaxTfMessages, [&](const RosMessageRef& r, RosNanos ts, std::span<const std::uint8_t> data) {
        if (!t0) t0 = ts;
        if (static_cast<double>(ts - *t0) * 1e-9 > kTfSearchWindowS) return false;
        for (const auto& t : decodeTfMessage(data, RosWire::kCdr, r)) tree.add(t);
        mount = findRosMount(tree, robot_frames, laser_frame);
        return !mount.found;
      });
      source = "/tf";
    }
    noteRosMount(mount, source, robot_frames, laser_frame, notes_.warnings);
    return mount;
  }

  bool feed() override {
    while (current_ < files_.size()) {
      Ros2Storage& file = *files_[current_];
      if (!streaming_) {
        std::vector<std::size_t> ids;
        for (const std::optional<std::size_t> t : {std::optional<std::size_t>(scan_topic_), odom_topic_})
          if (t && topics_[*t].in_file[current_]) ids.push_back(*topics_[*t].in_file[current_]);
        if (ids.empty()) {
          ++current_;
          continue;
        }
        file.start(ids);
        streaming_ = true;
      }
      Ros2Message m;
      if (!file.next(m)) {
        streaming_ = false;
        ++current_;
        continue;
      }
      const auto data = payload(file, m);
      if (m.topic == topics_[scan_topic_].in_file[current_])
        pushScan(data, RosWire::kCdr, ref(file, m), m.time);
      else
        pushOdometry(data, RosWire::kCdr, ref(file, m), m.time);
      return true;
    }
    return false;
  }

  std::optional<ScratchDir> scratch_;  // declared first: removed after the storages are closed
  std::vector<std::unique_ptr<Ros2Storage>> files_;
  Compression compression_ = Compression::kNone;
  std::vector<Topic> topics_;
  std::size_t scan_topic_ = 0;
  std::optional<std::size_t> odom_topic_;
  std::vector<std::uint8_t> buffer_;
  std::size_t current_ = 0;
  bool streaming_ = false;
};

}  // namespace

std::unique_ptr<FrameSource> openRosbag2(const std::string& path, const ReaderOptions& options) {
  return std::make_unique<Ros2Source>(path, options);
}

}  // namespace lidar2d::io::internal
