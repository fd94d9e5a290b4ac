#pragma once
/// @file
/// The global localizer's descriptor database file (written by `lidar2d localize-index`). Layout in
/// docs/file-formats.md: magic "L2DLOCDB", format version, the build options, the checksum of the map
/// it describes, the positions, their lines and range profiles, and a trailing FNV-1a 64 checksum
/// of everything before it. Little-endian. The k-d tree is rebuilt when the file is read (deterministic).

#include <cstdint>
#include <string>

#include "lidar2d/localization/localizer.hpp"

namespace lidar2d::io {

/// Current version of the database format; files of any other version are refused.
inline constexpr std::uint32_t kLocalizationDbVersion = 2;

/// Writes `db` to `path` atomically. Throws `lidar2d::Error` (kIo) when the file cannot be written.
void writeLocalizationDatabase(const std::string& path, const localization::Database& db);

/// Reads a database. Throws `lidar2d::Error` naming the file and field: kIo when it cannot be read;
/// kBadInput for a wrong magic ("not a lidar2d localization database"), a truncated file, a checksum
/// mismatch (corrupt) or inconsistent contents; kUnsupported for another format version.
localization::Database readLocalizationDatabase(const std::string& path);

/// Reads only the header and returns the checksum of the map the database was built from (for a
/// quick check before loading). Same errors as `readLocalizationDatabase`.
std::uint64_t readLocalizationDatabaseMapChecksum(const std::string& path);

}  // namespace lidar2d::io
