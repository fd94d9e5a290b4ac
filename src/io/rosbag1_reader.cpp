// ROS1 bag reader (bag formats 2.0 and 1.2, uncompressed, bz2 or lz4 chunks) on top of Debian's
// rosbag_storage library: rosbag::Bag/View do the container (records, chunks, indexes, time
// order), our bounds-checked decoders in internal/ros_messages.cpp turn the raw message bytes into
// plain structs (see there why not ros::serialization). No ROS type leaves this file.

#include <console_bridge/console.h>
#include <fmt/format.h>
#include <ros/serialization.h>
#include <rosbag/bag.h>
#include <rosbag/exceptions.h>
#include <rosbag/query.h>
#include <rosbag/view.h>

#include <algorithm>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <memory>
#include <mutex>
#include <new>
#include <optional>
#include <set>
#include <string>
#include <string_view>
#include <vector>

#include "lidar2d/core/error.hpp"
#include "src/io/internal/readers.hpp"
#include "src/io/internal/ros_frames.hpp"
#include "src/io/internal/ros_messages.hpp"

namespace lidar2d::io::internal {
namespace {

constexpr const char* kLaserScanType = "sensor_msgs/LaserScan";
constexpr const char* kOdometryType = "nav_msgs/Odometry";
// MD5 sums of the message definitions our decoders implement (from the .msg files; what rosbag
// stores in each connection header). "*" means "any" in ROS1.
constexpr const char* kLaserScanMd5 = "90c7ef2dc6895d81024acba2ac42f369";
constexpr const char* kOdometryMd5 = "cd5e73d190d741a2f92e81eda573aca7";
constexpr const char* kTfMessageMd5 = "94810edda583a504dfda3829e70d7eec";  // tf2_msgs and tf/tfMessage
// Old bags (before tf2) have no /tf_static and republish static transforms on /tf; read at most this
// much of /tf when looking for the laser mounting.
constexpr double kTfSearchWindowS = 30.0;
constexpr std::size_t kMaxTfMessages = 100000;

void silenceRosLogging() {
  // rosbag_storage logs through console_bridge to stderr; the library must never print.
  static std::once_flag once;
  std::call_once(once, [] { console_bridge::setLogLevel(console_bridge::CONSOLE_BRIDGE_LOG_NONE); });
}

/// Runs `f`, turning rosbag's and ROS's exceptions into lidar2d::Error naming the file.
template <typename F>
auto guarded(const std::string& path, const char* doing, F&& f) -> decltype(f()) {
  try {
    return f();
  } catch (const Error&) {
    throw;
  } catch (const std::bad_alloc&) {
    throw badInput(fmt::format("out of memory while {} (corrupt sizes in the bag?)", doing), {path});
  } catch (const std::exception& e) {
    throw badInput(fmt::format("not a readable ROS1 bag ({}): {}", doing, e.what()), {path});
  }
}

std::vector<std::uint8_t>& rawBytes(const rosbag::MessageInstance& m, std::vector<std::uint8_t>& buf) {
  buf.resize(m.size());
  ros::serialization::OStream s(buf.data(), static_cast<std::uint32_t>(buf.size()));
  m.write(s);
  return buf;
}

/// rosbag needs the index that a bag 2.0 stores at its end; an interrupted recording lacks it and
/// rosbag's own message ("wanted 4 bytes, read 0") does not say so. Throws a clearer error when the
/// file header's index_pos is zero or past the end of the file; returns otherwise.
void explainTruncation(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::string head(4096, '\0');
  in.read(head.data(), static_cast<std::streamsize>(head.size()));
  head.resize(static_cast<std::size_t>(in.gcount()));
  if (head.rfind("#ROSBAG V2.0\n", 0) != 0) return;
  const auto key = head.find("index_pos=");
  if (key == std::string::npos || key + 18 > head.size()) return;
  std::uint64_t index_pos = 0;
  std::memcpy(&index_pos, head.data() + key + 10, sizeof index_pos);
  std::error_code ec;
  const auto size = std::filesystem::file_size(path, ec);
  if (ec) return;
  if (index_pos == 0)
    throw badInput("bag has no index (the recording was not closed); 'rosbag reindex' can rebuild it", {path});
  if (index_pos >= size)
    throw badInput(fmt::format("truncated bag: its index should start at byte {} but the file has {} bytes (an "
                               "interrupted recording or copy? 'rosbag reindex' can rebuild the index)",
                               index_pos, size),
                   {path});
}

// rosbag_storage parses every record header with ros::Header::parse, which checks a field's length
// against 1 MB but not against the header holding it, and so reads past the end of its buffer when
// a length is corrupt (found by fuzzing under AddressSanitizer: a 1.2 bag with one changed byte).
// This pass reads the record headers rosbag will parse, in the order it finds them, and refuses a
// field that overruns its header with an error naming the byte. Format 1.2: the records one after
// another. Format 2.0: the file header, the connection and chunk-info records at its index_pos,
// and each chunk's header and index records; the records inside a chunk stored plain (compression
// none) too, and the index records' entries (`checkIndex`). Compressed (bz2, lz4) chunks are not
// opened here, so damage inside them remains the limitation docs/file-formats.md describes. A
// record cut short by the end of the file, or an index position outside it, ends the pass:
// truncation is rosbag's and `explainTruncation`'s to report.
class RecordHeaderCheck {
 public:
  explicit RecordHeaderCheck(std::string path) : path_(std::move(path)), in_(path_, std::ios::binary) {}

