#include "lidar2d/core/error.hpp"

#include <fmt/format.h>

namespace lidar2d {
namespace {

std::string formatWhat(const std::string& message, const ErrorLocation& where) {
  // fmt instead of std::string operator+ chains: GCC 12 raises a false -Wrestrict on those.
  std::string out;
  if (!where.file.empty()) {
    out = where.line > 0 ? fmt::format("{}:{}: ", where.file, where.line) : fmt::format("{}: ", where.file);
  } else if (where.line > 0) {
    out = fmt::format("line {}: ", where.line);
  }
  if (!where.field.empty()) out += fmt::format("{}: ", where.field);
  out += message;
  return out;
}

}  // namespace

Error::Error(ErrorKind kind, const std::string& message, ErrorLocation where)
    : std::runtime_error(formatWhat(message, where)),
      kind_(kind),
      where_(std::move(where)),
      message_(message) {}

Error badInput(const std::string& message, ErrorLocation where) {
  return Error(ErrorKind::kBadInput, message, std::move(where));
}
Error ioError(const std::string& message, ErrorLocation where) {
  return Error(ErrorKind::kIo, message, std::move(where));
}
Error invalidArgument(const std::string& message, ErrorLocation where) {
  return Error(ErrorKind::kInvalidArgument, message, std::move(where));
}

}  // namespace lidar2d
