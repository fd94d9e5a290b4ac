#pragma once
// The container of a ROS1 bag (formats 2.0 and 1.2): its connections (topic, type, md5sum), the
// index of its messages (time, and where each one is) and the raw bytes of one message; plain,
// bz2 and lz4 (the LZ4 frame format that roslz4 writes) chunks. What a message's bytes mean is
// ros_messages.hpp's business.
//
// Why our own reader instead of Debian's rosbag_storage (which lidar2d used before): rosbag_storage
// trusts the file. It parsed record headers without checking a field's length against the header
// (reading past its buffer; found by fuzzing under AddressSanitizer), and read a message at each
// offset an index record gives without checking it against the chunk (an offset past a bz2 chunk's
// end crashed it). A pass over the file before rosbag could only check what lies outside compressed
// chunks: the records inside them reached rosbag unchecked. Here every length, offset and field is
// checked against the buffer that holds it before it is used, and the format is small (the
// documented format: wiki.ros.org/Bags/Format/2.0 and /1.2).
//
// Every bad file is a lidar2d::Error (ErrorKind::kBadInput) naming the file and the byte.

#include <cstdint>
#include <fstream>
#include <future>
#include <map>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "src/io/internal/ros_messages.hpp"

namespace lidar2d::io::internal {

/// One connection (a topic as published by one node; a topic may have several).
struct Ros1Connection {
  std::uint32_t id = 0;
  std::string topic, type, md5sum;
  std::uint64_t messages = 0;  ///< index entries of this connection
};

/// One message as the bag's index gives it.
struct Ros1Entry {
  RosNanos time = 0;        ///< the bag time (the recorder's receive time), not the header stamp
  std::uint32_t conn = 0;   ///< Ros1Connection::id
  std::uint32_t chunk = 0;  ///< format 2.0: the chunk holding it (0, 1, ... in file order)
  std::uint64_t offset =
      0;  ///< 2.0: its record's byte in the chunk's uncompressed data; 1.2: its data's byte in the file
  std::uint32_t size = 0;  ///< 1.2: its data's length (2.0: from the record)
};

class Ros1Bag {
 public:
  /// Opens `path` and reads its connections and index (format 2.0: the records at the file
  /// header's index_pos and the index records after each chunk; 1.2: every record, one after the
  /// other). Throws lidar2d::Error for a file that is not a ROS1 bag of these formats, is truncated,
  /// or whose records or index do not fit together.
  explicit Ros1Bag(std::string path);
  ~Ros1Bag();
  Ros1Bag(const Ros1Bag&) = delete;
  Ros1Bag& operator=(const Ros1Bag&) = delete;

  const std::string& path() const { return path_; }

  /// Every connection, in the order of their ids (2.0) or of their first appearance (1.2).
  const std::vector<Ros1Connection>& connections() const { return connections_; }

  /// The messages of the connections `ids`, in time order; messages of equal time keep the order in
  /// which they are stored in the file.
  std::vector<Ros1Entry> messages(const std::vector<std::uint32_t>& ids) const;

  /// The serialized message `e` (one of messages()'s). The bytes stay valid until the next call.
  /// Format 2.0 decompresses a chunk the first time one of its messages is read (the last two
  /// chunks are kept, and the next kPrefetch compressed ones are decompressed ahead on other
  /// threads) and checks all of its records and index entries then.
  std::span<const std::uint8_t> read(const Ros1Entry& e);

 private:
  struct Chunk;
  struct CachedChunk;

  void openV20();
  void openV12();
  const CachedChunk& load(std::uint32_t chunk);
  std::vector<std::unique_ptr<CachedChunk>>::iterator cached(std::uint32_t chunk);  ///< cache_.end() if not
  std::unique_ptr<CachedChunk> decode(std::uint32_t chunk, std::vector<std::uint8_t> raw) const;

  static constexpr std::uint32_t kPrefetch = 2;  ///< compressed chunks decompressed ahead of the reads

  std::string path_;
  std::ifstream in_;
  std::uint64_t size_ = 0;
  bool v12_ = false;
  std::vector<Ros1Connection> connections_;
  std::vector<Ros1Entry> entries_;  // all messages, in file order
  std::vector<Chunk> chunks_;       // 2.0
  std::vector<std::unique_ptr<CachedChunk>> cache_;
  std::map<std::uint32_t, std::future<std::unique_ptr<CachedChunk>>> pending_;  // chunks being prefetched
  std::vector<std::uint8_t> buffer_;                                            // 1.2: the last message read
};

}  // namespace lidar2d::io::internal