  void run() {
    std::error_code ec;
    size_ = std::filesystem::file_size(path_, ec);
    if (!in_ || ec) return;  // (rosbag's open reports it)
    std::string magic(16, '\0');
    in_.read(magic.data(), 16);
    if (magic.rfind("#ROSRECORD V1.2\n", 0) == 0) {
      for (std::uint64_t pos = 16; pos < size_;) {
        const auto r = record(pos);
        if (!r) return;
        pos = r->end;
      }
    } else if (magic.rfind("#ROSBAG V2.0\n", 0) == 0) {
      const auto head = record(13);
      if (!head) return;
      const std::uint64_t index_pos = number(*head, "index_pos", 8);
      const std::uint64_t records = number(*head, "conn_count", 4) + number(*head, "chunk_count", 4);
      std::vector<std::pair<std::uint64_t, std::uint64_t>> chunks;  // chunk_pos, connections in it
      std::uint64_t pos = index_pos;
      for (std::uint64_t i = 0; i < records && pos < size_; ++i) {
        const auto r = record(pos);
        if (!r) return;
        if (r->op == 0x06) chunks.emplace_back(number(*r, "chunk_pos", 8), number(*r, "count", 4));
        pos = r->end;
      }
      for (const auto& [chunk_pos, connections] : chunks) {
        const auto c = record(chunk_pos);
        if (!c) continue;
        const bool plain = c->compression == "none";
        std::vector<std::uint64_t> starts;  // a plain chunk's record offsets
        if (plain) starts = checkChunk(*c, chunk_pos);
        const std::uint64_t chunk_size = plain ? c->data_len : number(*c, "size", 4);
        std::uint64_t p = c->end;
        for (std::uint64_t k = 0; k < connections && p < size_; ++k) {
          const auto r = record(p);
          if (!r) break;
          if (r->op == 0x04) checkIndex(*r, p, chunk_pos, chunk_size, plain ? &starts : nullptr);
          p = r->end;
        }
      }
    }
  }

 private:
  struct Record {
    std::vector<std::pair<std::string, std::string>> fields;
    int op = -1;
    std::string compression;
    std::uint64_t data_at = 0, data_len = 0, end = 0;
  };

  static std::uint32_t u32(const char* p) {
    std::uint32_t v;
    std::memcpy(&v, p, 4);
    return v;
  }

