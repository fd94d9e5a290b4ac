// Placeholder: replaced by the real reader.
#include "lidar2d/core/error.hpp"
#include "src/io/internal/readers.hpp"

namespace lidar2d::io::internal {

std::unique_ptr<FrameSource> openRosbag1(const std::string& path, const ReaderOptions&) {
  throw Error(ErrorKind::kUnsupported, "rosbag1 logs are not supported yet", {path});
}

}  // namespace lidar2d::io::internal
