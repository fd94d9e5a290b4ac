#pragma once
/// @file
/// Atomic output files: content goes to a temporary file next to the target, which is renamed over
/// the target only by `commit()`. A writer destroyed without `commit()` (an exception, a crash)
/// removes its temporary file, so a reader never sees a half-written output.

#include <fstream>
#include <string>
#include <vector>

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

/// The output files of one command in one folder, which appear together or not at all: each is
/// written into a hidden staging folder inside `dir` (unique per process), and `commit()` moves
/// them all into `dir`. Destroyed without `commit()` (a later output failed), it removes the staging
/// folder and what it holds, so a failed command leaves `dir` as it found it: never a new
/// trajectory beside an old map.
class OutputSet {
 public:
  /// Creates the staging folder in `dir`, which must exist (empty: the current folder). Throws `lidar2d::Error` (kIo)
  /// when it cannot.
  explicit OutputSet(std::string dir);
  ~OutputSet();
  OutputSet(const OutputSet&) = delete;
  OutputSet& operator=(const OutputSet&) = delete;

  /// The path to write the output `name` (a file name, no folder) to, in the staging folder. Throws
  /// `lidar2d::Error` (kIo) naming `dir`/`name` when that is a folder (it could not be replaced).
  std::string stage(const std::string& name);
  /// Moves the staged files into `dir` in the order staged (a rename each, replacing any file of the
  /// same name) and returns their paths there. Throws `lidar2d::Error` (kIo) when a file that was
  /// staged was not written, or a rename fails.
  std::vector<std::string> commit();

 private:
  std::string dir_;
  std::string staging_;
  std::vector<std::string> names_;
};

}  // namespace lidar2d::io
