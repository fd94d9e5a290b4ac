#pragma once
// Decompression of the compressed blocks inside log containers (ROS1 bag chunks, MCAP chunks,
// rosbag2 messages and files), one implementation for every reader, with the libraries Debian
// packages: libbz2, liblz4 (frame format) and libzstd.
//
// The output buffer grows with what the decompressor actually produces instead of being allocated
// at the size a header states, so a corrupt or hostile size cannot allocate gigabytes; producing
// more or fewer bytes than stated is an error.

#include <cstdint>
#include <filesystem>
#include <span>
#include <string>
#include <vector>

#include "lidar2d/core/error.hpp"

namespace lidar2d::io::internal {

enum class Codec {
  kBz2,   ///< bzip2 stream
  kLz4,   ///< LZ4 frame format (magic 0x184D2204), as roslz4 and MCAP write it
  kZstd,  ///< one or more zstd frames
};

/// Where a decompression failure is reported: the thrown lidar2d::Error (kBadInput) reads
/// "`prefix`why" at `where`.
struct DecompressContext {
  std::string prefix;
  ErrorLocation where;
};

/// Decompresses `in`. With `exact`, the output must be exactly `size` bytes; otherwise `size` is
/// the most it may be. A corrupt or truncated input, or an output of another size, throws as
/// `context` says.
std::vector<std::uint8_t> decompress(Codec codec, std::span<const std::uint8_t> in, std::uint64_t size, bool exact,
                                     const DecompressContext& context);

/// Decompresses the zstd file `in` into the new file `out`, streaming, writing at most `max_bytes`
/// (more is an error, as is a corrupt or truncated input); `out` is removed when it throws. Errors
/// name `in` (the user's file) as `context.where`.
void decompressZstdFile(const std::filesystem::path& in, const std::filesystem::path& out, std::uint64_t max_bytes,
                        const DecompressContext& context);

/// The compression (or archive) format whose magic number `head`, a file's first bytes, starts
/// with: "gzip", "bzip2", "zstd", "xz", "lz4", "zip" or "7z"; nullptr for none of them. The log
/// readers name it in their error for a file they cannot read compressed, where its bytes would
/// otherwise be reported as a malformed text line.
const char* compressionMagic(std::span<const unsigned char> head);

}  // namespace lidar2d::io::internal