  // The fields of the header at `h` (`len` bytes), checked; `at` and `where` place it for errors.
  std::vector<std::pair<std::string, std::string>> parseFields(const char* h, std::uint32_t len, std::uint64_t at,
                                                              const std::string& where) const {
    std::vector<std::pair<std::string, std::string>> out;
    for (std::uint32_t q = 0; q < len;) {
      if (len - q < 4 || u32(h + q) > len - q - 4)
        throw badInput(fmt::format("corrupt record header at byte {}{}: a field's length runs past the header's {} bytes",
                                   at, where, len),
                       {path_});
      const std::string_view field(h + q + 4, u32(h + q));
      const std::size_t eq = field.find('=');
      if (eq != std::string_view::npos) out.emplace_back(field.substr(0, eq), field.substr(eq + 1));
      q += 4 + u32(h + q);
    }
    return out;
  }

  // The record at byte `pos`, its header checked; nothing when it is cut short by the end of the file.
  std::optional<Record> record(std::uint64_t pos) {
    if (pos >= size_ || size_ - pos < 8) return std::nullopt;
    char len4[4];
    in_.clear();
    in_.seekg(static_cast<std::streamoff>(pos));
    if (!in_.read(len4, 4)) return std::nullopt;
    const std::uint32_t hlen = u32(len4);
    if (hlen > size_ - pos - 8) return std::nullopt;
    header_.resize(hlen);
    if (!in_.read(header_.data(), hlen) || !in_.read(len4, 4)) return std::nullopt;
    Record r;
    r.fields = parseFields(header_.data(), hlen, pos, "");
    r.data_at = pos + 8 + hlen;
    r.data_len = u32(len4);
    if (r.data_len > size_ - r.data_at) return std::nullopt;
    r.end = r.data_at + r.data_len;
    for (const auto& [name, value] : r.fields) {
      if (name == "op" && value.size() == 1) r.op = static_cast<unsigned char>(value[0]);
      if (name == "compression") r.compression = value;
    }
    return r;
  }

  // A little-endian integer field of `bytes` bytes; 0 when absent or of another size.
  static std::uint64_t number(const Record& r, const char* name, std::size_t bytes) {
    for (const auto& [n, v] : r.fields)
      if (n == name && v.size() == bytes) {
        std::uint64_t x = 0;
        std::memcpy(&x, v.data(), bytes);
        return x;
      }
    return 0;
  }

  // `bytes` bytes of the file from byte `pos`; nothing when they cannot be read.
  std::optional<std::string> bytesAt(std::uint64_t pos, std::uint64_t bytes) {
    std::string data(bytes, '\0');
    in_.clear();
    in_.seekg(static_cast<std::streamoff>(pos));
    if (!in_.read(data.data(), static_cast<std::streamsize>(data.size()))) return std::nullopt;
    return data;
  }

  // The records of a plain chunk, back to back in its data; returns their offsets in it.
  std::vector<std::uint64_t> checkChunk(const Record& c, std::uint64_t chunk_pos) {
    std::vector<std::uint64_t> starts;
    const std::optional<std::string> bytes = bytesAt(c.data_at, c.data_len);
    if (!bytes) return starts;
    const std::string& data = *bytes;
    const std::string where = fmt::format(" of the chunk at byte {}", chunk_pos);
    for (std::uint64_t q = 0; q + 8 <= data.size();) {
      const std::uint32_t hlen = u32(data.data() + q);
      if (hlen > data.size() - q - 8) break;
      (void)parseFields(data.data() + q + 4, hlen, q, where);
      starts.push_back(q);
      q += 8 + hlen + u32(data.data() + q + 4 + hlen);
    }
    return starts;
  }

