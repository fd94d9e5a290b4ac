#pragma once
/// @file
/// Typed errors of the lidar2d library. The library never prints and never aborts on bad input:
/// it throws `lidar2d::Error`, whose message names the file, line and field when they are known.
/// The CLI turns an `Error` into one line on stderr and exit code 1.

#include <cstddef>
#include <stdexcept>
#include <string>
#include <utility>

namespace lidar2d {

/// Where in the input a problem was found. Empty/zero members are unknown and are not printed.
struct ErrorLocation {
  ErrorLocation() = default;
  ErrorLocation(std::string file_, std::size_t line_ = 0, std::string field_ = {})
      : file(std::move(file_)), line(line_), field(std::move(field_)) {}

  std::string file;   ///< path of the input file, as given by the user
  std::size_t line = 0;  ///< 1-based line (text formats) or 0 when not applicable
  std::string field;  ///< name of the offending field, e.g. "FLASER range 17" or "angle_increment"
};

/// What kind of problem an `Error` reports. Bad input and I/O failures map to exit code 1.
enum class ErrorKind {
  kBadInput,      ///< malformed, truncated, or out-of-range content
  kIo,            ///< the file could not be opened, read or written
  kInvalidArgument,  ///< a parameter passed to a library function is out of its domain
  kUnsupported,   ///< a valid input that lidar2d does not handle (format version, message type)
};

/// The single exception type thrown by lidar2d for bad input. `what()` returns
/// "file:line: field: message" with the unknown parts left out.
class Error : public std::runtime_error {
 public:
  Error(ErrorKind kind, const std::string& message, ErrorLocation where = {});

  ErrorKind kind() const noexcept { return kind_; }
  const ErrorLocation& where() const noexcept { return where_; }
  /// The message without the location prefix.
  const std::string& message() const noexcept { return message_; }

 private:
  ErrorKind kind_;
  ErrorLocation where_;
  std::string message_;
};

/// Convenience constructors.
[[nodiscard]] Error badInput(const std::string& message, ErrorLocation where = {});
[[nodiscard]] Error ioError(const std::string& message, ErrorLocation where = {});
[[nodiscard]] Error invalidArgument(const std::string& message, ErrorLocation where = {});

}  // namespace lidar2d
