// ROS1 bag reader (bag formats 2.0 and 1.2, uncompressed, bz2 or lz4 chunks): internal/ros1_bag.cpp
// reads the container (records, chunks, index, time order; see there why not Debian's
// rosbag_storage), the bounds-checked decoders in internal/ros_messages.cpp turn the raw message
// bytes into plain structs, and internal/ros_frames.cpp pairs scans with odometry and the mounting.

#include <fmt/format.h>

#include <algorithm>
#include <cstdint>
#include <map>
#include <memory>
#include <optional>
#include <set>
#include <span>
#include <string>
#include <vector>

#include "lidar2d/core/error.hpp"
#include "src/io/internal/readers.hpp"
#include "src/io/internal/ros1_bag.hpp"
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

class Ros1Source final : public RosMessageSource {
 public:
  Ros1Source(std::string path, const ReaderOptions& options) : RosMessageSource(std::move(path)), bag_(path_) {
    setUp(options);
  }

  LogFormat format() const override { return LogFormat::kRosbag1; }

 private:
  bool feed() override {
    if (next_ == view_.size()) return false;
    consume(view_[next_++]);
    return true;
  }

  struct Topic {
    RosTopicInfo info;
    std::set<std::string> md5s;
    std::vector<std::uint32_t> connections;
  };

