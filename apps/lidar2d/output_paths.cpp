// Output paths checked (and their folders created) before a command starts its work, so that a
// typo in -o fails at once rather than after minutes of mapping.

#include <fmt/format.h>
#include <unistd.h>

#include <filesystem>
#include <string>
#include <system_error>

#include "commands.hpp"
#include "lidar2d/core/error.hpp"

namespace lidar2d::cli {

void prepareOutputDir(const std::string& path) {
  namespace fs = std::filesystem;
  if (path.empty()) throw ioError("output path is empty");
  std::error_code ec;
  fs::create_directories(path, ec);
  if (ec || !fs::is_directory(path, ec))
    throw ioError(fmt::format("cannot create the output folder: {}", ec ? ec.message() : "not a folder"),
                  ErrorLocation(path));
  if (::access(path.c_str(), W_OK | X_OK) != 0) throw ioError("the output folder is not writable", ErrorLocation(path));
}

void prepareOutputFile(const std::string& path) {
  namespace fs = std::filesystem;
  if (path.empty()) throw ioError("output path is empty");
  std::error_code ec;
  if (fs::is_directory(path, ec)) throw ioError("is a folder, expected a file path", ErrorLocation(path));
  const fs::path parent = fs::path(path).parent_path();
  try {
    prepareOutputDir(parent.empty() ? "." : parent.string());
  } catch (const Error& e) {
    throw ioError(fmt::format("{} (folder '{}')", e.message(), parent.string()), ErrorLocation(path));
  }
}

}  // namespace lidar2d::cli
