// Placeholder: replaced by the real reader.
#include "lidar2d/core/error.hpp"
#include "src/io/internal/readers.hpp"

namespace lidar2d::io::internal {

std::unique_ptr<FrameSource> openCarmen(const std::string& path, const ReaderOptions&) {
  throw Error(ErrorKind::kUnsupported, "carmen logs are not supported yet", {path});
}

}  // namespace lidar2d::io::internal