  // An index record after a chunk (op 0x04, version 1: `count` entries of a time and an offset into
  // the chunk's uncompressed data). rosbag_storage reads a message record at each offset without
  // checking it against the chunk (an offset past the end of a bz2 chunk crashed it: found by
  // damaging a bag's index by hand). So the entries must fit the record, and each offset must leave
  // room for a record in the chunk (`chunk_size` bytes); in a plain chunk it must be where a record
  // starts (`starts`). An offset inside a compressed chunk is not checked further: that would
  // decompress it (docs/file-formats.md).
  void checkIndex(const Record& r, std::uint64_t pos, std::uint64_t chunk_pos, std::uint64_t chunk_size,
                  const std::vector<std::uint64_t>* starts) {
    if (number(r, "ver", 4) != 1) return;  // (rosbag refuses other versions itself)
    const std::uint64_t count = number(r, "count", 4);
    constexpr std::uint64_t kEntry = 12;
    if (count > r.data_len / kEntry)
      throw badInput(fmt::format("corrupt index record at byte {}: {} entries of {} bytes do not fit its {} bytes",
                                 pos, count, kEntry, r.data_len),
                     {path_});
    const std::optional<std::string> data = bytesAt(r.data_at, count * kEntry);
    if (!data) return;
    for (std::uint64_t e = 0; e < count; ++e) {
      const std::uint64_t offset = u32(data->data() + e * kEntry + 8);
      const bool fits = chunk_size >= 8 && offset <= chunk_size - 8;
      if (!fits || (starts && !std::binary_search(starts->begin(), starts->end(), offset)))
        throw badInput(fmt::format("corrupt index record at byte {}: entry {} points to byte {} of the chunk at byte "
                                   "{}, {} (the chunk holds {} bytes)",
                                   pos, e, offset, chunk_pos, fits ? "where no record starts" : "past its end",
                                   chunk_size),
                       {path_});
    }
  }

  std::string path_;
  std::ifstream in_;
  std::uint64_t size_ = 0;
  std::string header_;
};

class Ros1Source final : public FrameSource {
 public:
  Ros1Source(std::string path, const ReaderOptions& options) : path_(std::move(path)), assembler_(SE2(), false) {
    silenceRosLogging();
    RecordHeaderCheck(path_).run();
    try {
      guarded(path_, "opening", [&] { bag_.open(path_, rosbag::bagmode::Read); });
    } catch (const Error&) {
      explainTruncation(path_);
      throw;
    }
    guarded(path_, "reading the index", [&] { setUp(options); });
  }

  std::optional<std::size_t> sizeHint() const override { return size_hint_; }

  std::optional<Frame> next() override {
    return guarded(path_, "reading messages", [&]() -> std::optional<Frame> {
      for (;;) {
        if (auto f = assembler_.pop()) return f;
        if (done_) return std::nullopt;
        if (it_ == view_->end()) {
          assembler_.finish();
          done_ = true;
          continue;
        }
        consume(*it_);
        ++it_;
      }
    });
  }

  LogFormat format() const override { return LogFormat::kRosbag1; }
  const std::string& path() const override { return path_; }

  SourceNotes notes() const override {
    return rosNotes(notes_, assembler_.warnings(), negative_ranges_, zero_stamps_);
  }

 private:
  struct Topic {
    RosTopicInfo info;
    std::set<std::string> md5s;
  };

  std::vector<Topic> listTopics() {
    std::vector<Topic> topics;
    std::map<std::string, std::size_t> by_name;
    rosbag::View all(bag_);
    for (const rosbag::ConnectionInfo* c : all.getConnections()) {
      auto [it, fresh] = by_name.emplace(c->topic, topics.size());
      if (fresh) topics.push_back({{c->topic, c->datatype, 0}, {}});
      topics[it->second].md5s.insert(c->md5sum);
    }
    for (auto& t : topics) {
      rosbag::View v(bag_, rosbag::TopicQuery(t.info.name));
      t.info.count = v.size();
    }
    return topics;
  }

