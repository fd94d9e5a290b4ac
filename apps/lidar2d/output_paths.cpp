// Output paths checked (and their folders created) before a command starts its work, so that a
// typo in -o fails at once rather than after minutes of mapping.

#include <fmt/format.h>
#include <unistd.h>

#include <exception>
#include <filesystem>
#include <string>
#include <system_error>

#include "commands.hpp"
#include "lidar2d/core/error.hpp"

namespace lidar2d::cli {

CreatedFolders::~CreatedFolders() {
  if (std::uncaught_exceptions() <= exceptions_) return;
  // The command failed: the folders it created go again, deepest first (remove() leaves a folder
  // that is not empty, which then holds something that was there before).
  std::error_code ec;
  for (auto it = created_.rbegin(); it != created_.rend(); ++it) std::filesystem::remove(*it, ec);
}

CreatedFolders prepareOutputDir(const std::string& path) {
  namespace fs = std::filesystem;
  if (path.empty()) throw ioError("output path is empty");
  CreatedFolders created;
  std::error_code ec;
  // The missing folders, outermost first, so that a failure can remove exactly those.
  std::vector<fs::path> missing;
  for (fs::path p = fs::path(path).lexically_normal(); !p.empty() && !fs::exists(p, ec); p = p.parent_path()) {
    missing.insert(missing.begin(), p);
    if (p == p.parent_path()) break;
  }
  for (const fs::path& p : missing) {
    if (!fs::create_directory(p, ec) && !fs::is_directory(p))
      throw ioError(fmt::format("cannot create the output folder: {}", ec ? ec.message() : "not a folder"),
                    ErrorLocation(p.string()));
    created.created_.push_back(p);
  }
  if (!fs::is_directory(path, ec)) throw ioError("exists and is not a folder", ErrorLocation(path));
  if (::access(path.c_str(), W_OK | X_OK) != 0) throw ioError("the output folder is not writable", ErrorLocation(path));
  return created;
}

CreatedFolders prepareOutputFile(const std::string& path) {
  namespace fs = std::filesystem;
  if (path.empty()) throw ioError("output path is empty");
  std::error_code ec;
  if (fs::is_directory(path, ec)) throw ioError("is a folder, expected a file path", ErrorLocation(path));
  const fs::path parent = fs::path(path).parent_path();
  try {
    return prepareOutputDir(parent.empty() ? "." : parent.string());
  } catch (const Error& e) {
    throw ioError(fmt::format("{} (folder '{}')", e.message(), e.where().file), ErrorLocation(path));
  }
}

}  // namespace lidar2d::cli
