// The ROS1 bag container (src/io/internal/ros1_bag.cpp) on bags written here byte by byte: plain,
// bz2 and lz4 chunks read alike and in time order, and crafted damage inside a chunk (which the
// compression hides from any check that does not decompress it) gives one clear error naming the
// file and the byte, for every compression. The real bags are read in test_rosbag1_reader.cpp.

#include <bzlib.h>
#include <fmt/format.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <lz4frame.h>

#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <string>
#include <vector>

#include "lidar2d/core/error.hpp"
#include "lidar2d/io/frame_source.hpp"
#include "src/io/internal/readers.hpp"
#include "src/io/internal/ros1_bag.hpp"
#include "support/test_support.hpp"

namespace lidar2d::io {
namespace {

using ::testing::HasSubstr;

std::string le32(std::uint32_t v) { return std::string(reinterpret_cast<const char*>(&v), 4); }
std::string le64(std::uint64_t v) { return std::string(reinterpret_cast<const char*>(&v), 8); }
std::string f32(float v) { return std::string(reinterpret_cast<const char*>(&v), 4); }
std::string str(const std::string& s) { return le32(static_cast<std::uint32_t>(s.size())) + s; }
std::string field(const std::string& name, const std::string& value) { return str(name + "=" + value); }
std::string op(int code) { return std::string(1, static_cast<char>(code)); }
std::string record(const std::string& header, const std::string& data) { return str(header) + str(data); }
std::string time(std::uint32_t sec, std::uint32_t nsec) { return le32(sec) + le32(nsec); }

/// A ROS1-serialized sensor_msgs/LaserScan: 4 beams from -45 deg in 30 deg steps.
std::string laserScan(std::uint32_t seq, std::uint32_t sec, std::uint32_t nsec, const std::vector<float>& ranges) {
  std::string m = le32(seq) + time(sec, nsec) + str("laser");
  for (float v : {-0.785398f, 0.785398f, 0.523599f, 0.0f, 0.1f, 0.05f, 30.0f}) m += f32(v);
  m += le32(static_cast<std::uint32_t>(ranges.size()));
  for (float r : ranges) m += f32(r);
  return m + le32(0);
}

std::string bz2(const std::string& in) {
  std::vector<char> out(in.size() + in.size() / 100 + 600);
  auto len = static_cast<unsigned>(out.size());
  EXPECT_EQ(BZ2_bzBuffToBuffCompress(out.data(), &len, const_cast<char*>(in.data()), static_cast<unsigned>(in.size()),
                                     9, 0, 0),
            BZ_OK);
  return std::string(out.data(), len);
}

std::string lz4(const std::string& in) {
  std::string out(LZ4F_compressFrameBound(in.size(), nullptr), '\0');
  const std::size_t len = LZ4F_compressFrame(out.data(), out.size(), in.data(), in.size(), nullptr);
  EXPECT_FALSE(LZ4F_isError(len));
  out.resize(len);
  return out;
}

struct Message {
  std::uint32_t conn, sec, nsec;
  std::string data;
};

/// What to write, and the damage to do on the way. The bag: connection 0 (/scan, LaserScan), three
/// scans stored out of time order (stamps 10.2, 10.0, 10.1 s), one chunk, the index after it (an
/// index record per connection).
struct BagSpec {
  std::string compression = "none";
  std::int64_t size_delta = 0;                                    // added to the chunk header's uncompressed size
  std::function<void(std::string&)> edit_chunk;                   // the chunk's uncompressed records
  std::function<void(std::string&)> edit_compressed;              // the chunk's stored bytes
  std::function<void(std::vector<std::uint32_t>&)> edit_offsets;  // the index entries' offsets
  std::uint32_t index_conn = 0;                                   // the connection the index record names
  bool chunk_listed_twice = false;                                // two chunk info records for the one chunk
  bool second_connection = false;  // the scan at 10.0 s from a second publisher (connection 1, same topic)
};

struct Built {
  std::string bytes;
  std::uint64_t chunk_pos = 0;                 // the chunk record's byte in the file
  std::uint64_t index_record_pos = 0;          // the index record's byte in the file
  std::vector<std::uint32_t> message_offsets;  // in the chunk's uncompressed data, in storage order
  std::uint64_t chunk_size = 0;                // the chunk's uncompressed bytes (after edit_chunk)
};

Built buildBag(const BagSpec& spec) {
  const std::string md5 = "90c7ef2dc6895d81024acba2ac42f369";
  const std::uint32_t conns = spec.second_connection ? 2 : 1;
  auto connection = [&](std::uint32_t id) {
    return record(field("op", op(0x07)) + field("conn", le32(id)) + field("topic", "/scan"),
                  field("topic", "/scan") + field("type", "sensor_msgs/LaserScan") + field("md5sum", md5) +
                      field("message_definition", "# test") + field("callerid", "/publisher" + std::to_string(id)));
  };
  const std::vector<Message> messages = {
      {0, 10, 200000000, laserScan(2, 10, 200000000, {3.0f, 3.1f, 3.2f, 3.3f})},
      {spec.second_connection ? 1u : 0u, 10, 0, laserScan(0, 10, 0, {1.0f, 1.1f, 1.2f, 1.3f})},
      {0, 10, 100000000, laserScan(1, 10, 100000000, {2.0f, 2.1f, 2.2f, 2.3f})}};
  Built b;
  std::string chunk;
  for (std::uint32_t c = 0; c < conns; ++c) chunk += connection(c);
  for (const Message& m : messages) {
    b.message_offsets.push_back(static_cast<std::uint32_t>(chunk.size()));
    chunk += record(field("op", op(0x02)) + field("conn", le32(m.conn)) + field("time", time(m.sec, m.nsec)), m.data);
  }
  if (spec.edit_chunk) spec.edit_chunk(chunk);
  b.chunk_size = chunk.size();
  std::string stored = spec.compression == "bz2" ? bz2(chunk) : spec.compression == "lz4" ? lz4(chunk) : chunk;
  if (spec.edit_compressed) spec.edit_compressed(stored);

  const std::string magic = "#ROSBAG V2.0\n";
  const std::uint32_t chunk_infos = spec.chunk_listed_twice ? 2 : 1;
  auto fileHeader = [&](std::uint64_t index_pos) {
    return record(field("op", op(0x03)) + field("index_pos", le64(index_pos)) + field("conn_count", le32(conns)) +
                      field("chunk_count", le32(chunk_infos)),
                  std::string(64, ' '));
  };
  b.chunk_pos = magic.size() + fileHeader(0).size();
  const auto size = static_cast<std::uint32_t>(static_cast<std::int64_t>(chunk.size()) + spec.size_delta);
  std::string body =
      record(field("op", op(0x05)) + field("compression", spec.compression) + field("size", le32(size)), stored);
  b.index_record_pos = b.chunk_pos + body.size();
  std::vector<std::uint32_t> offsets = b.message_offsets;
  if (spec.edit_offsets) spec.edit_offsets(offsets);
  std::string counts;  // the chunk info's (connection, count) pairs
  for (std::uint32_t c = 0; c < conns; ++c) {
    std::string entries;
    std::uint32_t count = 0;
    for (std::size_t k = 0; k < messages.size(); ++k)
      if (messages[k].conn == c) {
        entries += time(messages[k].sec, messages[k].nsec) + le32(offsets[k]);
        ++count;
      }
    const std::uint32_t named = c == 0 ? spec.index_conn : c;
    body +=
        record(field("op", op(0x04)) + field("ver", le32(1)) + field("conn", le32(named)) + field("count", le32(count)),
               entries);
    counts += le32(named) + le32(count);
  }
  const std::uint64_t index_pos = b.chunk_pos + body.size();
  for (std::uint32_t c = 0; c < conns; ++c) body += connection(c);
  for (std::uint32_t i = 0; i < chunk_infos; ++i)
    body += record(field("op", op(0x06)) + field("ver", le32(1)) + field("chunk_pos", le64(b.chunk_pos)) +
                       field("start_time", time(10, 0)) + field("end_time", time(10, 200000000)) +
                       field("count", le32(conns)),
                   counts);
  b.bytes = magic + fileHeader(index_pos) + body;
  return b;
}

/// Writes the bag and reads every frame through the ROS1 reader.
std::vector<Frame> readBag(const test::TempDir& tmp, const Built& b, const std::string& name = "t.bag") {
  const auto f = tmp.path() / name;
  test::writeFile(f, b.bytes);
  auto src = internal::openRosbag1(f.string(), {});
  std::vector<Frame> frames;
  while (auto fr = src->next()) frames.push_back(std::move(*fr));
  return frames;
}

/// Reading the bag throws a lidar2d::Error naming the file and containing `text`.
void expectError(const Built& b, const std::string& text) {
  test::TempDir tmp;
  const auto f = (tmp.path() / "bad.bag").string();
  try {
    readBag(tmp, b, "bad.bag");
    ADD_FAILURE() << "no error; expected: " << text;
  } catch (const Error& e) {
    EXPECT_THAT(e.what(), HasSubstr(f));
    EXPECT_THAT(e.what(), HasSubstr(text));
  }
}

class Ros1Container : public ::testing::TestWithParam<std::string> {
 protected:
  BagSpec spec() const {
    BagSpec s;
    s.compression = GetParam();
    return s;
  }
};

TEST_P(Ros1Container, ReadsEveryScanInTimeOrder) {
  test::TempDir tmp;
  const std::vector<Frame> frames = readBag(tmp, buildBag(spec()));
  ASSERT_EQ(frames.size(), 3u);
  for (std::size_t k = 0; k < 3; ++k) {
    EXPECT_NEAR(frames[k].time, 10.0 + 0.1 * static_cast<double>(k), 1e-9);
    ASSERT_EQ(frames[k].scan.ranges().size(), 4u);
    EXPECT_FLOAT_EQ(static_cast<float>(frames[k].scan.ranges()[0]), 1.0f + static_cast<float>(k));
    EXPECT_FLOAT_EQ(static_cast<float>(frames[k].scan.ranges()[3]), 1.3f + static_cast<float>(k));
  }
}

TEST_P(Ros1Container, ConnectionsAndIndex) {
  test::TempDir tmp;
  const auto f = tmp.path() / "t.bag";
  const Built b = buildBag(spec());
  test::writeFile(f, b.bytes);
  internal::Ros1Bag bag(f.string());
  ASSERT_EQ(bag.connections().size(), 1u);
  EXPECT_EQ(bag.connections()[0].topic, "/scan");
  EXPECT_EQ(bag.connections()[0].type, "sensor_msgs/LaserScan");
  EXPECT_EQ(bag.connections()[0].messages, 3u);
  const auto messages = bag.messages({0});
  ASSERT_EQ(messages.size(), 3u);
  EXPECT_EQ(messages[0].offset, b.message_offsets[1]);  // 10.0 s, stored second
  EXPECT_EQ(messages[1].offset, b.message_offsets[2]);
  EXPECT_EQ(messages[2].offset, b.message_offsets[0]);
  EXPECT_TRUE(bag.messages({5}).empty());
}

TEST_P(Ros1Container, TwoConnectionsOnOneTopic) {
  BagSpec s = spec();
  s.second_connection = true;
  test::TempDir tmp;
  const Built b = buildBag(s);
  const std::vector<Frame> frames = readBag(tmp, b);
  ASSERT_EQ(frames.size(), 3u);
  for (std::size_t k = 0; k < 3; ++k) {
    EXPECT_NEAR(frames[k].time, 10.0 + 0.1 * static_cast<double>(k), 1e-9);
    EXPECT_FLOAT_EQ(static_cast<float>(frames[k].scan.ranges()[0]), 1.0f + static_cast<float>(k));
  }
  internal::Ros1Bag bag((tmp.path() / "t.bag").string());
  ASSERT_EQ(bag.connections().size(), 2u);
  EXPECT_EQ(bag.connections()[0].messages, 2u);
  EXPECT_EQ(bag.connections()[1].messages, 1u);
  EXPECT_EQ(bag.connections()[1].topic, "/scan");
  EXPECT_EQ(bag.messages({1}).size(), 1u);
  EXPECT_EQ(bag.messages({0, 1}).size(), 3u);
}

TEST_P(Ros1Container, IndexOffsetInsideARecord) {
  BagSpec s = spec();
  s.edit_offsets = [](auto& o) { o[1] += 3; };
  const Built b = buildBag(s);
  expectError(b,
              fmt::format("corrupt index record at byte {}: entry 1 points to byte {} of the chunk at byte {}, where "
                          "no record starts",
                          b.index_record_pos, b.message_offsets[1] + 3, b.chunk_pos));
}

TEST_P(Ros1Container, IndexOffsetAtTheConnectionRecord) {
  BagSpec s = spec();
  s.edit_offsets = [](auto& o) { o[2] = 0; };
  const Built b = buildBag(s);
  expectError(b, fmt::format("corrupt index record at byte {}: entry 2 points to byte 0 of the chunk at byte {}, which "
                             "holds a record of op 7, not a message",
                             b.index_record_pos, b.chunk_pos));
}

TEST_P(Ros1Container, IndexOffsetPastTheChunk) {
  BagSpec s = spec();
  s.edit_offsets = [](auto& o) { o[0] = 0x7ffffff0u; };
  const Built b = buildBag(s);
  expectError(b,
              fmt::format("corrupt index record at byte {}: entry 0 points to byte 2147483632 of the chunk at byte {}, "
                          "past its end",
                          b.index_record_pos, b.chunk_pos));
}

TEST_P(Ros1Container, FieldLengthPastItsHeaderInsideTheChunk) {
  BagSpec s = spec();
  const std::uint32_t at = buildBag(spec()).message_offsets[1];
  s.edit_chunk = [at](std::string& c) {
    std::uint32_t first_field;
    std::memcpy(&first_field, c.data() + at + 4, 4);
    const std::string bigger = le32(first_field + 1000);
    c.replace(at + 4, 4, bigger);
  };
  const Built b = buildBag(s);
  expectError(b, fmt::format("corrupt record header at byte {} of the chunk at byte {}: a field's length runs past the "
                             "header's",
                             at, b.chunk_pos));
}

TEST_P(Ros1Container, RecordDataPastTheChunkEnd) {
  BagSpec s = spec();
  s.edit_chunk = [](std::string& c) { c.resize(c.size() - 10); };  // the last message cut short
  const Built b = buildBag(s);
  expectError(b, fmt::format("the record at byte {} of the chunk at byte {} runs past the chunk's end ({} bytes)",
                             b.message_offsets.back(), b.chunk_pos, b.chunk_size));
}

TEST_P(Ros1Container, MessageOfAnotherConnectionThanItsIndex) {
  BagSpec s = spec();
  const std::uint32_t first = buildBag(spec()).message_offsets[0];
  s.edit_chunk = [first](std::string& c) {
    // The first message's conn field (the value after "conn=" in its header) becomes 9.
    const auto at = c.find("conn=", first);
    c.replace(at + 5, 4, le32(9));
  };
  const Built b = buildBag(s);
  expectError(b, "a message of connection 9, not 0");
}

TEST_P(Ros1Container, IndexOfAnUndeclaredConnection) {
  BagSpec s = spec();
  s.index_conn = 7;
  expectError(buildBag(s), "names connection 7, which the bag does not declare");
}

TEST_P(Ros1Container, ChunkListedTwiceInTheIndex) {
  BagSpec s = spec();
  s.chunk_listed_twice = true;
  const Built b = buildBag(s);
  expectError(b, fmt::format("the index lists the chunk at byte {} twice", b.chunk_pos));
}

INSTANTIATE_TEST_SUITE_P(Compression, Ros1Container, ::testing::Values("none", "bz2", "lz4"),
                         [](const auto& info) { return info.param; });

class Ros1CompressedChunk : public Ros1Container {};

TEST_P(Ros1CompressedChunk, StatedSizeLargerThanTheData) {
  BagSpec s = spec();
  s.size_delta = 100;
  const Built b = buildBag(s);
  expectError(b, fmt::format("the chunk at byte {}: it decompresses to {} bytes, not the {} its header states",
                             b.chunk_pos, b.chunk_size, b.chunk_size + 100));
}

TEST_P(Ros1CompressedChunk, StatedSizeSmallerThanTheData) {
  BagSpec s = spec();
  s.size_delta = -100;
  expectError(buildBag(s), "it decompresses to more than the");
}

TEST_P(Ros1CompressedChunk, CutShort) {
  BagSpec s = spec();
  s.edit_compressed = [](std::string& z) { z.resize(z.size() / 2); };
  expectError(buildBag(s), "ends early (truncated)");
}

TEST_P(Ros1CompressedChunk, Garbage) {
  BagSpec s = spec();
  s.edit_compressed = [](std::string& z) {
    for (std::size_t i = 0; i < z.size(); ++i) z[i] = static_cast<char>(i * 37 + 11);
  };
  expectError(buildBag(s), fmt::format("corrupt {} data", GetParam()));
}

INSTANTIATE_TEST_SUITE_P(Compression, Ros1CompressedChunk, ::testing::Values("bz2", "lz4"),
                         [](const auto& info) { return info.param; });

TEST(Ros1Container, UnknownCompression) {
  BagSpec s;
  s.compression = "zstd";
  expectError(buildBag(s), "is compressed with 'zstd' (lidar2d reads none, bz2 and lz4)");
}

// What `rosbag record` leaves when nothing was published: a file header whose index (no
// connections, no chunks) starts at the end of the file.
TEST(Ros1Container, EmptyRecording) {
  test::TempDir tmp;
  const auto f = tmp.path() / "empty.bag";
  const std::string magic = "#ROSBAG V2.0\n";
  auto header = [](std::uint64_t index_pos) {
    return record(field("op", op(0x03)) + field("index_pos", le64(index_pos)) + field("conn_count", le32(0)) +
                      field("chunk_count", le32(0)),
                  std::string(100, ' '));
  };
  const std::uint64_t end = magic.size() + header(0).size();
  test::writeFile(f, magic + header(end));
  internal::Ros1Bag bag(f.string());
  EXPECT_TRUE(bag.connections().empty());
  try {
    internal::openRosbag1(f.string(), {});
    ADD_FAILURE() << "no error";
  } catch (const Error& e) {
    EXPECT_THAT(e.what(), HasSubstr("no sensor_msgs/LaserScan topic in the bag (topics: none)"));
  }
  // With one connection announced, the same file is cut short.
  test::writeFile(f, magic + record(field("op", op(0x03)) + field("index_pos", le64(end)) +
                                        field("conn_count", le32(1)) + field("chunk_count", le32(0)),
                                    std::string(100, ' ')));
  try {
    internal::Ros1Bag cut(f.string());
    ADD_FAILURE() << "no error";
  } catch (const Error& e) {
    EXPECT_THAT(e.what(), HasSubstr("truncated bag: its index should start at byte"));
  }
}

// Chunks are decompressed ahead of the reads on other threads: a damaged chunk's error reaches the
// reader when one of its messages is read, and only then. mit-csail.orig.bag has seven bz2 chunks;
// the second one's compressed bytes are zeroed in the middle.
TEST(Ros1Container, PrefetchedChunkErrorsComeWithTheirMessages) {
  LIDAR2D_REQUIRE_DATA("raw/mit-csail.orig.bag");
  test::TempDir tmp;
  const auto f = tmp.path() / "second_chunk.bag";
  std::filesystem::copy_file(test::dataFile("raw/mit-csail.orig.bag"), f);
  std::filesystem::permissions(f, std::filesystem::perms::owner_read | std::filesystem::perms::owner_write);
  std::uint64_t second_chunk = 0;
  {
    std::fstream io(f, std::ios::binary | std::ios::in | std::ios::out);
    // The top-level records after the 13-byte magic: the file header, then chunks and index records.
    std::uint64_t pos = 13;
    int chunks = 0;
    while (chunks < 2) {
      std::uint32_t hlen = 0, dlen = 0;
      io.seekg(static_cast<std::streamoff>(pos));
      io.read(reinterpret_cast<char*>(&hlen), 4);
      std::string header(hlen, '\0');
      io.read(header.data(), hlen);
      io.read(reinterpret_cast<char*>(&dlen), 4);
      ASSERT_TRUE(io.good());
      if (header.find(std::string("op=") + '\x05') != std::string::npos && ++chunks == 2) {
        second_chunk = pos;
        io.seekp(static_cast<std::streamoff>(pos + 8 + hlen + dlen / 2));
        const std::string zeros(64, '\0');
        io.write(zeros.data(), static_cast<std::streamsize>(zeros.size()));
      }
      pos += 8 + hlen + dlen;
    }
  }
  {
    internal::Ros1Bag bag(f.string());
    const auto messages = bag.messages({0, 1, 2, 3});
    ASSERT_FALSE(messages.empty());
    EXPECT_EQ(messages.front().chunk, 0u);
    EXPECT_FALSE(bag.read(messages.front()).empty());  // chunk 0; chunks 1 and 2 start decompressing
  }                                                    // (no error: the second chunk was never read)
  try {
    auto src = internal::openRosbag1(f.string(), {});
    while (src->next()) {
    }
    ADD_FAILURE() << "no error";
  } catch (const Error& e) {
    EXPECT_THAT(e.what(), HasSubstr(fmt::format("not a readable ROS1 bag: the chunk at byte {}: corrupt bz2 data",
                                                second_chunk)));
  }
}

TEST(Ros1Container, NotABag) {
  test::TempDir tmp;
  const auto f = tmp.path() / "x.bag";
  test::writeFile(f, "#ROSBAG V3.0\nwhatever");
  try {
    internal::Ros1Bag bag(f.string());
    ADD_FAILURE() << "no error";
  } catch (const Error& e) {
    EXPECT_THAT(e.what(), HasSubstr("not a readable ROS1 bag: it starts with neither"));
  }
}

}  // namespace
}  // namespace lidar2d::io
