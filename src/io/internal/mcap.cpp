#include "src/io/internal/mcap.hpp"

#include <fmt/format.h>
#include <zlib.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <filesystem>

#include "lidar2d/core/error.hpp"
#include "src/io/internal/decompress.hpp"
#include "src/io/internal/read_file.hpp"

namespace lidar2d::io::internal {
namespace {

constexpr std::uint8_t kMagic[8] = {0x89, 'M', 'C', 'A', 'P', '0', '\r', '\n'};
constexpr std::uint64_t kHeadBytes = 9;  // opcode + uint64 content length

enum Op : std::uint8_t {
  kHeader = 0x01,
  kFooter = 0x02,
  kSchema = 0x03,
  kChannel = 0x04,
  kMessage = 0x05,
  kChunk = 0x06,
  kDataEnd = 0x0F,
};

const char* opName(std::uint8_t op) {
  static constexpr const char* kNames[] = {"invalid",        "Header",        "Footer",     "Schema",
                                           "Channel",        "Message",       "Chunk",      "Message Index",
                                           "Chunk Index",    "Attachment",    "Attachment Index",
                                           "Statistics",     "Metadata",      "Metadata Index",
                                           "Summary Offset", "Data End"};
  return op < std::size(kNames) ? kNames[op] : "extension";
}

/// Bounds-checked little-endian reads of a record's fields; an error names the record, its byte
/// offset and the field.
class Fields {
 public:
  Fields(std::span<const std::uint8_t> b, const std::string& file, const char* record, std::uint64_t offset)
      : b_(b), file_(file), record_(record), offset_(offset) {}

  template <typename T>
  T num(const char* field) {
    need(sizeof(T), field);
    T v;
    std::memcpy(&v, b_.data() + p_, sizeof(T));  // MCAP is little-endian, as is every target we build for
    p_ += sizeof(T);
    return v;
  }
  std::string str(const char* field) {
    const auto n = num<std::uint32_t>(field);
    need(n, field);
    std::string s(reinterpret_cast<const char*>(b_.data() + p_), n);
    p_ += n;
    return s;
  }
  /// A uint32 (or uint64 with `long_prefix`) length-prefixed byte string, viewed in place.
  std::span<const std::uint8_t> bytes(const char* field, bool long_prefix) {
    const std::uint64_t n = long_prefix ? num<std::uint64_t>(field) : num<std::uint32_t>(field);
    need(n, field);
    auto s = b_.subspan(p_, n);
    p_ += n;
    return s;
  }
  std::span<const std::uint8_t> rest() const { return b_.subspan(p_); }
  [[noreturn]] void fail(const char* field, const std::string& why) const {
    throw badInput("not a readable MCAP file: " + why,
                   {file_, 0, fmt::format("{}.{} at byte {}", record_, field, offset_)});
  }

