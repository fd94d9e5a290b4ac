#pragma once
// A reader of MCAP files (the published specification, mcap.dev/spec, major version 0), the
// default storage of rosbag2 since ROS 2 Iron. Debian 12 packages no MCAP library, so this is our
// own reader of the documented format: it scans the records in file order, which works the same
// with or without a summary section, chunk index or message indexes (it uses none of them).
//
// What is checked, each failure one lidar2d::Error (kBadInput, or kUnsupported for a valid file
// lidar2d cannot read) naming the file, the byte offset of the record and its field: the leading
// and trailing magic, every record's length against the file's size (a truncated file), the
// Header as first record, chunk compression ("", "zstd", "lz4" (LZ4 frame format); anything else is
// unsupported), a chunk's stated uncompressed size (at most kMaxChunkBytes, and exactly what the
// data decompresses to), the chunk CRC32, the data section CRC32 (Data End) and the summary CRC32
// (Footer) when the writer stored them (0 = not stored), channel and schema references, and the
// Footer followed by the closing magic at the very end of the file.

#include <cstdint>
#include <fstream>
#include <map>
#include <span>
#include <string>
#include <vector>

namespace lidar2d::io::internal {

/// A channel (a topic with its encoding) and the name of its schema (rosbag2: the ROS message
/// type, e.g. "sensor_msgs/msg/LaserScan"; empty when the channel has no schema).
struct McapChannel {
  std::uint16_t id = 0;
  std::string topic;
  std::string message_encoding;  ///< e.g. "cdr"
  std::string schema_name;
  std::string schema_encoding;  ///< e.g. "ros2msg"
};

/// A Message record. `data` stays valid until the next call of McapReader::next.
struct McapMessage {
  const McapChannel* channel = nullptr;
  std::uint32_t sequence = 0;
  std::uint64_t log_time = 0;      ///< [ns]
  std::uint64_t publish_time = 0;  ///< [ns]
  std::span<const std::uint8_t> data;
  std::uint64_t record_offset = 0;  ///< byte offset of the record in the file, or of its chunk
  std::uint64_t chunk_offset = 0;   ///< offset of the record in its chunk's records (when in_chunk)
  bool in_chunk = false;
};

/// Reads the messages of one MCAP file in file order, with bounded memory (one record, or one
/// decompressed chunk, at a time).
class McapReader {
 public:
  /// Largest chunk (uncompressed) accepted [bytes]; writers use about 1 MiB (rosbag2: 768 KiB).
  static constexpr std::uint64_t kMaxChunkBytes = std::uint64_t{1} << 30;

  /// Opens `path` and reads the leading magic and the Header record; throws lidar2d::Error naming
  /// `display` (the file as the user knows it) when it is not an MCAP file.
  McapReader(const std::string& path, std::string display);

  /// The next Message record, or false at the end of the file (after the Footer and the closing
  /// magic were checked). Throws lidar2d::Error on malformed content.
  bool next(McapMessage& m);

  /// "message at byte N" or "message at byte M of the chunk at byte N", for errors.
  static std::string where(const McapMessage& m);

  const std::string& file() const { return file_; }
  /// The Header's profile ("ros2" for rosbag2).
  const std::string& profile() const { return profile_; }

 private:
  struct RecordHead {
    std::uint8_t op = 0;
    std::uint64_t offset = 0;  // of the opcode byte
    std::uint64_t length = 0;  // of the content
  };
  bool readHead(RecordHead& h);
  void readContent(const RecordHead& h, std::vector<std::uint8_t>& out);
  void skipContent(const RecordHead& h);
  void readBytes(std::uint8_t* out, std::uint64_t n, std::uint64_t at, const char* what);
  void checksum(const std::uint8_t* p, std::size_t n);

  void onSchema(std::span<const std::uint8_t> content, std::uint64_t offset);
  void onChannel(std::span<const std::uint8_t> content, std::uint64_t offset);
  void parseMessage(std::span<const std::uint8_t> content, McapMessage& m) const;
  void loadChunk(const RecordHead& h);
  bool nextInChunk(McapMessage& m);
  void onDataEnd(const RecordHead& h);
  void onFooter(const RecordHead& h);

  std::string file_;
  std::ifstream in_;
  std::uint64_t size_ = 0;
  std::uint64_t pos_ = 0;  // next byte to read
  std::string profile_;

  struct Schema {
    std::string name, encoding;
  };
  std::map<std::uint16_t, Schema> schemas_;
  std::map<std::uint16_t, McapChannel> channels_;

  std::vector<std::uint8_t> record_;  // content of the last record read
  std::vector<std::uint8_t> chunk_;   // decompressed records of the current chunk
  std::uint64_t chunk_record_offset_ = 0;
  std::uint64_t chunk_pos_ = 0;
  bool in_chunk_ = false;

  // CRC32 of the data section (from the first byte of the file up to Data End) and of the summary
  // (after Data End up to the Footer's summary_crc field).
  unsigned long data_crc_ = 0, summary_crc_ = 0;
  bool in_summary_ = false;
  bool done_ = false;
};

}  // namespace lidar2d::io::internal
