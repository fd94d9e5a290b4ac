#include "lidar2d/io/atomic_file.hpp"

#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>

#include "lidar2d/core/error.hpp"

namespace lidar2d::io {

AtomicFile::AtomicFile(std::string path) : path_(std::move(path)) {
  namespace fs = std::filesystem;
  std::error_code ec;
  if (path_.empty()) throw ioError("output path is empty");
  if (fs::is_directory(path_, ec)) throw ioError("is a directory, expected a file path", {path_});
  const fs::path parent = fs::path(path_).parent_path();
  if (!parent.empty() && !fs::is_directory(parent, ec))
    throw ioError("folder '" + parent.string() + "' does not exist", {path_});
  // The temporary name is unique per process so that two writers never share it.
  tmp_path_ = path_ + ".tmp." + std::to_string(::getpid());
  out_.open(tmp_path_, std::ios::out | std::ios::binary | std::ios::trunc);
  if (!out_) throw ioError(std::string("cannot write: ") + std::strerror(errno), {path_});
}

AtomicFile::~AtomicFile() {
  if (!committed_) {
    out_.close();
    std::remove(tmp_path_.c_str());
  }
}

void AtomicFile::commit() {
  out_.flush();
  const bool ok = static_cast<bool>(out_);
  out_.close();
  if (!ok || out_.fail()) {
    std::remove(tmp_path_.c_str());
    committed_ = true;
    throw ioError("write failed (disk full?)", {path_});
  }
  if (std::rename(tmp_path_.c_str(), path_.c_str()) != 0) {
    const std::string why = std::strerror(errno);
    std::remove(tmp_path_.c_str());
    committed_ = true;
    throw ioError("cannot rename temporary file into place: " + why, {path_});
  }
  committed_ = true;
}

void writeFileAtomically(const std::string& path, const std::string& content) {
  AtomicFile f(path);
  f.stream() << content;
  f.commit();
}

OutputSet::OutputSet(std::string dir) : dir_(std::move(dir)) {
  namespace fs = std::filesystem;
  std::error_code ec;
  const fs::path folder = dir_.empty() ? fs::path(".") : fs::path(dir_);
  if (!fs::is_directory(folder, ec)) throw ioError("folder does not exist", {dir_});
  staging_ = (folder / (".lidar2d-staging." + std::to_string(::getpid()))).string();
  fs::remove_all(staging_, ec);  // a crashed earlier process of the same id
  if (!fs::create_directory(staging_, ec) || ec)
    throw ioError("cannot create a staging folder: " + (ec ? ec.message() : std::string("it exists")), {staging_});
}

OutputSet::~OutputSet() {
  std::error_code ec;
  std::filesystem::remove_all(staging_, ec);
}

std::string OutputSet::stage(const std::string& name) {
  namespace fs = std::filesystem;
  std::error_code ec;
  const fs::path target = fs::path(dir_) / name;  // a bare name when dir_ is empty
  if (fs::is_directory(target, ec)) throw ioError("is a directory, expected a file path", {target.string()});
  names_.push_back(name);
  return (fs::path(staging_) / name).string();
}

std::vector<std::string> OutputSet::commit() {
  namespace fs = std::filesystem;
  std::error_code ec;
  for (const auto& name : names_)
    if (!fs::is_regular_file(fs::path(staging_) / name, ec))
      throw ioError("was staged but not written", {(fs::path(dir_) / name).string()});
  std::vector<std::string> paths;
  for (const auto& name : names_) {
    const std::string target = (fs::path(dir_) / name).string();
    if (std::rename((fs::path(staging_) / name).c_str(), target.c_str()) != 0)
      throw ioError(std::string("cannot move the output into place: ") + std::strerror(errno), {target});
    paths.push_back(target);
  }
  return paths;
}

}  // namespace lidar2d::io
