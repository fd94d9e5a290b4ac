#include "src/io/internal/ros1_bag.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cstring>
#include <filesystem>
#include <future>
#include <map>
#include <optional>
#include <string_view>
#include <system_error>
#include <utility>

#include "lidar2d/core/error.hpp"
#include "src/io/internal/decompress.hpp"

namespace lidar2d::io::internal {
namespace {

constexpr std::string_view kMagic20 = "#ROSBAG V2.0\n";
constexpr std::string_view kMagic12 = "#ROSRECORD V1.2\n";

enum Op : int {
  kMessageDefinition = 0x01,  // 1.2
  kMessageData = 0x02,
  kFileHeader = 0x03,
  kIndexData = 0x04,
  kChunk = 0x05,
  kChunkInfo = 0x06,
  kConnection = 0x07,
};

constexpr std::uint64_t kIndexEntryBytes = 12;  // 2.0 index entry: sec, nsec, offset (uint32 each)

std::uint32_t u32(const std::uint8_t* p) {
  std::uint32_t v;
  std::memcpy(&v, p, 4);
  return v;
}

RosNanos nanos(std::uint32_t sec, std::uint32_t nsec) {
  return static_cast<RosNanos>(sec) * 1000000000 + static_cast<RosNanos>(nsec);
}

/// The name=value fields of a record header (a connection record's data has the same layout), as
/// views into the bytes they were parsed from.
struct Fields {
  std::vector<std::pair<std::string_view, std::string_view>> list;
  int op = -1;

  std::optional<std::string_view> get(std::string_view name) const {
    for (const auto& [n, v] : list)
      if (n == name) return v;
    return std::nullopt;
  }
};

/// Parses the `len` header bytes at `h`; a field that overruns them, or has no '=', is an error
/// naming `at` (the record's byte) and `where` (" of the chunk at byte N" inside a chunk).
Fields parseFields(const std::uint8_t* h, std::uint64_t len, std::uint64_t at, const std::string& where,
                   const std::string& path) {
  Fields f;
  for (std::uint64_t q = 0; q < len;) {
    if (len - q < 4 || u32(h + q) > len - q - 4)
      throw badInput(fmt::format("corrupt record header at byte {}{}: a field's length runs past the header's {} bytes",
                                 at, where, len),
                     {path});
    const std::string_view field(reinterpret_cast<const char*>(h + q + 4), u32(h + q));
    const std::size_t eq = field.find('=');
    if (eq == std::string_view::npos)
      throw badInput(fmt::format("corrupt record header at byte {}{}: a field without '='", at, where), {path});
    f.list.emplace_back(field.substr(0, eq), field.substr(eq + 1));
    if (field.substr(0, eq) == "op" && field.size() == eq + 2) f.op = static_cast<unsigned char>(field[eq + 1]);
    q += 4 + u32(h + q);
  }
  return f;
}

/// The little-endian unsigned field `name` of `bytes` bytes; an error naming `what` when it is
/// missing or of another size.
std::uint64_t number(const Fields& f, std::string_view name, std::size_t bytes, const std::string& what,
                     const std::string& path) {
  const auto v = f.get(name);
  if (!v || v->size() != bytes)
    throw badInput(fmt::format("not a readable ROS1 bag: the {} has no {}-byte '{}' field", what, bytes, name), {path});
  std::uint64_t x = 0;
  std::memcpy(&x, v->data(), bytes);
  return x;
}

std::string text(const Fields& f, std::string_view name, const std::string& what, const std::string& path) {
  const auto v = f.get(name);
  if (!v) throw badInput(fmt::format("not a readable ROS1 bag: the {} has no '{}' field", what, name), {path});
  return std::string(*v);
}

/// A record read from the file: its header bytes (kept, the fields view them) and where its data is.
struct FileRecord {
  FileRecord() = default;
  FileRecord(FileRecord&&) = default;
  FileRecord(const FileRecord&) = delete;  // (a copy's fields would view the original's header)
  std::vector<std::uint8_t> header;
  Fields fields;
  std::uint64_t pos = 0, data_at = 0, data_len = 0, end = 0;
};

}  // namespace

// An index record after a chunk: the connection and, per message, the offset of its record.
struct IndexRecord {
  std::uint64_t pos = 0;
  std::uint32_t conn = 0;
  std::vector<std::uint32_t> offsets;
};

struct Ros1Bag::Chunk {
  std::uint64_t pos = 0, data_at = 0, data_len = 0;
  std::uint64_t size = 0;  // uncompressed
  std::string compression;
  std::vector<IndexRecord> index;
};

struct Ros1Bag::CachedChunk {
  struct Record {
    std::uint64_t offset = 0, data_at = 0, data_len = 0;
    int op = -1;
    std::optional<std::uint32_t> conn;
  };
  std::uint32_t chunk = 0;
  std::vector<std::uint8_t> data;
  std::vector<Record> records;  // in offset order
};

namespace {

// File access shared by the two formats; every read is checked against the file's size.
class File {
 public:
  File(std::ifstream& in, std::uint64_t size, const std::string& path) : in_(in), size_(size), path_(path) {}

