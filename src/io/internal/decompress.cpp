#include "src/io/internal/decompress.hpp"

#include <bzlib.h>
#include <fmt/format.h>
#include <lz4frame.h>
#include <zstd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <fstream>
#include <initializer_list>
#include <memory>

namespace lidar2d::io::internal {
namespace {

class Output {
 public:
  Output(std::uint64_t size, bool exact, const DecompressContext& context)
      : size_(size), exact_(exact), context_(context) {}

  /// Room for more output: the free tail of the buffer, grown (doubling from 1 MiB) up to the
  /// stated size. Empty once the buffer holds `size` bytes.
  std::span<std::uint8_t> room() {
    if (produced_ == out_.size() && out_.size() < size_)
      out_.resize(std::min<std::uint64_t>(size_, std::max<std::uint64_t>(out_.size() * 2, std::uint64_t{1} << 20)));
    return {out_.data() + produced_, out_.size() - produced_};
  }
  void produced(std::size_t n) { produced_ += n; }
  bool full() const { return produced_ >= size_; }
  std::vector<std::uint8_t> finish() {
    if (exact_ && produced_ != size_)
      fail(fmt::format("it decompresses to {} bytes, not the {} its header states", produced_, size_));
    out_.resize(produced_);
    return std::move(out_);
  }
  [[noreturn]] void tooLong() const {
    fail(exact_ ? fmt::format("it decompresses to more than the {} bytes its header states", size_)
                : fmt::format("it decompresses to more than {} bytes", size_));
  }
  [[noreturn]] void fail(const std::string& why) const { throw badInput(context_.prefix + why, context_.where); }

