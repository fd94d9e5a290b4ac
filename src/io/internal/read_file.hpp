#pragma once
// Whole-file reads for the readers that parse from memory (images, map YAML, localization
// databases), with one clear error for what is not a readable file of a sane size.

#include <cstdint>
#include <string>

namespace lidar2d::io::internal {

// Checks that `path` can be read as an input file: throws (as readWholeFile) for a missing path, a
// directory, a device or a socket. Returns true for a regular file, false for a named pipe.
bool checkInputFile(const std::string& path, const std::string& what, const std::string& field = {});

// The bytes of the file at `path`, read whole. `what` names the expected content in errors ("image
// file", "localization database file"), `field` the error's field (may be empty). Refused, each
// with a one-line lidar2d::Error naming the file: a missing path, a directory, a character or block
// device or socket (/dev/zero would never end; std::ifstream opens all of these), a file larger
// than `max_bytes` (a regular file's size is checked before anything is read; a pipe, which has
// none, while it is read), and read errors. A named pipe is read to its end.
std::string readWholeFile(const std::string& path, std::uint64_t max_bytes, const std::string& what,
                          const std::string& field = {});

}  // namespace lidar2d::io::internal