  std::vector<std::uint8_t> bytes(std::uint64_t pos, std::uint64_t n, const std::string& what) {
    if (pos > size_ || n > size_ - pos)
      throw badInput(
          fmt::format("truncated bag: the {} at byte {} needs {} bytes but the file has {}", what, pos, n, size_),
          {path_});
    std::vector<std::uint8_t> out(n);
    in_.clear();
    in_.seekg(static_cast<std::streamoff>(pos));
    if (!in_.read(reinterpret_cast<char*>(out.data()), static_cast<std::streamsize>(n)))
      throw badInput(fmt::format("cannot read {} bytes at byte {}", n, pos), {path_});
    return out;
  }

  /// The record at `pos` (`what` names it in errors): its header read and parsed, its data not read.
  FileRecord record(std::uint64_t pos, const std::string& what) {
    FileRecord r;
    r.pos = pos;
    if (pos > size_ || size_ - pos < 8)
      throw badInput(
          fmt::format("truncated bag: the {} at byte {} lies past the end of the file ({} bytes)", what, pos, size_),
          {path_});
    const std::uint32_t hlen = u32(bytes(pos, 4, what).data());
    if (hlen > size_ - pos - 8)
      throw badInput(fmt::format("not a readable ROS1 bag: the {} at byte {} states a {}-byte header, more than the {} "
                                 "bytes left in the file (truncated or corrupt)",
                                 what, pos, hlen, size_ - pos - 8),
                     {path_});
    r.header = bytes(pos + 4, hlen + 4, what);
    r.data_at = pos + 8 + hlen;
    r.data_len = u32(r.header.data() + hlen);
    if (r.data_len > size_ - r.data_at)
      throw badInput(fmt::format("truncated bag: the {} at byte {} states {} bytes of data but the file ends {} bytes "
                                 "after its header",
                                 what, pos, r.data_len, size_ - r.data_at),
                     {path_});
    r.fields = parseFields(r.header.data(), hlen, pos, "", path_);
    r.end = r.data_at + r.data_len;
    return r;
  }

  void expectOp(const FileRecord& r, int op, const std::string& what) const {
    if (r.fields.op != op)
      throw badInput(fmt::format("not a readable ROS1 bag: expected a {} (op {:#04x}) at byte {}, found op {}", what,
                                 op, r.pos, r.fields.op),
                     {path_});
  }

