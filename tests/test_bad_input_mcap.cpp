// Bad MCAP files and bad rosbag2 bag folders (split, compressed): each gives one lidar2d::Error
// naming the file and the byte offset or field, and through the CLI exit code 1 with one stderr
// line and nothing on stdout. The inputs are the reference writer's fixtures (tests/fixtures/mcap),
// cut or patched here.

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cstring>
#include <filesystem>
#include <string>
#include <vector>

#include "lidar2d/core/error.hpp"
#include "lidar2d/io/frame_source.hpp"
#include "support/test_support.hpp"

namespace lidar2d::io {
namespace {

namespace fs = std::filesystem;
using ::testing::HasSubstr;

fs::path fixture(const std::string& name) { return test::sourceFile("tests/fixtures/mcap") / name; }

void readAll(const fs::path& p) {
  auto src = openLog(p.string());
  while (src->next()) {
  }
}

/// Expects an Error of `kind` whose message contains every part.
void expectError(const fs::path& p, ErrorKind kind, std::initializer_list<std::string> parts) {
  EXPECT_TRUE(test::throwsError([&] { readAll(p); }, kind, parts));
}

/// `lidar2d info` and `lidar2d map` fail with exit 1, one stderr line containing `parts`, nothing
/// on stdout and no output file.
void expectCliError(const fs::path& p, std::initializer_list<std::string> parts) {
  test::TempDir out;
  for (const auto& args : std::vector<std::vector<std::string>>{
           {"info", p.string()}, {"map", p.string(), "-o", (out / "m").string()}}) {
    const auto r = test::runCli(args);
    EXPECT_EQ(r.exit_code, 1) << r.err;
    EXPECT_EQ(r.out, "");
    for (const auto& part : parts) EXPECT_THAT(r.err, HasSubstr(part));
    ASSERT_FALSE(r.err.empty());
    EXPECT_EQ(r.err.find('\n'), r.err.size() - 1) << "more than one line: " << r.err;
  }
  EXPECT_TRUE(fs::is_empty(out.path()));
}

std::string bytes(const fs::path& p) { return test::readFile(p); }

std::uint64_t u64At(const std::string& b, std::size_t at) {
  std::uint64_t v;
  std::memcpy(&v, b.data() + at, 8);
  return v;
}

/// Offset of the first record with opcode `op` (top level, after the magic).
std::size_t firstRecord(const std::string& b, std::uint8_t op) {
  for (std::size_t at = 8; at + 9 <= b.size(); at += 9 + u64At(b, at + 1))
    if (static_cast<std::uint8_t>(b[at]) == op) return at;
  ADD_FAILURE() << "no record " << int(op);
  return 0;
}

TEST(BadMcap, EveryTruncationIsOneError) {
  const std::string full = bytes(fixture("chunked_zstd.mcap"));
  test::TempDir tmp;
  const fs::path f = tmp / "cut.mcap";
  // Every cut in the magic, the Header and the start of the first chunk, then every 29th byte, then
  // every cut in the file's last bytes (Data End, summary, Footer, closing magic).
  std::vector<std::size_t> cuts;
  for (std::size_t n = 1; n < full.size(); n += (n < 300 || n + 120 > full.size()) ? 1 : 29) cuts.push_back(n);
  for (const std::size_t n : cuts) {
    test::writeFile(f, full.substr(0, n));
    try {
      readAll(f);
      ADD_FAILURE() << "no error for " << n << " bytes";
    } catch (const Error& e) {
      ASSERT_EQ(e.where().file, f.string()) << n << ": " << e.what();
      // A cut inside the magic is plain text to detectFormat; the rest is reported by byte offset.
      if (n >= 5) {
        ASSERT_THAT(e.what(), HasSubstr("byte")) << n;
      }
    }
  }
  test::writeFile(f, full.substr(0, full.size() - 3));
  expectCliError(f, {f.string(), "closing magic", "truncated"});
}

TEST(BadMcap, WrongMagic) {
  test::TempDir tmp;
  std::string b = bytes(fixture("unchunked.mcap"));
  b[3] = 'X';  // "\x89MCXP": not MCAP, read as a (binary) CARMEN log
  test::writeFile(tmp / "a.mcap", b);
  EXPECT_TRUE(test::throwsError([&] { readAll(tmp / "a.mcap"); }, ErrorKind::kBadInput, {"a.mcap"}));
  b = bytes(fixture("unchunked.mcap"));
  b[5] = '1';  // a future major version
  test::writeFile(tmp / "v1.mcap", b);
  expectError(tmp / "v1.mcap", ErrorKind::kUnsupported, {"v1.mcap", "magic at byte 5", "major version '1'"});
  b = bytes(fixture("unchunked.mcap"));
  b[b.size() - 2] = 'x';  // closing magic
  test::writeFile(tmp / "end.mcap", b);
  expectError(tmp / "end.mcap", ErrorKind::kBadInput, {"end.mcap", "closing magic at byte", "not followed by the MCAP magic"});
}

TEST(BadMcap, ChunkCrcMismatch) {
  test::TempDir tmp;
  std::string b = bytes(fixture("chunked.mcap"));
  const std::size_t chunk = firstRecord(b, 0x06);
  b[chunk + 200] ^= 0x01;  // a byte of the (uncompressed) records
  test::writeFile(tmp / "crc.mcap", b);
  expectError(tmp / "crc.mcap", ErrorKind::kBadInput,
              {"crc.mcap", "Chunk.uncompressed_crc at byte " + std::to_string(chunk), "not the"});
  expectCliError(tmp / "crc.mcap", {"crc.mcap", "uncompressed_crc"});
}

TEST(BadMcap, DataSectionCrcMismatch) {
  test::TempDir tmp;
  std::string b = bytes(fixture("unchunked.mcap"));
  const std::size_t msg = firstRecord(b, 0x05);
  b[msg + 9 + 22 + 10] ^= 0x40;  // inside the message's data
  test::writeFile(tmp / "data.mcap", b);
  expectError(tmp / "data.mcap", ErrorKind::kBadInput, {"data.mcap", "Data End.data_section_crc at byte"});
}

TEST(BadMcap, AbsurdChunkSize) {
  test::TempDir tmp;
  std::string b = bytes(fixture("chunked_zstd.mcap"));
  const std::size_t chunk = firstRecord(b, 0x06);
  const std::uint64_t huge = std::uint64_t{1} << 40;
  std::memcpy(b.data() + chunk + 9 + 16, &huge, 8);  // uncompressed_size
  test::writeFile(tmp / "huge.mcap", b);
  expectError(tmp / "huge.mcap", ErrorKind::kBadInput,
              {"huge.mcap", "Chunk.uncompressed_size at byte " + std::to_string(chunk), "1099511627776"});
  // A size a little off is caught by the decompressor.
  const std::uint64_t off_by_one = u64At(bytes(fixture("chunked_zstd.mcap")), chunk + 9 + 16) + 1;
  std::memcpy(b.data() + chunk + 9 + 16, &off_by_one, 8);
  test::writeFile(tmp / "off.mcap", b);
  expectError(tmp / "off.mcap", ErrorKind::kBadInput, {"off.mcap", "Chunk.records at byte", "its header states"});
  // A record length beyond the end of the file.
  b = bytes(fixture("chunked_zstd.mcap"));
  std::memcpy(b.data() + chunk + 1, &huge, 8);
  test::writeFile(tmp / "len.mcap", b);
  expectError(tmp / "len.mcap", ErrorKind::kBadInput, {"len.mcap", "Chunk record length at byte", "truncated"});
}

TEST(BadMcap, UnknownCompression) {
  test::TempDir tmp;
  std::string b = bytes(fixture("chunked_zstd.mcap"));
  const std::size_t chunk = firstRecord(b, 0x06);
  ASSERT_EQ(b.substr(chunk + 9 + 28 + 4, 4), "zstd");
  b[chunk + 9 + 28 + 4 + 3] = 'x';
  test::writeFile(tmp / "zstx.mcap", b);
  expectError(tmp / "zstx.mcap", ErrorKind::kUnsupported,
              {"zstx.mcap", "Chunk.compression at byte " + std::to_string(chunk), "'zstx'"});
  expectCliError(tmp / "zstx.mcap", {"zstx.mcap", "'zstx'"});
}

TEST(BadMcap, CorruptCompressedChunk) {
  test::TempDir tmp;
  std::string b = bytes(fixture("chunked_lz4.mcap"));
  const std::size_t chunk = firstRecord(b, 0x06);
  for (std::size_t i = 60; i < 90; ++i) b[chunk + i] = 0;
  test::writeFile(tmp / "lz4.mcap", b);
  // liblz4 rejects it (Chunk.records), or the CRC does (Chunk.uncompressed_crc): either names the chunk.
  expectError(tmp / "lz4.mcap", ErrorKind::kBadInput, {"lz4.mcap", "at byte " + std::to_string(chunk) + ":"});
}

/// A copy of a fixture bag folder in `tmp`.
fs::path copyBag(const test::TempDir& tmp, const std::string& name) {
  fs::copy(fixture(name), tmp / name, fs::copy_options::recursive);
  return tmp / name;
}

TEST(BadRosbag2Folder, MissingSplitFile) {
  test::TempDir tmp;
  const fs::path bag = copyBag(tmp, "split");
  fs::remove(bag / "split_1.mcap");
  expectError(bag, ErrorKind::kIo, {(bag / "metadata.yaml").string(), "relative_file_paths", "split_1.mcap"});
  expectCliError(bag, {"metadata.yaml", "split_1.mcap"});
}

TEST(BadRosbag2Folder, TruncatedCompressedFile) {
  test::TempDir tmp;
  const fs::path bag = copyBag(tmp, "compressed_file");
  const std::string b = bytes(bag / "c_1.mcap.zstd");
  test::writeFile(bag / "c_1.mcap.zstd", b.substr(0, b.size() / 2));
  expectError(bag, ErrorKind::kBadInput, {(bag / "c_1.mcap.zstd").string(), "compression_mode FILE", "truncated"});
  expectCliError(bag, {"c_1.mcap.zstd", "truncated"});
}

TEST(BadRosbag2Folder, MessageModeWithUncompressedMessages) {
  test::TempDir tmp;
  const fs::path bag = tmp / "bag";
  fs::create_directory(bag);
  fs::copy_file(fixture("unchunked.mcap"), bag / "u.mcap");
  test::writeFile(bag / "metadata.yaml", "rosbag2_bagfile_information:\n  storage_identifier: mcap\n"
                                         "  relative_file_paths: [u.mcap]\n  compression_format: zstd\n"
                                         "  compression_mode: message\n");
  expectError(bag, ErrorKind::kBadInput, {(bag / "u.mcap").string(), "compression_mode MESSAGE", "message at byte"});
}

TEST(BadRosbag2Folder, UnknownCompressionAndStorage) {
  test::TempDir tmp;
  const fs::path bag = copyBag(tmp, "split");
  const std::string meta = test::readFile(bag / "metadata.yaml");
  auto patched = [&](const std::string& from, const std::string& to) {
    std::string m = meta;
    m.replace(m.find(from), from.size(), to);
    test::writeFile(bag / "metadata.yaml", m);
  };
  patched("compression_format: \"\"\n  compression_mode: \"\"", "compression_format: \"lz4\"\n  compression_mode: FILE");
  expectError(bag, ErrorKind::kUnsupported, {"metadata.yaml", "compression_format", "'lz4'"});
  patched("compression_mode: \"\"", "compression_mode: CHUNK");
  expectError(bag, ErrorKind::kBadInput, {"metadata.yaml", "compression_mode", "'CHUNK'"});
  patched("storage_identifier: mcap", "storage_identifier: hdf5");
  expectError(bag, ErrorKind::kUnsupported, {"metadata.yaml", "storage_identifier", "'hdf5'"});
  patched("relative_file_paths:", "relative_file_paths: [\n");
  expectError(bag, ErrorKind::kBadInput, {"metadata.yaml", "not a readable rosbag2 metadata file"});
}

TEST(BadRosbag2Folder, ZstdFileGivenDirectly) {
  const fs::path f = fixture("compressed_file/c_0.mcap.zstd");
  expectError(f, ErrorKind::kBadInput, {f.string(), "zstd-compressed file: give the rosbag2 bag folder"});
}

}  // namespace
}  // namespace lidar2d::io