 private:
  std::uint64_t size_;
  bool exact_;
  const DecompressContext& context_;
  std::vector<std::uint8_t> out_;
  std::size_t produced_ = 0;
};

std::vector<std::uint8_t> bz2(std::span<const std::uint8_t> in, Output& out) {
  bz_stream s{};
  if (BZ2_bzDecompressInit(&s, 0, 0) != BZ_OK) out.fail("bzip2 could not start");
  struct End {
    bz_stream* s;
    ~End() { BZ2_bzDecompressEnd(s); }
  } end{&s};
  // libbz2 takes a non-const pointer but does not write through next_in.
  s.next_in = const_cast<char*>(reinterpret_cast<const char*>(in.data()));
  s.avail_in = static_cast<unsigned>(in.size());
  for (;;) {
    // A call with no room left is still made: the stream's end marker may follow the last byte.
    const auto room = out.room();
    s.next_out = reinterpret_cast<char*>(room.data());
    s.avail_out = static_cast<unsigned>(std::min<std::size_t>(room.size(), 1u << 30));
    const unsigned before_in = s.avail_in, before_out = s.avail_out;
    const int rc = BZ2_bzDecompress(&s);
    out.produced(before_out - s.avail_out);
    if (rc == BZ_STREAM_END) break;
    if (rc != BZ_OK) out.fail(fmt::format("corrupt bz2 data (bzip2 error {})", rc));
    if (s.avail_in == before_in && s.avail_out == before_out) {
      if (room.empty()) out.tooLong();
      out.fail("the bz2 data ends early (truncated)");
    }
  }
  return out.finish();
}

std::vector<std::uint8_t> lz4(std::span<const std::uint8_t> in, Output& out) {
  LZ4F_dctx* raw = nullptr;
  if (LZ4F_isError(LZ4F_createDecompressionContext(&raw, LZ4F_VERSION))) out.fail("lz4 could not start");
  std::unique_ptr<LZ4F_dctx, decltype(&LZ4F_freeDecompressionContext)> ctx(raw, &LZ4F_freeDecompressionContext);
  std::size_t consumed = 0;
  for (;;) {
    const auto room = out.room();
    std::size_t dst = room.size(), src = in.size() - consumed;
    const std::size_t rc = LZ4F_decompress(ctx.get(), room.data(), &dst, in.data() + consumed, &src, nullptr);
    if (LZ4F_isError(rc)) out.fail(fmt::format("corrupt lz4 data ({})", LZ4F_getErrorName(rc)));
    out.produced(dst);
    consumed += src;
    if (rc == 0) break;  // the frame is complete
    if (dst == 0 && src == 0) {
      if (consumed == in.size()) out.fail("the lz4 data ends early (truncated)");
      out.tooLong();
    }
  }
  return out.finish();
}

struct ZstdFree {
  void operator()(ZSTD_DCtx* c) const { ZSTD_freeDCtx(c); }
};

std::vector<std::uint8_t> zstd(std::span<const std::uint8_t> in, Output& out) {
  std::unique_ptr<ZSTD_DCtx, ZstdFree> ctx(ZSTD_createDCtx());
  if (!ctx) out.fail("zstd could not start");
  ZSTD_inBuffer src{in.data(), in.size(), 0};
  std::size_t rc = 1;
  while (src.pos < src.size) {
    const auto room = out.room();
    ZSTD_outBuffer dst{room.data(), room.size(), 0};
    rc = ZSTD_decompressStream(ctx.get(), &dst, &src);
    if (ZSTD_isError(rc)) out.fail(fmt::format("corrupt zstd data ({})", ZSTD_getErrorName(rc)));
    out.produced(dst.pos);
    if (dst.pos == 0 && room.empty()) out.tooLong();
  }
  // Input used up: flush what the decoder still holds; rc == 0 means the last frame is complete.
  while (rc != 0) {
    const auto room = out.room();
    ZSTD_outBuffer dst{room.data(), room.size(), 0};
    rc = ZSTD_decompressStream(ctx.get(), &dst, &src);
    if (ZSTD_isError(rc)) out.fail(fmt::format("corrupt zstd data ({})", ZSTD_getErrorName(rc)));
    out.produced(dst.pos);
    if (dst.pos == 0) {
      if (room.empty() && out.full()) out.tooLong();
      out.fail("the zstd data ends early (truncated)");
    }
  }
  return out.finish();
}

}  // namespace

std::vector<std::uint8_t> decompress(Codec codec, std::span<const std::uint8_t> in, std::uint64_t size, bool exact,
                                     const DecompressContext& context) {
  Output out(size, exact, context);
  switch (codec) {
    case Codec::kBz2:
      return bz2(in, out);
    case Codec::kLz4:
      return lz4(in, out);
    case Codec::kZstd:
      return zstd(in, out);
  }
  out.fail("unknown codec");
}

void decompressZstdFile(const std::filesystem::path& in, const std::filesystem::path& out, std::uint64_t max_bytes,
                        const DecompressContext& context) {
  auto fail = [&](const std::string& why) {
    std::error_code ec;
    std::filesystem::remove(out, ec);
    throw badInput(context.prefix + why, context.where);
  };
  std::ifstream src(in, std::ios::binary);
  if (!src) throw ioError(fmt::format("cannot open: {}", std::strerror(errno)), context.where);
  std::ofstream dst(out, std::ios::binary | std::ios::trunc);
  if (!dst) throw ioError(fmt::format("cannot write the decompressed copy {}: {}", out.string(), std::strerror(errno)));
  std::unique_ptr<ZSTD_DCtx, ZstdFree> ctx(ZSTD_createDCtx());
  if (!ctx) fail("zstd could not start");
  std::vector<char> ibuf(ZSTD_DStreamInSize()), obuf(ZSTD_DStreamOutSize());
  std::uint64_t written = 0;
  std::size_t rc = 0;
  bool any = false;
  while (src) {
    src.read(ibuf.data(), static_cast<std::streamsize>(ibuf.size()));
    const auto n = static_cast<std::size_t>(src.gcount());
    if (n == 0) break;
    any = true;
    ZSTD_inBuffer ib{ibuf.data(), n, 0};
    while (ib.pos < ib.size) {
      ZSTD_outBuffer ob{obuf.data(), obuf.size(), 0};
      rc = ZSTD_decompressStream(ctx.get(), &ob, &ib);
      if (ZSTD_isError(rc)) fail(fmt::format("corrupt zstd data ({})", ZSTD_getErrorName(rc)));
      written += ob.pos;
      if (written > max_bytes) fail(fmt::format("it decompresses to more than {} bytes", max_bytes));
      dst.write(obuf.data(), static_cast<std::streamsize>(ob.pos));
    }
  }
  if (src.bad()) fail("read error");
  if (!any) fail("the file is empty");
  // The input is used up; a frame still open (rc != 0) means the file was cut short.
  while (rc != 0) {
    ZSTD_inBuffer ib{nullptr, 0, 0};
    ZSTD_outBuffer ob{obuf.data(), obuf.size(), 0};
    rc = ZSTD_decompressStream(ctx.get(), &ob, &ib);
    if (ZSTD_isError(rc)) fail(fmt::format("corrupt zstd data ({})", ZSTD_getErrorName(rc)));
    if (ob.pos == 0) fail("the zstd data ends early (truncated)");
    written += ob.pos;
    if (written > max_bytes) fail(fmt::format("it decompresses to more than {} bytes", max_bytes));
    dst.write(obuf.data(), static_cast<std::streamsize>(ob.pos));
  }
  dst.close();
  if (!dst) fail(fmt::format("cannot write the decompressed copy {}", out.string()));
}

const char* compressionMagic(std::span<const unsigned char> head) {
  struct Magic {
    const char* name;
    std::initializer_list<unsigned char> bytes;
  };
  static const Magic kMagics[] = {{"gzip", {0x1f, 0x8b}},
                                  {"bzip2", {'B', 'Z', 'h'}},
                                  {"zstd", {0x28, 0xb5, 0x2f, 0xfd}},
                                  {"xz", {0xfd, '7', 'z', 'X', 'Z', 0x00}},
                                  {"lz4", {0x04, 0x22, 0x4d, 0x18}},
                                  {"zip", {'P', 'K', 0x03, 0x04}},
                                  {"7z", {'7', 'z', 0xbc, 0xaf, 0x27, 0x1c}}};
  for (const Magic& m : kMagics)
    if (head.size() >= m.bytes.size() && std::equal(m.bytes.begin(), m.bytes.end(), head.begin())) return m.name;
  return nullptr;
}

}  // namespace lidar2d::io::internal
