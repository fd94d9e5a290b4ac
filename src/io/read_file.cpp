#include "src/io/internal/read_file.hpp"

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <fstream>

#include <fmt/format.h>

#include "lidar2d/core/error.hpp"

namespace lidar2d::io::internal {

namespace {
std::string withArticle(const std::string& what) {
  const bool vowel = !what.empty() && std::string("aeiou").find(what.front()) != std::string::npos;
  return (vowel ? "an " : "a ") + what;
}
}  // namespace

bool checkInputFile(const std::string& path, const std::string& what, const std::string& field) {
  namespace fs = std::filesystem;
  const ErrorLocation where(path, 0, field);
  std::error_code ec;
  const fs::file_status st = fs::status(path, ec);
  if (ec || !fs::exists(st)) {
    if (!ec || ec == std::errc::no_such_file_or_directory) throw ioError(what + " does not exist", where);
    throw ioError(fmt::format("cannot read the {}: {}", what, ec.message()), where);
  }
  if (fs::is_directory(st)) throw badInput("is a directory, not " + withArticle(what), where);
  if (fs::is_regular_file(st)) return true;
  if (!fs::is_fifo(st)) throw badInput("is a device or socket, not " + withArticle(what), where);
  return false;
}

std::string readWholeFile(const std::string& path, std::uint64_t max_bytes, const std::string& what,
                          const std::string& field) {
  const ErrorLocation where(path, 0, field);
  const bool regular = checkInputFile(path, what, field);
  auto tooLarge = [&](const std::string& size) {
    return badInput(fmt::format("{} than the {} MiB limit for {}", size, max_bytes >> 20, withArticle(what)), where);
  };
  std::uint64_t expected = 0;
  if (regular) {
    std::error_code ec;
    expected = std::filesystem::file_size(path, ec);
    if (ec) throw ioError(fmt::format("cannot read the {}: {}", what, ec.message()), where);
    if (expected > max_bytes) throw tooLarge(fmt::format("is {} bytes, more", expected));
  }
  std::ifstream in(path, std::ios::binary);
  if (!in) throw ioError(fmt::format("cannot read the {}: {}", what, std::strerror(errno)), where);
  std::string data;
  data.reserve(static_cast<std::size_t>(expected));
  char buf[1 << 16];
  while (in.read(buf, sizeof buf) || in.gcount() > 0) {
    data.append(buf, static_cast<std::size_t>(in.gcount()));
    if (data.size() > max_bytes) throw tooLarge("holds more");
  }
  if (in.bad()) throw ioError(fmt::format("read error in the {}", what), where);
  return data;
}

}  // namespace lidar2d::io::internal
