#include <fmt/format.h>

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <fstream>

#include "lidar2d/core/error.hpp"
#include "lidar2d/io/frame_source.hpp"
#include "src/io/internal/readers.hpp"

namespace lidar2d::io {

const char* toString(LogFormat f) {
  switch (f) {
    case LogFormat::kCarmen:
      return "carmen";
    case LogFormat::kRosbag1:
      return "rosbag1";
    case LogFormat::kRosbag2:
      return "rosbag2";
    case LogFormat::kRangeTable:
      return "range-table";
  }
  return "unknown";
}

LogFormat detectFormat(const std::string& path) {
  namespace fs = std::filesystem;
  std::error_code ec;
  if (!fs::exists(path, ec)) throw ioError("no such file", {path});
  if (fs::is_directory(path, ec)) {
    if (fs::exists(fs::path(path) / "metadata.yaml", ec)) return LogFormat::kRosbag2;
    const RangeTableFiles t = internal::rangeTableFolder(path);
    const bool has[3] = {fs::exists(t.poses, ec), fs::exists(t.angles, ec), fs::exists(t.ranges, ec)};
    if (has[0] && has[1] && has[2]) return LogFormat::kRangeTable;
    if (has[0] || has[1] || has[2])
      throw badInput(fmt::format("a range table folder needs poses.txt, angles.txt and ranges.txt; {} is missing",
                                 !has[0] ? "poses.txt" : (!has[1] ? "angles.txt" : "ranges.txt")),
                     {path});
    throw badInput(
        "is a directory, not a log file (a ROS2 bag folder would hold metadata.yaml, a range table folder "
        "poses.txt, angles.txt and ranges.txt)",
        {path});
  }
  std::ifstream in(path, std::ios::binary);
  if (!in) throw ioError(std::string("cannot open: ") + std::strerror(errno), {path});
  char head[16] = {};
  in.read(head, sizeof head);
  const auto n = static_cast<std::size_t>(in.gcount());
  if (n == 0) throw badInput("file is empty", {path});
  const std::string h(head, n);
  if (n >= 2 && static_cast<unsigned char>(head[0]) == 0x1f && static_cast<unsigned char>(head[1]) == 0x8b)
    return LogFormat::kCarmen;  // gzip: only CARMEN text logs are read compressed
  if (h.rfind("#ROSBAG V", 0) == 0 || h.rfind("#ROSRECORD V", 0) == 0) return LogFormat::kRosbag1;  // 2.0 | 1.2
  if (h.rfind("SQLite format 3", 0) == 0) return LogFormat::kRosbag2;
  if (n >= 2 && head[0] == 'B' && head[1] == 'Z')
    throw badInput("bzip2-compressed file: decompress it first (only gzip is read directly)", {path});
  return LogFormat::kCarmen;  // text; the CARMEN reader reports content it cannot parse
}

namespace {

// ReaderOptions::laser_mount: the same mounting pose on every frame.
class MountOverride final : public FrameSource {
 public:
  MountOverride(std::unique_ptr<FrameSource> inner, const SE2& mount) : inner_(std::move(inner)), mount_(mount) {}
  std::optional<Frame> next() override {
    std::optional<Frame> f = inner_->next();
    if (f) f->T_robot_laser = mount_;
    return f;
  }
  LogFormat format() const override { return inner_->format(); }
  const std::string& path() const override { return inner_->path(); }
  SourceNotes notes() const override {
    SourceNotes n = inner_->notes();
    n.scan_source += " (laser mounting given by the options, not the log)";
    return n;
  }
  std::optional<std::size_t> sizeHint() const override { return inner_->sizeHint(); }

 private:
  std::unique_ptr<FrameSource> inner_;
  SE2 mount_;
};

std::unique_ptr<FrameSource> openFormat(const std::string& path, const ReaderOptions& options) {
  switch (detectFormat(path)) {
    case LogFormat::kCarmen:
      return internal::openCarmen(path, options);
    case LogFormat::kRosbag1:
      return internal::openRosbag1(path, options);
    case LogFormat::kRosbag2:
      return internal::openRosbag2(path, options);
    case LogFormat::kRangeTable:
      return internal::openRangeTable(internal::rangeTableFolder(path));
  }
  throw badInput("unknown log format", {path});
}

}  // namespace

std::unique_ptr<FrameSource> openLog(const std::string& path, const ReaderOptions& options) {
  if (options.laser_mount && (!options.laser_mount->isFinite() ||
                              !laserMountOffsetOk(options.laser_mount->x(), options.laser_mount->y())))
    throw invalidArgument(fmt::format("laser mounting pose must be finite, within +-{:g} m of the robot's centre",
                                      kMaxLaserMountOffset),
                          {"ReaderOptions", 0, "laser_mount"});
  std::unique_ptr<FrameSource> source =
      options.range_table ? internal::openRangeTable(*options.range_table) : openFormat(path, options);
  if (options.laser_mount) return std::make_unique<MountOverride>(std::move(source), *options.laser_mount);
  return source;
}

}  // namespace lidar2d::io
