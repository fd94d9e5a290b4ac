// rosbag2's MCAP storage (rosbag2_storage_mcap): one channel per topic and publisher, the schema
// name is the ROS type ("sensor_msgs/msg/LaserScan"), message_encoding the serialization ("cdr"),
// log_time the receive time [ns]. Counting the messages takes one pass over the file (the
// Statistics record is optional and not trusted); each later pass reopens the file.

#include <fmt/format.h>

#include <limits>
#include <map>
#include <optional>

#include "lidar2d/core/error.hpp"
#include "src/io/internal/mcap.hpp"
#include "src/io/internal/ros2_storage.hpp"

namespace lidar2d::io::internal {
namespace {

class McapStorage final : public Ros2Storage {
 public:
  McapStorage(const std::string& path, const std::string& display) : path_(path), display_(display) {
    McapReader reader(path_, display_);
    McapMessage m;
    while (reader.next(m)) ++topics_[topicOf(*m.channel, reader)].info.count;
  }

  const std::string& file() const override { return display_; }
  const std::vector<Ros2Topic>& topics() const override { return topics_; }

  void start(const std::vector<std::size_t>& topics) override {
    wanted_.assign(topics_.size(), false);
    for (const std::size_t t : topics) wanted_.at(t) = true;
    reader_.emplace(path_, display_);
  }

  bool next(Ros2Message& out) override {
    while (reader_ && reader_->next(m_)) {
      const std::size_t t = topicOf(*m_.channel, *reader_);
      if (!wanted_[t]) continue;
      if (m_.log_time > static_cast<std::uint64_t>(std::numeric_limits<RosNanos>::max()))
        throw badInput(fmt::format("the {} has a log_time of {} ns, beyond the year 2262", McapReader::where(m_),
                                   m_.log_time),
                       {display_, 0, "Message.log_time"});
      out = {t, static_cast<RosNanos>(m_.log_time), m_.data};
      return true;
    }
    reader_.reset();
    return false;
  }

  std::string where(const Ros2Message& m) const override {
    return fmt::format("{} on {}", McapReader::where(m_), topics_.at(m.topic).info.name);
  }

 private:
  /// The topic index of a channel; a channel seen for the first time joins its topic (several
  /// publishers of a topic have a channel each; they must agree on the type).
  std::size_t topicOf(const McapChannel& c, const McapReader& reader) {
    if (const auto it = by_channel_.find(c.id); it != by_channel_.end()) return it->second;
    std::size_t t = topics_.size();
    for (std::size_t i = 0; i < topics_.size(); ++i)
      if (topics_[i].info.name == c.topic) t = i;
    if (t == topics_.size()) {
      Ros2Topic topic;
      topic.info.name = c.topic;
      topic.info.type = c.schema_name;
      topic.serialization = c.message_encoding;
      topics_.push_back(std::move(topic));
    } else if (topics_[t].info.type != c.schema_name || topics_[t].serialization != c.message_encoding) {
      throw badInput(fmt::format("not a readable rosbag2 MCAP file: topic {} has channels of type {} ({}) and {} ({})",
                                 c.topic, topics_[t].info.type, topics_[t].serialization, c.schema_name,
                                 c.message_encoding),
                     {reader.file(), 0, fmt::format("Channel {}", c.id)});
    }
    by_channel_[c.id] = t;
    return t;
  }

  std::string path_, display_;
  std::vector<Ros2Topic> topics_;
  std::map<std::uint16_t, std::size_t> by_channel_;
  std::vector<bool> wanted_;
  std::optional<McapReader> reader_;
  McapMessage m_;
};

}  // namespace

std::unique_ptr<Ros2Storage> openMcapStorage(const std::string& path, const std::string& display) {
  return std::make_unique<McapStorage>(path, display);
}

}  // namespace lidar2d::io::internal