  void checkMd5(const Topic& t, const char* md5) const {
    for (const auto& m : t.md5s)
      if (m != md5 && m != "*")
        throw Error(ErrorKind::kUnsupported,
                    fmt::format("topic {} stores {} with definition md5 {}, not the standard {} (an older or modified "
                                "message definition)",
                                t.info.name, t.info.type, m, md5),
                    {path_});
  }

  /// The first message of a topic, decoded with `decode`.
  template <typename Decode>
  auto firstMessage(const std::string& topic, Decode&& decode) {
    rosbag::View v(bag_, rosbag::TopicQuery(topic));
    std::vector<std::uint8_t> buf;
    using Msg = decltype(decode(std::span<const std::uint8_t>(), RosMessageRef()));
    std::optional<Msg> out;
    const auto it = v.begin();
    if (it != v.end()) out = decode(rawBytes(*it, buf), RosMessageRef{path_, fmt::format("first message on {}", topic)});
    return out;
  }

  void setUp(const ReaderOptions& options) {
    const std::vector<Topic> topics = listTopics();
    std::vector<RosTopicInfo> infos;
    for (const auto& t : topics) infos.push_back(t.info);
    auto find = [&](const std::string& name) -> const Topic& {
      for (const auto& t : topics)
        if (t.info.name == name) return t;
      throw badInput("internal: topic vanished", {path_});
    };

    const RosTopicChoice choice =
        chooseScanAndOdometry(infos, kLaserScanType, kOdometryType, options, path_, notes_.warnings);
    const RosTopicInfo* scan = &choice.scan;
    const std::optional<RosTopicInfo>& odom = choice.odom;
    checkMd5(find(scan->name), kLaserScanMd5);
    scan_topic_ = scan->name;
    size_hint_ = static_cast<std::size_t>(scan->count);

    if (odom) {
      checkMd5(find(odom->name), kOdometryMd5);
      odom_topic_ = odom->name;
    }

    // Frames: the laser frame from the first scan, the robot frame from the first odometry message.
    const auto first_scan = firstMessage(scan_topic_, [](auto bytes, const RosMessageRef& ref) {
      return decodeLaserScan(bytes, RosWire::kRos1, ref);
    });
    const std::string laser_frame = first_scan ? first_scan->frame_id : std::string();
    std::vector<std::string> robot_frames{"base_link", "base_footprint"};
    if (!odom_topic_.empty()) {
      const auto first_odom = firstMessage(odom_topic_, [](auto bytes, const RosMessageRef& ref) {
        return decodeOdometry(bytes, RosWire::kRos1, ref);
      });
      if (first_odom && !first_odom->child_frame_id.empty()) robot_frames = {first_odom->child_frame_id};
    }
    const RosMount mount = findMount(topics, robot_frames, laser_frame);

    notes_.scan_source = fmt::format("{} ({}, frame '{}'{})", scan_topic_, kLaserScanType, laser_frame,
                                     mount.found ? fmt::format(", mounting {}", mount.description) : std::string());
    if (!odom_topic_.empty())
      notes_.odom_source = fmt::format("{} ({} to '{}', interpolated at scan stamps)", odom_topic_, kOdometryType,
                                       robot_frames.front());
    assembler_ = RosFrameAssembler(mount.T_robot_laser, !odom_topic_.empty());

    std::vector<std::string> wanted{scan_topic_};
    if (!odom_topic_.empty()) wanted.push_back(odom_topic_);
    view_ = std::make_unique<rosbag::View>(bag_, rosbag::TopicQuery(wanted));
    it_ = view_->begin();
  }