 private:
  std::ifstream& in_;
  std::uint64_t size_;
  const std::string& path_;
};

}  // namespace

Ros1Bag::Ros1Bag(std::string path) : path_(std::move(path)), in_(path_, std::ios::binary) {
  std::error_code ec;
  size_ = std::filesystem::file_size(path_, ec);
  if (!in_ || ec) throw badInput("not a readable ROS1 bag: cannot open the file", {path_});
  std::string magic(16, '\0');
  in_.read(magic.data(), 16);
  magic.resize(static_cast<std::size_t>(in_.gcount()));
  if (magic.starts_with(kMagic20))
    openV20();
  else if (magic.starts_with(kMagic12)) {
    v12_ = true;
    openV12();
  } else
    throw badInput("not a readable ROS1 bag: it starts with neither '#ROSBAG V2.0' nor '#ROSRECORD V1.2'", {path_});
  std::sort(connections_.begin(), connections_.end(), [](const auto& a, const auto& b) { return a.id < b.id; });
  for (const Ros1Entry& e : entries_)
    std::lower_bound(connections_.begin(), connections_.end(), e.conn, [](const Ros1Connection& c, std::uint32_t id) {
      return c.id < id;
    })->messages++;
}

Ros1Bag::~Ros1Bag() = default;

void Ros1Bag::openV20() {
  File file(in_, size_, path_);
  const FileRecord head = file.record(kMagic20.size(), "file header");
  file.expectOp(head, kFileHeader, "file header");
  const std::string what = fmt::format("file header at byte {}", head.pos);
  if (const auto enc = head.fields.get("encryptor"); enc && !enc->empty())
    throw Error(ErrorKind::kUnsupported, fmt::format("encrypted bag ({}) is not supported", *enc), {path_});
  const std::uint64_t index_pos = number(head.fields, "index_pos", 8, what, path_);
  const std::uint64_t conn_count = number(head.fields, "conn_count", 4, what, path_);
  const std::uint64_t chunk_count = number(head.fields, "chunk_count", 4, what, path_);
  if (index_pos == 0)
    throw badInput("bag has no index (the recording was not closed); 'rosbag reindex' can rebuild it", {path_});
  // (An empty recording's index is empty and starts at the end of the file.)
  if (index_pos > size_ || (index_pos == size_ && conn_count + chunk_count > 0))
    throw badInput(fmt::format("truncated bag: its index should start at byte {} but the file has {} bytes (an "
                               "interrupted recording or copy? 'rosbag reindex' can rebuild the index)",
                               index_pos, size_),
                   {path_});

  // The index: the connection records, then one chunk info record per chunk (the writer's order;
  // either kind is accepted in any order).
  struct ChunkInfo {
    std::uint64_t pos;
    std::size_t connections;
  };
  std::vector<ChunkInfo> infos;
  std::uint64_t pos = index_pos;
  for (std::uint64_t i = 0; i < conn_count + chunk_count; ++i) {
    const FileRecord r = file.record(pos, "index record");
    const std::string at = fmt::format("record at byte {}", r.pos);
    if (r.fields.op == kConnection) {
      Ros1Connection c;
      c.id = static_cast<std::uint32_t>(number(r.fields, "conn", 4, "connection " + at, path_));
      c.topic = text(r.fields, "topic", "connection " + at, path_);
      const std::vector<std::uint8_t> data = file.bytes(r.data_at, r.data_len, "connection " + at);
      const Fields def = parseFields(data.data(), data.size(), r.data_at, " (a connection's data)", path_);
      c.type = text(def, "type", "connection " + at, path_);
      c.md5sum = text(def, "md5sum", "connection " + at, path_);
      for (const auto& other : connections_)
        if (other.id == c.id)
          throw badInput(fmt::format("not a readable ROS1 bag: connection {} is declared twice (the second time at "
                                     "byte {})",
                                     c.id, r.pos),
                         {path_});
      connections_.push_back(std::move(c));
    } else if (r.fields.op == kChunkInfo) {
      const std::string w = "chunk info " + at;
      if (number(r.fields, "ver", 4, w, path_) != 1)
        throw badInput(fmt::format("not a readable ROS1 bag: the {} has version {}, not 1", w,
                                   number(r.fields, "ver", 4, w, path_)),
                       {path_});
      const std::uint64_t count = number(r.fields, "count", 4, w, path_);
      if (count > r.data_len / 8)
        throw badInput(
            fmt::format("not a readable ROS1 bag: the {} lists {} connections in {} bytes", w, count, r.data_len),
            {path_});
      infos.push_back({number(r.fields, "chunk_pos", 8, w, path_), static_cast<std::size_t>(count)});
    } else {
      throw badInput(fmt::format("not a readable ROS1 bag: the index at byte {} holds a record of op {} at byte {} "
                                 "(expected connection and chunk info records)",
                                 index_pos, r.fields.op, r.pos),
                     {path_});
    }
    pos = r.end;
  }
  std::sort(infos.begin(), infos.end(), [](const auto& a, const auto& b) { return a.pos < b.pos; });
  for (std::size_t i = 1; i < infos.size(); ++i)
    if (infos[i].pos == infos[i - 1].pos)  // (its messages would be read twice)
      throw badInput(fmt::format("not a readable ROS1 bag: the index lists the chunk at byte {} twice", infos[i].pos),
                     {path_});
  auto declared = [&](std::uint32_t id) {
    return std::any_of(connections_.begin(), connections_.end(), [&](const auto& c) { return c.id == id; });
  };

  // Each chunk's header and the index records after it (one per connection in the chunk).
  for (const ChunkInfo& info : infos) {
    const FileRecord c = file.record(info.pos, "chunk");
    file.expectOp(c, kChunk, "chunk");
    Chunk chunk;
    chunk.pos = c.pos;
    chunk.data_at = c.data_at;
    chunk.data_len = c.data_len;
    chunk.compression = text(c.fields, "compression", fmt::format("chunk at byte {}", c.pos), path_);
    if (chunk.compression != "none" && chunk.compression != "bz2" && chunk.compression != "lz4")
      throw Error(ErrorKind::kUnsupported,
                  fmt::format("the chunk at byte {} is compressed with '{}' (lidar2d reads none, bz2 and lz4)", c.pos,
                              chunk.compression),
                  {path_});
    chunk.size = chunk.compression == "none"
                     ? c.data_len
                     : number(c.fields, "size", 4, fmt::format("chunk at byte {}", c.pos), path_);
    const auto chunk_no = static_cast<std::uint32_t>(chunks_.size());
    std::uint64_t p = c.end;
    for (std::size_t k = 0; k < info.connections; ++k) {
      const FileRecord r = file.record(p, "index record");
      file.expectOp(r, kIndexData, "index record");
      const std::string w = fmt::format("index record at byte {}", r.pos);
      if (const auto ver = number(r.fields, "ver", 4, w, path_); ver != 1)
        throw badInput(fmt::format("not a readable ROS1 bag: the {} has version {}, not 1", w, ver), {path_});
      IndexRecord index;
      index.pos = r.pos;
      index.conn = static_cast<std::uint32_t>(number(r.fields, "conn", 4, w, path_));
      if (!declared(index.conn))
        throw badInput(fmt::format("not a readable ROS1 bag: the {} names connection {}, which the bag does not "
                                   "declare",
                                   w, index.conn),
                       {path_});
      const std::uint64_t count = number(r.fields, "count", 4, w, path_);
      // (laser_scan_matcher_demo.bag states a data length other than count x 12: the count is trusted.)
      if (count > r.data_len / kIndexEntryBytes)
        throw badInput(fmt::format("corrupt index record at byte {}: {} entries of {} bytes do not fit its {} bytes",
                                   r.pos, count, kIndexEntryBytes, r.data_len),
                       {path_});
      const std::vector<std::uint8_t> data = file.bytes(r.data_at, count * kIndexEntryBytes, w);
      index.offsets.reserve(count);
      for (std::uint64_t e = 0; e < count; ++e) {
        const std::uint8_t* entry = data.data() + e * kIndexEntryBytes;
        const std::uint32_t offset = u32(entry + 8);
        if (chunk.size < 8 || offset > chunk.size - 8)
          throw badInput(fmt::format("corrupt index record at byte {}: entry {} points to byte {} of the chunk at byte "
                                     "{}, past its end (the chunk holds {} bytes)",
                                     r.pos, e, offset, chunk.pos, chunk.size),
                         {path_});
        index.offsets.push_back(offset);
        entries_.push_back({nanos(u32(entry), u32(entry + 4)), index.conn, chunk_no, offset, 0});
      }
      chunk.index.push_back(std::move(index));
      p = r.end;
    }
    chunks_.push_back(std::move(chunk));
  }
  // File order: by chunk, then by offset in it.
  std::sort(entries_.begin(), entries_.end(), [](const Ros1Entry& a, const Ros1Entry& b) {
    return a.chunk != b.chunk ? a.chunk < b.chunk : a.offset < b.offset;
  });
}

void Ros1Bag::openV12() {
  // Records one after the other: the file header, each topic's message definition before its first
  // message, the messages, and (at the end) per-topic index records, which are not needed here.
  File file(in_, size_, path_);
  for (std::uint64_t pos = kMagic12.size(); pos < size_;) {
    const FileRecord r = file.record(pos, "record");
    const std::string w = fmt::format("record at byte {}", r.pos);
    if (r.fields.op == kMessageDefinition || r.fields.op == kMessageData) {
      const std::string topic = text(r.fields, "topic", w, path_);
      auto it = std::find_if(connections_.begin(), connections_.end(), [&](const auto& c) { return c.topic == topic; });
      if (it == connections_.end()) {
        const auto type = r.fields.get("type");
        const auto md5 = r.fields.get("md5");
        if (!type || !md5)
          throw badInput(fmt::format("not a readable ROS1 bag: the message {} on topic {} comes before the topic's "
                                     "definition",
                                     w, topic),
                         {path_});
        connections_.push_back(
            {static_cast<std::uint32_t>(connections_.size()), topic, std::string(*type), std::string(*md5), 0});
        it = connections_.end() - 1;
      }
      if (r.fields.op == kMessageData) {
        const auto sec = static_cast<std::uint32_t>(number(r.fields, "sec", 4, "message " + w, path_));
        const auto nsec = static_cast<std::uint32_t>(number(r.fields, "nsec", 4, "message " + w, path_));
        entries_.push_back({nanos(sec, nsec), it->id, 0, r.data_at, static_cast<std::uint32_t>(r.data_len)});
      }
    }
    pos = r.end;
  }
}

std::vector<Ros1Entry> Ros1Bag::messages(const std::vector<std::uint32_t>& ids) const {
  std::vector<Ros1Entry> out;
  for (const Ros1Entry& e : entries_)
    if (std::find(ids.begin(), ids.end(), e.conn) != ids.end()) out.push_back(e);
  std::stable_sort(out.begin(), out.end(), [](const Ros1Entry& a, const Ros1Entry& b) { return a.time < b.time; });
  return out;
}

// Decompresses a chunk (its stored bytes `raw`), walks its records and checks its index entries
// against them. Touches no member of the bag but the (immutable) chunk table, so it may run on
// another thread (see load()).
std::unique_ptr<Ros1Bag::CachedChunk> Ros1Bag::decode(std::uint32_t chunk_no, std::vector<std::uint8_t> raw) const {
  const Chunk& chunk = chunks_.at(chunk_no);
  auto c = std::make_unique<CachedChunk>();
  c->chunk = chunk_no;
  const std::string where = fmt::format("chunk at byte {}", chunk.pos);
  const DecompressContext context{fmt::format("not a readable ROS1 bag: the {}: ", where), {path_}};
  if (chunk.compression == "bz2")
    c->data = decompress(Codec::kBz2, raw, chunk.size, /*exact=*/true, context);
  else if (chunk.compression == "lz4")
    c->data = decompress(Codec::kLz4, raw, chunk.size, /*exact=*/true, context);
  else
    c->data = std::move(raw);

  // Its records, back to back (connection and message records), each within the chunk.
  const std::vector<std::uint8_t>& d = c->data;
  const std::string of = " of the " + where;
  for (std::uint64_t q = 0; q < d.size();) {
    const std::uint64_t left = d.size() - q;
    const std::uint32_t hlen = left < 8 ? 0 : u32(d.data() + q);
    if (left < 8 || hlen > left - 8 || u32(d.data() + q + 4 + hlen) > left - 8 - hlen)
      throw badInput(
          fmt::format("not a readable ROS1 bag: the record at byte {}{} runs past the chunk's end ({} bytes)", q, of,
                      d.size()),
          {path_});
    const Fields f = parseFields(d.data() + q + 4, hlen, q, of, path_);
    CachedChunk::Record rec;
    rec.offset = q;
    rec.op = f.op;
    rec.data_at = q + 8 + hlen;
    rec.data_len = u32(d.data() + q + 4 + hlen);
    if (f.op == kMessageData)
      rec.conn =
          static_cast<std::uint32_t>(number(f, "conn", 4, fmt::format("message record at byte {}{}", q, of), path_));
    c->records.push_back(rec);
    q = rec.data_at + rec.data_len;
  }

  // Each index entry must point to a message record of its connection.
  for (const IndexRecord& index : chunk.index)
    for (std::size_t e = 0; e < index.offsets.size(); ++e) {
      const std::uint32_t offset = index.offsets[e];
      const auto it = std::lower_bound(c->records.begin(), c->records.end(), offset,
                                       [](const CachedChunk::Record& r, std::uint64_t o) { return r.offset < o; });
      const std::string entry = fmt::format("corrupt index record at byte {}: entry {} points to byte {} of the {}",
                                            index.pos, e, offset, where);
      if (it == c->records.end() || it->offset != offset)
        throw badInput(fmt::format("{}, where no record starts (the chunk holds {} bytes)", entry, d.size()), {path_});
      if (it->op != kMessageData)
        throw badInput(fmt::format("{}, which holds a record of op {}, not a message", entry, it->op), {path_});
      if (*it->conn != index.conn)
        throw badInput(fmt::format("{}, a message of connection {}, not {}", entry, *it->conn, index.conn), {path_});
    }
  return c;
}

std::vector<std::unique_ptr<Ros1Bag::CachedChunk>>::iterator Ros1Bag::cached(std::uint32_t chunk_no) {
  return std::find_if(cache_.begin(), cache_.end(), [&](const auto& c) { return c->chunk == chunk_no; });
}

const Ros1Bag::CachedChunk& Ros1Bag::load(std::uint32_t chunk_no) {
  if (const auto hit = cached(chunk_no); hit != cache_.end()) {
    std::rotate(cache_.begin(), hit, hit + 1);
    return *cache_.front();
  }
  File file(in_, size_, path_);
  auto stored = [&](std::uint32_t k) {
    const Chunk& chunk = chunks_.at(k);
    return file.bytes(chunk.data_at, chunk.data_len, fmt::format("chunk at byte {}", chunk.pos));
  };
  std::unique_ptr<CachedChunk> c;
  if (const auto it = pending_.find(chunk_no); it != pending_.end()) {
    auto future = std::move(it->second);
    pending_.erase(it);
    c = future.get();  // (rethrows the chunk's error)
  } else {
    c = decode(chunk_no, stored(chunk_no));
  }
  // The next chunks in file order are the likeliest next reads (messages in time order are
  // nearly in file order): decompress them on other threads meanwhile, so that a full read of a
  // compressed bag uses both cores (bz2 is about 80% of reading one). A chunk prefetched but never
  // read costs only the work; its error, if any, is never reported.
  for (std::uint32_t k = chunk_no + 1; k < chunks_.size() && k <= chunk_no + kPrefetch; ++k) {
    if (cached(k) != cache_.end() || pending_.count(k) || chunks_[k].compression == "none") continue;
    try {
      pending_.emplace(k, std::async(std::launch::async,
                                     [this, k, raw = stored(k)]() mutable { return decode(k, std::move(raw)); }));
    } catch (const std::system_error&) {  // no thread to be had: the chunk is decompressed when read
      break;
    }
  }
  // Prefetches that fell behind (the reads went elsewhere) are dropped; their threads finish first.
  for (auto it = pending_.begin(); it != pending_.end();)
    it = (it->first < chunk_no || it->first > chunk_no + kPrefetch) ? pending_.erase(it) : std::next(it);

  if (cache_.size() < 2) cache_.emplace_back();
  cache_.back() = std::move(c);
  std::rotate(cache_.begin(), cache_.end() - 1, cache_.end());
  return *cache_.front();
}

std::span<const std::uint8_t> Ros1Bag::read(const Ros1Entry& e) {
  if (v12_) {  // the data is in the file
    File file(in_, size_, path_);
    buffer_ = file.bytes(e.offset, e.size, fmt::format("message at byte {}", e.offset));
    return buffer_;
  }
  const CachedChunk& c = load(e.chunk);
  const auto it = std::lower_bound(c.records.begin(), c.records.end(), e.offset,
                                   [](const CachedChunk::Record& r, std::uint64_t o) { return r.offset < o; });
  // (load() checked that every index entry is a message record.)
  return {c.data.data() + it->data_at, static_cast<std::size_t>(it->data_len)};
}

}  // namespace lidar2d::io::internal