 private:
  void need(std::uint64_t n, const char* field) const {
    if (n > b_.size() - p_)
      fail(field, fmt::format("the field needs {} bytes but the record has {} left", n, b_.size() - p_));
  }
  std::span<const std::uint8_t> b_;
  const std::string& file_;
  const char* record_;
  std::uint64_t offset_;
  std::size_t p_ = 0;
};

[[noreturn]] void failAt(const std::string& file, std::uint64_t offset, const std::string& what, const std::string& why) {
  throw badInput("not a readable MCAP file: " + why, {file, 0, fmt::format("{} at byte {}", what, offset)});
}

}  // namespace

McapReader::McapReader(const std::string& path, std::string display) : file_(std::move(display)) {
  if (!checkInputFile(path, "MCAP file"))
    throw badInput("an MCAP file must be a regular file (it is read twice), not a pipe", {file_});
  in_.open(path, std::ios::binary);
  if (!in_) throw ioError(fmt::format("cannot open: {}", std::strerror(errno)), {file_});
  std::error_code ec;
  size_ = std::filesystem::file_size(path, ec);
  if (ec) throw ioError("cannot read the file size: " + ec.message(), {file_});
  if (size_ < sizeof kMagic) failAt(file_, 0, "magic", fmt::format("the file has only {} bytes", size_));
  std::uint8_t magic[sizeof kMagic];
  readBytes(magic, sizeof magic, 0, "magic");
  if (std::memcmp(magic, kMagic, 5) != 0) failAt(file_, 0, "magic", "the file does not start with the MCAP magic");
  if (magic[5] != '0')
    throw Error(ErrorKind::kUnsupported, fmt::format("MCAP major version '{}' is not supported (only 0)",
                                                     static_cast<char>(magic[5])),
                {file_, 0, "magic at byte 5"});
  if (std::memcmp(magic, kMagic, sizeof kMagic) != 0) failAt(file_, 0, "magic", "the magic's last bytes are wrong");
  checksum(magic, sizeof magic);
  RecordHead h;
  if (!readHead(h) || h.op != kHeader)
    failAt(file_, sizeof kMagic, "Header", "the first record is not a Header record");
  readContent(h, record_);
  Fields f(record_, file_, "Header", h.offset);
  profile_ = f.str("profile");
  (void)f.str("library");
}

void McapReader::readBytes(std::uint8_t* out, std::uint64_t n, std::uint64_t at, const char* what) {
  in_.read(reinterpret_cast<char*>(out), static_cast<std::streamsize>(n));
  if (static_cast<std::uint64_t>(in_.gcount()) != n) {
    if (in_.bad()) throw ioError(fmt::format("read error at byte {} ({})", at, what), {file_});
    failAt(file_, at, what, "the file ends early (truncated)");
  }
  pos_ = at + n;
}

void McapReader::checksum(const std::uint8_t* p, std::size_t n) {
  if (done_) return;
  unsigned long& crc = in_summary_ ? summary_crc_ : data_crc_;
  while (n > 0) {  // zlib's crc32 takes a uInt length
    const auto k = static_cast<uInt>(std::min<std::size_t>(n, 1u << 30));
    crc = crc32(crc, p, k);
    p += k;
    n -= k;
  }
}

bool McapReader::readHead(RecordHead& h) {
  if (pos_ == size_) return false;
  std::uint8_t head[kHeadBytes];
  h.offset = pos_;
  if (size_ - pos_ < kHeadBytes)
    failAt(file_, pos_, "record", fmt::format("the file ends {} bytes into a record header (truncated)", size_ - pos_));
  readBytes(head, kHeadBytes, pos_, "record");
  h.op = head[0];
  std::memcpy(&h.length, head + 1, 8);
  if (h.op == 0) failAt(file_, h.offset, "record", "opcode 0x00 is no MCAP record (corrupt data)");
  if (h.length > size_ - pos_)
    failAt(file_, h.offset, fmt::format("{} record length", opName(h.op)),
           fmt::format("the record states {} bytes but the file has {} left (truncated, or a corrupt length)",
                       h.length, size_ - pos_));
  // Data End and the Footer are in neither CRC (the Footer's first fields are added in onFooter).
  if (h.op != kFooter && h.op != kDataEnd) checksum(head, kHeadBytes);
  return true;
}

void McapReader::readContent(const RecordHead& h, std::vector<std::uint8_t>& out) {
  out.resize(h.length);  // within the file's size (readHead)
  readBytes(out.data(), h.length, h.offset + kHeadBytes, opName(h.op));
  if (h.op != kFooter && h.op != kDataEnd) checksum(out.data(), out.size());
}

void McapReader::skipContent(const RecordHead& h) {
  // Read rather than seek: the bytes count in the data section's CRC.
  std::uint8_t block[65536];
  for (std::uint64_t left = h.length; left > 0;) {
    const std::uint64_t n = std::min<std::uint64_t>(left, sizeof block);
    readBytes(block, n, pos_, opName(h.op));
    checksum(block, n);
    left -= n;
  }
}

void McapReader::onSchema(std::span<const std::uint8_t> content, std::uint64_t offset) {
  Fields f(content, file_, "Schema", offset);
  const auto id = f.num<std::uint16_t>("id");
  Schema s;
  s.name = f.str("name");
  s.encoding = f.str("encoding");
  (void)f.bytes("data", false);
  if (id != 0) schemas_[id] = std::move(s);  // the spec: a schema id of 0 is invalid and ignored
}

void McapReader::onChannel(std::span<const std::uint8_t> content, std::uint64_t offset) {
  Fields f(content, file_, "Channel", offset);
  McapChannel c;
  c.id = f.num<std::uint16_t>("id");
  const auto schema_id = f.num<std::uint16_t>("schema_id");
  c.topic = f.str("topic");
  c.message_encoding = f.str("message_encoding");
  (void)f.bytes("metadata", false);
  if (schema_id != 0) {
    const auto s = schemas_.find(schema_id);
    if (s == schemas_.end())
      f.fail("schema_id", fmt::format("channel {} ({}) refers to schema {}, which no earlier Schema record defines",
                                      c.id, c.topic, schema_id));
    c.schema_name = s->second.name;
    c.schema_encoding = s->second.encoding;
  }
  // Channels are repeated in the summary and may be repeated in chunks; a message keeps a pointer
  // to its channel, so an existing entry is updated in place rather than replaced.
  channels_[c.id] = std::move(c);
}

void McapReader::parseMessage(std::span<const std::uint8_t> content, McapMessage& m) const {
  Fields f(content, file_, "Message", m.record_offset);
  const auto channel = f.num<std::uint16_t>("channel_id");
  m.sequence = f.num<std::uint32_t>("sequence");
  m.log_time = f.num<std::uint64_t>("log_time");
  m.publish_time = f.num<std::uint64_t>("publish_time");
  m.data = f.rest();
  const auto c = channels_.find(channel);
  if (c == channels_.end())
    throw badInput(fmt::format("not a readable MCAP file: the {} is on channel {}, which no earlier Channel record "
                               "defines",
                               where(m), channel),
                   {file_, 0, "Message.channel_id"});
  m.channel = &c->second;
}

void McapReader::loadChunk(const RecordHead& h) {
  readContent(h, record_);
  Fields f(record_, file_, "Chunk", h.offset);
  (void)f.num<std::uint64_t>("message_start_time");
  (void)f.num<std::uint64_t>("message_end_time");
  const auto size = f.num<std::uint64_t>("uncompressed_size");
  const auto crc = f.num<std::uint32_t>("uncompressed_crc");
  const std::string compression = f.str("compression");
  const auto records = f.bytes("records", true);
  if (size > kMaxChunkBytes)
    f.fail("uncompressed_size", fmt::format("the chunk states {} bytes uncompressed, more than the {} lidar2d accepts",
                                            size, kMaxChunkBytes));
  const DecompressContext context{fmt::format("not a readable MCAP file: the chunk's {} records: ", compression),
                                  {file_, 0, fmt::format("Chunk.records at byte {}", h.offset)}};
  if (compression.empty()) {
    if (records.size() != size)
      f.fail("uncompressed_size", fmt::format("an uncompressed chunk states {} bytes but holds {}", size,
                                              records.size()));
    chunk_.assign(records.begin(), records.end());
  } else if (compression == "zstd") {
    chunk_ = decompress(Codec::kZstd, records, size, /*exact=*/true, context);
  } else if (compression == "lz4") {
    chunk_ = decompress(Codec::kLz4, records, size, /*exact=*/true, context);
  } else {
    throw Error(ErrorKind::kUnsupported,
                fmt::format("the chunk is compressed with '{}' (lidar2d reads uncompressed, zstd and lz4 chunks)",
                            compression),
                {file_, 0, fmt::format("Chunk.compression at byte {}", h.offset)});
  }
  if (crc != 0) {
    const auto actual = static_cast<std::uint32_t>(crc32(crc32(0, nullptr, 0), chunk_.data(), static_cast<uInt>(chunk_.size())));
    if (actual != crc)
      f.fail("uncompressed_crc", fmt::format("the chunk's records have CRC32 {:#010x}, not the {:#010x} it states "
                                             "(corrupt data)",
                                             actual, crc));
  }
  chunk_record_offset_ = h.offset;
  chunk_pos_ = 0;
  in_chunk_ = true;
}

bool McapReader::nextInChunk(McapMessage& m) {
  while (chunk_pos_ < chunk_.size()) {
    const std::uint64_t at = chunk_pos_;
    const std::uint64_t left = chunk_.size() - at;
    auto failHere = [&](const std::string& why) {
      throw badInput("not a readable MCAP file: " + why,
                     {file_, 0, fmt::format("record at byte {} of the chunk at byte {}", at, chunk_record_offset_)});
    };
    if (left < kHeadBytes) failHere(fmt::format("{} bytes left in the chunk, too few for a record", left));
    const std::uint8_t op = chunk_[at];
    std::uint64_t length;
    std::memcpy(&length, chunk_.data() + at + 1, 8);
    if (length > left - kHeadBytes)
      failHere(fmt::format("the {} record states {} bytes but the chunk has {} left", opName(op), length,
                           left - kHeadBytes));
    if (op == 0) failHere("opcode 0x00 is no MCAP record (corrupt data)");
    const std::span<const std::uint8_t> content(chunk_.data() + at + kHeadBytes, length);
    chunk_pos_ = at + kHeadBytes + length;
    const std::uint64_t where = chunk_record_offset_;
    if (op == kSchema) {
      onSchema(content, where);
    } else if (op == kChannel) {
      onChannel(content, where);
    } else if (op == kMessage) {
      m = {};
      m.in_chunk = true;
      m.record_offset = chunk_record_offset_;
      m.chunk_offset = at;
      parseMessage(content, m);
      return true;
    }
    // Other records do not belong in a chunk; like unknown (extension) records they are skipped.
  }
  in_chunk_ = false;
  return false;
}

void McapReader::onDataEnd(const RecordHead& h) {
  const unsigned long computed = data_crc_;
  readContent(h, record_);
  Fields f(record_, file_, "Data End", h.offset);
  const auto stated = f.num<std::uint32_t>("data_section_crc");
  if (stated != 0 && stated != static_cast<std::uint32_t>(computed))
    f.fail("data_section_crc",
           fmt::format("the data section has CRC32 {:#010x}, not the {:#010x} it states (corrupt data)",
                       static_cast<std::uint32_t>(computed), stated));
  in_summary_ = true;
}

void McapReader::onFooter(const RecordHead& h) {
  if (h.length != 20)
    failAt(file_, h.offset, "Footer record length", fmt::format("a Footer has 20 bytes, not {}", h.length));
  readContent(h, record_);
  // The summary CRC covers the Footer up to (not including) summary_crc.
  std::uint8_t head[kHeadBytes] = {kFooter};
  std::memcpy(head + 1, &h.length, 8);
  checksum(head, kHeadBytes);
  checksum(record_.data(), 16);
  Fields f(record_, file_, "Footer", h.offset);
  (void)f.num<std::uint64_t>("summary_start");
  (void)f.num<std::uint64_t>("summary_offset_start");
  const auto stated = f.num<std::uint32_t>("summary_crc");
  const auto computed = static_cast<std::uint32_t>(in_summary_ ? summary_crc_ : 0);
  if (stated != 0 && in_summary_ && stated != computed)
    f.fail("summary_crc", fmt::format("the summary has CRC32 {:#010x}, not the {:#010x} it states (corrupt data)",
                                      computed, stated));
  std::uint8_t magic[sizeof kMagic];
  const std::uint64_t at = pos_;
  if (size_ - pos_ < sizeof kMagic) failAt(file_, at, "closing magic", "the file ends early (truncated)");
  readBytes(magic, sizeof magic, at, "closing magic");
  if (std::memcmp(magic, kMagic, sizeof kMagic) != 0)
    failAt(file_, at, "closing magic", "the Footer is not followed by the MCAP magic");
  if (pos_ != size_)
    failAt(file_, pos_, "end of file", fmt::format("{} bytes follow the closing magic", size_ - pos_));
  done_ = true;
}

bool McapReader::next(McapMessage& m) {
  if (done_) return false;
  for (;;) {
    if (in_chunk_ && nextInChunk(m)) return true;
    RecordHead h;
    if (!readHead(h))
      failAt(file_, pos_, "Footer", "the file ends without a Footer record and closing magic (truncated)");
    switch (h.op) {
      case kHeader:
        failAt(file_, h.offset, "Header", "a second Header record");
      case kSchema:
        readContent(h, record_);
        onSchema(record_, h.offset);
        break;
      case kChannel:
        readContent(h, record_);
        onChannel(record_, h.offset);
        break;
      case kMessage:
        if (in_summary_) failAt(file_, h.offset, "Message", "a Message record after Data End");
        readContent(h, record_);
        m = {};
        m.record_offset = h.offset;
        parseMessage(record_, m);
        return true;
      case kChunk:
        if (in_summary_) failAt(file_, h.offset, "Chunk", "a Chunk record after Data End");
        loadChunk(h);
        break;
      case kDataEnd:
        if (in_summary_) failAt(file_, h.offset, "Data End", "a second Data End record");
        onDataEnd(h);
        break;
      case kFooter:
        onFooter(h);
        return false;
      default:  // indexes, attachments, metadata, statistics, extensions: not needed here
        skipContent(h);
        break;
    }
  }
}

std::string McapReader::where(const McapMessage& m) {
  if (m.in_chunk) return fmt::format("message at byte {} of the chunk at byte {}", m.chunk_offset, m.record_offset);
  return fmt::format("message at byte {}", m.record_offset);
}

}  // namespace lidar2d::io::internal
