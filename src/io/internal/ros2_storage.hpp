#pragma once
// One file of a rosbag2 bag, whatever its storage: the sqlite3 database (.db3, rosbag2's default
// before Iron) or MCAP (.mcap, the default since Iron). The ROS2 reader (rosbag2_reader.cpp) chains
// the files of a split bag and decodes the messages; a storage only lists topics and yields
// serialized messages.

#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "src/io/internal/ros_frames.hpp"
#include "src/io/internal/ros_messages.hpp"

namespace lidar2d::io::internal {

/// A topic of a storage file: name, ROS type ("sensor_msgs/msg/LaserScan"), message count, and the
/// serialization format ("cdr").
struct Ros2Topic {
  RosTopicInfo info;
  std::string serialization;
};

/// A serialized message: its topic (index into Ros2Storage::topics()), receive time and bytes
/// (valid until the next call of Ros2Storage::next).
struct Ros2Message {
  std::size_t topic = 0;
  RosNanos time = 0;
  std::span<const std::uint8_t> data;
};

class Ros2Storage {
 public:
  virtual ~Ros2Storage() = default;
  /// The file as the user knows it (for errors); for a file decompressed from `bag_0.db3.zstd`, that name.
  virtual const std::string& file() const = 0;
  /// Every topic of the file with its message count.
  virtual const std::vector<Ros2Topic>& topics() const = 0;
  /// Starts a new pass over the messages of `topics` (indices into topics()): .db3 in receive-time
  /// order, .mcap in file order (rosbag2 writes in receive order).
  virtual void start(const std::vector<std::size_t>& topics) = 0;
  /// The next message of the pass, or false at its end. Throws lidar2d::Error on malformed content.
  virtual bool next(Ros2Message& m) = 0;
  /// Where the last message of next() is, for errors: "message id 17 on /scan",
  /// "message at byte 120 of the chunk at byte 9000 on /scan".
  virtual std::string where(const Ros2Message& m) const = 0;
};

/// Opens the sqlite3 database `path`; errors name `display`.
std::unique_ptr<Ros2Storage> openSqliteStorage(const std::string& path, const std::string& display);
/// Opens the MCAP file `path` and counts its messages in one pass; errors name `display`.
std::unique_ptr<Ros2Storage> openMcapStorage(const std::string& path, const std::string& display);

}  // namespace lidar2d::io::internal