  /// The topics in the order of their first connection.
  std::vector<Topic> listTopics() const {
    std::vector<Topic> topics;
    std::map<std::string, std::size_t> by_name;
    for (const Ros1Connection& c : bag_.connections()) {
      auto [it, fresh] = by_name.emplace(c.topic, topics.size());
      if (fresh) topics.push_back({{c.topic, c.type, 0}, {}, {}});
      Topic& t = topics[it->second];
      t.md5s.insert(c.md5sum);
      t.connections.push_back(c.id);
      t.info.count += c.messages;
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
  /// (Taken from view_, which holds the topic's messages in time order.)
  auto firstMessage(const Topic& topic, Decode&& decode) {
    using Msg = decltype(decode(std::span<const std::uint8_t>(), RosMessageRef()));
    std::optional<Msg> out;
    const auto first = std::find_if(view_.begin(), view_.end(), [&](const Ros1Entry& e) {
      return std::find(topic.connections.begin(), topic.connections.end(), e.conn) != topic.connections.end();
    });
    if (first != view_.end())
      out = decode(bag_.read(*first), RosMessageRef{path_, fmt::format("first message on {}", topic.info.name)});
    return out;
  }

  void setUp(const ReaderOptions& options) {
    const std::vector<Topic> topics = listTopics();
    const auto pick = pickScanAndOdometry(topics, kLaserScanType, kOdometryType, options, path_, notes_.warnings, notes_.lasers);
    const Topic& scan = *pick.scan;
    checkMd5(scan, kLaserScanMd5);
    scan_topic_ = scan.info.name;
    size_hint_ = static_cast<std::size_t>(scan.info.count);
    std::vector<std::uint32_t> wanted = scan.connections;
    scan_connections_ = scan.connections;

    const Topic* odom = pick.odom;
    if (odom) {
      checkMd5(*odom, kOdometryMd5);
      odom_topic_ = odom->info.name;
      wanted.insert(wanted.end(), odom->connections.begin(), odom->connections.end());
    }

    view_ = bag_.messages(wanted);

    // Frames: the laser frame from the first scan, the robot frame from the first odometry message.
    const auto first_scan = firstMessage(
        scan, [](auto bytes, const RosMessageRef& ref) { return decodeLaserScan(bytes, RosWire::kRos1, ref); });
    const std::string laser_frame = first_scan ? first_scan->frame_id : std::string();
    std::vector<std::string> robot_frames{"base_link", "base_footprint"};
    if (odom) {
      const auto first_odom = firstMessage(
          *odom, [](auto bytes, const RosMessageRef& ref) { return decodeOdometry(bytes, RosWire::kRos1, ref); });
      if (first_odom && !first_odom->child_frame_id.empty()) robot_frames = {first_odom->child_frame_id};
    }
    // A mounting given by the options replaces tf's: tf is not read (openLog applies that one).
    const RosMount mount = options.laser_mount ? RosMount() : findMount(topics, robot_frames, laser_frame);

    describeRosSources(notes_, scan_topic_, kLaserScanType, laser_frame, mount, odom ? odom_topic_ : std::string(),
                       kOdometryType, robot_frames.front());
    assembler_ = RosFrameAssembler(rosFrameMount(mount, options, path_, notes_.warnings), odom != nullptr);
  }

  RosMount findMount(const std::vector<Topic>& topics, const std::vector<std::string>& robot_frames,
                     const std::string& laser_frame) {
    RosTfTree tree(path_);
    auto tfTopic = [&](const std::string& name) -> const Topic* {
      for (const auto& t : topics)
        if (t.info.name == name && (t.info.type == "tf2_msgs/TFMessage" || t.info.type == "tf/tfMessage") &&
            (t.md5s.count(kTfMessageMd5) || t.md5s.count("*")))
          return &t;
      return nullptr;
    };
    auto addMessage = [&](const Ros1Entry& m, const std::string& topic, std::size_t k) {
      const RosMessageRef ref{path_, fmt::format("message {} on {}", k, topic)};
      for (const auto& t : decodeTfMessage(bag_.read(m), RosWire::kRos1, ref)) tree.add(t);
    };
    RosMount mount;
    std::string source;
    if (const Topic* st = tfTopic("/tf_static"); st && !laser_frame.empty()) {
      const std::vector<Ros1Entry> messages = bag_.messages(st->connections);
      for (std::size_t k = 0; k < messages.size() && k < kMaxTfMessages; ++k)
        addMessage(messages[k], st->info.name, k + 1);
      mount = findRosMount(tree, robot_frames, laser_frame);
      source = "/tf_static";
    }
    if (const Topic* dyn = tfTopic("/tf"); dyn && !mount.found && !laser_frame.empty()) {
      const std::vector<Ros1Entry> messages = bag_.messages(dyn->connections);
      for (std::size_t k = 0; k < messages.size() && k < kMaxTfMessages; ++k) {
        if (rosSeconds(messages[k].time) - rosSeconds(messages.front().time) > kTfSearchWindowS) break;
        addMessage(messages[k], dyn->info.name, k + 1);
        mount = findRosMount(tree, robot_frames, laser_frame);
        if (mount.found) break;
      }
      source = "/tf";
    }
    noteRosMount(mount, source, robot_frames, laser_frame, notes_.warnings);
    return mount;
  }

  void consume(const Ros1Entry& m) {
    const bool is_scan =
        std::find(scan_connections_.begin(), scan_connections_.end(), m.conn) != scan_connections_.end();
    const std::string& topic = is_scan ? scan_topic_ : odom_topic_;
    const std::size_t count = is_scan ? ++scan_count_ : ++odom_count_;
    const RosMessageRef ref{path_, fmt::format("message {} on {} (bag time {:.6f})", count, topic, rosSeconds(m.time))};
    if (is_scan) {
      pushScan(bag_.read(m), RosWire::kRos1, ref, m.time);
    } else {
      pushOdometry(bag_.read(m), RosWire::kRos1, ref, m.time);
    }
  }

  Ros1Bag bag_;
  std::vector<Ros1Entry> view_;  // the scan and odometry messages, in time order
  std::size_t next_ = 0;
  std::string scan_topic_, odom_topic_;
  std::vector<std::uint32_t> scan_connections_;
  std::size_t scan_count_ = 0, odom_count_ = 0;
};

}  // namespace

std::unique_ptr<FrameSource> openRosbag1(const std::string& path, const ReaderOptions& options) {
  return std::make_unique<Ros1Source>(path, options);
}

}  // namespace lidar2d::io::internal
