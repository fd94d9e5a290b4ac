#pragma once
/// @file
/// Atomic output files: content goes to a temporary file next to the target, which is renamed over
/// the target only by `commit()`. A writer destroyed without `commit()` (an exception, a crash)
/// removes its temporary file, so a reader never sees a half-written output.

#include <fstream>
#include <string>

namespace lidar2d::io {

class AtomicFile {
 public:
  /// Opens a temporary file beside `path`. Throws `lidar2d::Error` (kIo) when it cannot be created
  /// (missing folder, no permission, `path` is a directory).
  explicit AtomicFile(std::string path);
  ~AtomicFile();
  AtomicFile(const AtomicFile&) = delete;
  AtomicFile& operator=(const AtomicFile&) = delete;

  std::ostream& stream() { return out_; }
  const std::string& path() const { return path_; }
  /// Flushes, checks for write errors, and renames the temporary file onto `path`. Throws
  /// `lidar2d::Error` (kIo) on failure, leaving the target untouched.
  void commit();

 private:
  std::string path_;
  std::string tmp_path_;
  std::ofstream out_;
  bool committed_ = false;
};

/// Writes `content` to `path` atomically.
void writeFileAtomically(const std::string& path, const std::string& content);

}  // namespace lidar2d::io
