#pragma once
// Lines of a text file, plain or gzip-compressed (zlib's gzopen reads plain files transparently),
// with one clear error for what is no such file: another compression than gzip, binary bytes, a
// line longer than 64 MiB, corrupt or truncated gzip data (raised at the line where the good data
// ends). Shared by the text readers (CARMEN logs, range tables).

#include <fmt/format.h>
#include <zlib.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "lidar2d/core/error.hpp"
#include "src/io/internal/decompress.hpp"

namespace lidar2d::io::internal {

/// How errors name the file's format.
struct TextKind {
  const char* name;       ///< "is a directory, not a <name> file", e.g. "CARMEN log"
  const char* noun;       ///< "not a text <noun> (binary byte ...)", e.g. "log"
  const char* text_name;  ///< "line longer than 64 MiB: not a <text_name>", e.g. "CARMEN text log"
};

inline constexpr std::size_t kMaxLineBytes = 64u << 20;  // longer lines are no text format of ours
inline constexpr std::size_t kReadChunk = 256u << 10;    // bytes per gzread

class TextLineReader {
 public:
  /// Opens `path` (plain or gzip). `kind` words the errors for the file's format.
  TextLineReader(const std::string& path, const TextKind& kind) : path_(path), kind_(kind) {
    namespace fs = std::filesystem;
    std::error_code ec;
    if (!fs::exists(path, ec)) throw ioError("no such file", {path});
    if (fs::is_directory(path, ec)) throw badInput(fmt::format("is a directory, not a {} file", kind_.name), {path});
    refuseCompressed(path);
    errno = 0;
    gz_ = gzopen(path.c_str(), "rb");
    if (!gz_) throw ioError(fmt::format("cannot open: {}", errno ? std::strerror(errno) : "out of memory"), {path});
    gzbuffer(gz_, 1u << 17);
    buf_.resize(kReadChunk * 2);
  }
  ~TextLineReader() {
    if (gz_) gzclose(gz_);
  }
  TextLineReader(const TextLineReader&) = delete;
  TextLineReader& operator=(const TextLineReader&) = delete;

  /// Next line without its end-of-line characters; false at the end of the file.
  bool next(std::string_view& line) {
    for (;;) {
      const char* b = buf_.data() + begin_;
      const char* nl = static_cast<const char*>(std::memchr(b, '\n', end_ - begin_));
      if (nl) {
        const std::size_t len = static_cast<std::size_t>(nl - b);
        begin_ += len + 1;
        return emit(b, len, line);
      }
      if (eof_) {
        // The decompressed data stopped early: report it at the line it cut, not as a short line.
        if (error_) throw *error_;
        if (begin_ == end_) return false;
        const std::size_t len = end_ - begin_;
        begin_ = end_;
        return emit(b, len, line);
      }
      fill();
    }
  }
  std::size_t lineNo() const { return line_; }

 private:
  // A file compressed by another tool than gzip gets one error naming its format, where its bytes
  // would otherwise be reported as a binary line.
  static void refuseCompressed(const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    unsigned char head[8] = {};
    in.read(reinterpret_cast<char*>(head), sizeof head);
    const char* what = compressionMagic({head, static_cast<std::size_t>(in.gcount())});
    if (what && std::string_view(what) != "gzip")
      throw badInput(fmt::format("{}-compressed file: decompress it first (only gzip is read directly)", what), {path});
  }
  bool emit(const char* b, std::size_t len, std::string_view& line) {
    ++line_;
    if (len > 0 && b[len - 1] == '\r') --len;
    line = std::string_view(b, len);
    checkText(line);
    return true;
  }
  // Binary content (control bytes; non-ASCII outside comments) means this is no text file.
  void checkText(std::string_view line) const {
    const bool comment = !line.empty() && line.front() == '#';
    for (std::size_t i = 0; i < line.size(); ++i) {
      const auto c = static_cast<unsigned char>(line[i]);
      const bool bad = (c < 0x20 && c != '\t' && c != '\r' && c != '\f' && c != '\v') || c == 0x7f ||
                       (c >= 0x80 && !comment);
      if (bad)
        throw badInput(fmt::format("not a text {} (binary byte 0x{:02x} at column {})", kind_.noun, c, i + 1),
                       {path_, line_});
    }
  }
  void fill() {
    // Keep the unfinished line, then append the next chunk.
    if (begin_ > 0) {
      std::memmove(buf_.data(), buf_.data() + begin_, end_ - begin_);
      end_ -= begin_;
      begin_ = 0;
    }
    if (end_ > kMaxLineBytes)
      throw badInput(fmt::format("line longer than {} MiB: not a {}", kMaxLineBytes >> 20, kind_.text_name),
                     {path_, line_ + 1});
    if (buf_.size() - end_ < kReadChunk) buf_.resize(end_ + kReadChunk);
    const int n = gzread(gz_, buf_.data() + end_, static_cast<unsigned>(kReadChunk));
    int err = Z_OK;
    const char* msg = gzerror(gz_, &err);
    if (n > 0) end_ += static_cast<std::size_t>(n);
    if (n < 0 || (err != Z_OK && err != Z_STREAM_END)) {
      // zlib hands out what it could decompress before the error; the complete lines in it are
      // still read, and the error is raised where the good data ends (see next()).
      const std::size_t at = line_ + 1 + static_cast<std::size_t>(
                                             std::count(buf_.data() + begin_, buf_.data() + end_, '\n'));
      if (err == Z_ERRNO)
        error_ = ioError(fmt::format("read error: {}", std::strerror(errno)), {path_, at});
      else if (err == Z_BUF_ERROR)
        error_ = badInput("truncated gzip data (the compressed stream ends early)", {path_, at});
      else {
        // zlib prefixes its message with the path, which the location already shows.
        std::string_view why = msg ? msg : "unknown zlib error";
        if (why.rfind(path_ + ": ", 0) == 0) why.remove_prefix(path_.size() + 2);
        error_ = badInput(fmt::format("corrupt gzip data ({})", why), {path_, at});
      }
      eof_ = true;
      return;
    }
    if (n == 0) eof_ = true;
  }

  std::string path_;
  TextKind kind_;
  gzFile gz_ = nullptr;
  std::vector<char> buf_;
  std::size_t begin_ = 0, end_ = 0;
  std::size_t line_ = 0;
  bool eof_ = false;
  std::optional<Error> error_;  // read error to raise once the data before it is consumed
};

}  // namespace lidar2d::io::internal