  RosMount findMount(const std::vector<Topic>& topics, const std::vector<std::string>& robot_frames,
                     const std::string& laser_frame) {
    RosTfTree tree;
    std::vector<std::uint8_t> buf;
    auto tfTopic = [&](const std::string& name) -> const Topic* {
      for (const auto& t : topics)
        if (t.info.name == name && (t.info.type == "tf2_msgs/TFMessage" || t.info.type == "tf/tfMessage") &&
            (t.md5s.count(kTfMessageMd5) || t.md5s.count("*")))
          return &t;
      return nullptr;
    };
    auto addMessage = [&](const rosbag::MessageInstance& m, std::size_t k) {
      const RosMessageRef ref{path_, fmt::format("message {} on {}", k, m.getTopic())};
      for (const auto& t : decodeTfMessage(rawBytes(m, buf), RosWire::kRos1, ref)) tree.add(t);
    };
    RosMount mount;
    std::string source;
    if (const Topic* st = tfTopic("/tf_static"); st && !laser_frame.empty()) {
      rosbag::View v(bag_, rosbag::TopicQuery(st->info.name));
      std::size_t k = 0;
      for (auto it = v.begin(); it != v.end() && k < kMaxTfMessages; ++it) addMessage(*it, ++k);
      mount = findRosMount(tree, robot_frames, laser_frame);
      source = "/tf_static";
    }
    if (const Topic* dyn = tfTopic("/tf"); dyn && !mount.found && !laser_frame.empty()) {
      rosbag::View v(bag_, rosbag::TopicQuery(dyn->info.name));
      std::size_t k = 0;
      std::optional<double> t0;
      for (auto it = v.begin(); it != v.end() && k < kMaxTfMessages; ++it) {
        const double t = it->getTime().toSec();
        if (!t0) t0 = t;
        if (t - *t0 > kTfSearchWindowS) break;
        addMessage(*it, ++k);
        mount = findRosMount(tree, robot_frames, laser_frame);
        if (mount.found) break;
      }
      source = "/tf";
    }
    noteRosMount(mount, source, robot_frames, laser_frame, notes_.warnings);
    return mount;
  }

  void consume(const rosbag::MessageInstance& m) {
    const std::string& topic = m.getTopic();
    const RosNanos bag_time = static_cast<RosNanos>(m.getTime().toNSec());
    if (topic == scan_topic_) {
      ++scan_count_;
      const RosMessageRef ref{path_, fmt::format("message {} on {} (bag time {:.6f})", scan_count_, topic,
                                                 rosSeconds(bag_time))};
      const RosLaserScanMsg msg = decodeLaserScan(rawBytes(m, buf_), RosWire::kRos1, ref);
      RosNanos stamp = msg.stamp;
      if (stamp == 0) {
        ++zero_stamps_;
        stamp = bag_time;
      }
      const double t = rosSeconds(stamp);
      assembler_.pushScan(toLaserScan(msg, t, ref, negative_ranges_), t);
    } else if (topic == odom_topic_) {
      ++odom_count_;
      const RosMessageRef ref{path_, fmt::format("message {} on {} (bag time {:.6f})", odom_count_, topic,
                                                 rosSeconds(bag_time))};
      const RosOdometryMsg msg = decodeOdometry(rawBytes(m, buf_), RosWire::kRos1, ref);
      RosNanos stamp = msg.stamp;
      if (stamp == 0) {
        ++zero_stamps_;
        stamp = bag_time;
      }
      assembler_.pushOdometry(rosSeconds(stamp), projectToPlane(msg.pose));
    }
  }

  std::string path_;
  rosbag::Bag bag_;
  std::unique_ptr<rosbag::View> view_;
  std::optional<std::size_t> size_hint_;
  rosbag::View::iterator it_;
  std::string scan_topic_, odom_topic_;
  RosFrameAssembler assembler_;
  SourceNotes notes_;
  std::vector<std::uint8_t> buf_;
  std::size_t scan_count_ = 0, odom_count_ = 0, negative_ranges_ = 0, zero_stamps_ = 0;
  bool done_ = false;
};

}  // namespace

std::unique_ptr<FrameSource> openRosbag1(const std::string& path, const ReaderOptions& options) {
  return std::make_unique<Ros1Source>(path, options);
}

}  // namespace lidar2d::io::internal
