#include "lidar2d/io/localization_db.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <type_traits>

#include "lidar2d/core/error.hpp"
#include "lidar2d/io/atomic_file.hpp"
#include "src/io/internal/read_file.hpp"

namespace lidar2d::io {

static_assert(std::endian::native == std::endian::little, "the database format is little-endian");

namespace {

constexpr char kMagic[8] = {'L', '2', 'D', 'L', 'O', 'C', 'D', 'B'};

std::uint64_t fnv1a(const char* data, std::size_t n) {
  std::uint64_t h = 1469598103934665603ULL;
  for (std::size_t i = 0; i < n; ++i) {
    h ^= static_cast<unsigned char>(data[i]);
    h *= 1099511628211ULL;
  }
  return h;
}

class Writer {
 public:
  template <class T>
  void put(const T& v) {
    static_assert(std::is_trivially_copyable_v<T>);
    const auto* p = reinterpret_cast<const char*>(&v);
    buf.append(p, sizeof(T));
  }
  std::string buf;
};

class Reader {
 public:
  Reader(const std::string& data, const std::string& path) : data_(data), path_(path) {}
  template <class T>
  T get(const char* field) {
    T v;
    if (pos_ + sizeof(T) > data_.size())
      throw badInput(fmt::format("truncated localization database (ends inside '{}')", field),
                     ErrorLocation(path_, 0, field));
    std::memcpy(&v, data_.data() + pos_, sizeof(T));
    pos_ += sizeof(T);
    return v;
  }
  std::size_t pos() const { return pos_; }

 private:
  const std::string& data_;
  const std::string& path_;
  std::size_t pos_ = 0;
};

void putLineOptions(Writer& w, const localization::LineExtractionOptions& l) {
  w.put(l.split_threshold_m);
  w.put(l.max_gap_m);
  w.put(static_cast<std::uint64_t>(l.min_points));
  w.put(l.min_length_m);
  w.put(l.max_rms_m);
  w.put(l.min_distance_m);
  w.put(l.merge_angle_rad);
  w.put(l.merge_distance_m);
}

localization::LineExtractionOptions getLineOptions(Reader& r) {
  localization::LineExtractionOptions l;
  l.split_threshold_m = r.get<double>("lines.split_threshold_m");
  l.max_gap_m = r.get<double>("lines.max_gap_m");
  l.min_points = static_cast<std::size_t>(r.get<std::uint64_t>("lines.min_points"));
  l.min_length_m = r.get<double>("lines.min_length_m");
  l.max_rms_m = r.get<double>("lines.max_rms_m");
  l.min_distance_m = r.get<double>("lines.min_distance_m");
  l.merge_angle_rad = r.get<double>("lines.merge_angle_rad");
  l.merge_distance_m = r.get<double>("lines.merge_distance_m");
  return l;
}

std::string readAll(const std::string& path) {
  return internal::readWholeFile(path, std::uint64_t{16} << 30, "localization database file");
}

// Checks magic and version; returns a reader positioned after them.
void checkHeader(Reader& r, const std::string& data, const std::string& path) {
  if (data.size() < sizeof(kMagic) || std::memcmp(data.data(), kMagic, sizeof(kMagic)) != 0)
    throw badInput("not a lidar2d localization database (bad magic)", ErrorLocation(path, 0, "magic"));
  for (std::size_t i = 0; i < sizeof(kMagic); ++i) r.get<char>("magic");
  const auto version = r.get<std::uint32_t>("version");
  if (version != kLocalizationDbVersion)
    throw Error(ErrorKind::kUnsupported,
                fmt::format("localization database format version {} is not supported (this lidar2d reads version "
                            "{}); rebuild it with 'lidar2d localize-index'",
                            version, kLocalizationDbVersion),
                ErrorLocation(path, 0, "version"));
}

}  // namespace

void writeLocalizationDatabase(const std::string& path, const localization::Database& db) {
  Writer w;
  // The whole file is assembled in memory: reserved once (a file of a large map is tens of MB).
  w.buf.reserve(1024 + db.positions().size() * 16 + db.lines().size() * 12 + db.profiles().size() * 2 + 8);
  w.buf.append(kMagic, sizeof(kMagic));
  w.put(kLocalizationDbVersion);
  w.put(db.mapChecksum());
  const auto& o = db.options();
  w.put(o.step_m);
  w.put(static_cast<std::int32_t>(o.beams));
  w.put(o.fov_rad);
  w.put(o.max_range_m);
  w.put(o.clearance_m);
  w.put(static_cast<std::int32_t>(o.occupied_min));
  w.put(static_cast<std::int32_t>(o.free_max));
  w.put(static_cast<std::uint64_t>(o.max_lines));
  w.put(o.min_pair_angle_rad);
  w.put(o.key_angle_scale_m_per_rad);
  w.put(static_cast<std::int32_t>(o.profile_bins));
  putLineOptions(w, o.lines);
  w.put(static_cast<std::uint64_t>(db.positions().size()));
  w.put(static_cast<std::uint64_t>(db.lines().size()));
  w.put(static_cast<std::uint64_t>(db.profiles().size()));
  for (const auto& p : db.positions()) {
    w.put(p.x);
    w.put(p.y);
    w.put(p.first_line);
    w.put(p.num_lines);
  }
  for (const auto& l : db.lines()) {
    w.put(l.normal_angle);
    w.put(l.distance);
    w.put(l.length);
  }
  // Profile ranges in centimetres (u16: up to 655 m; the virtual scans reach max_range_m).
  for (const float v : db.profiles())
    w.put(static_cast<std::uint16_t>(std::lround(std::clamp(static_cast<double>(v) * 100.0, 0.0, 65535.0))));
  w.put(fnv1a(w.buf.data(), w.buf.size()));
  writeFileAtomically(path, w.buf);
}

std::uint64_t readLocalizationDatabaseMapChecksum(const std::string& path) {
  const std::string data = readAll(path);
  Reader r(data, path);
  checkHeader(r, data, path);
  return r.get<std::uint64_t>("map checksum");
}

localization::Database readLocalizationDatabase(const std::string& path) {
  const std::string data = readAll(path);
  Reader r(data, path);
  checkHeader(r, data, path);
  if (data.size() < r.pos() + 8) throw badInput("truncated localization database", ErrorLocation(path, 0, "header"));
  std::uint64_t stored = 0;
  std::memcpy(&stored, data.data() + data.size() - 8, 8);
  const std::uint64_t map_checksum = r.get<std::uint64_t>("map checksum");
  localization::DatabaseOptions o;
  o.step_m = r.get<double>("step_m");
  o.beams = r.get<std::int32_t>("beams");
  o.fov_rad = r.get<double>("fov_rad");
  o.max_range_m = r.get<double>("max_range_m");
  o.clearance_m = r.get<double>("clearance_m");
  o.occupied_min = r.get<std::int32_t>("occupied_min");
  o.free_max = r.get<std::int32_t>("free_max");
  o.max_lines = static_cast<std::size_t>(r.get<std::uint64_t>("max_lines"));
  o.min_pair_angle_rad = r.get<double>("min_pair_angle_rad");
  o.key_angle_scale_m_per_rad = r.get<double>("key_angle_scale_m_per_rad");
  o.profile_bins = r.get<std::int32_t>("profile_bins");
  o.lines = getLineOptions(r);
  const auto n_pos = r.get<std::uint64_t>("positions");
  const auto n_lines = r.get<std::uint64_t>("lines");
  const auto n_profile = r.get<std::uint64_t>("profile values");
  if (n_pos > data.size() || n_lines > data.size() || n_profile > data.size() ||
      r.pos() + n_pos * 16 + n_lines * 12 + n_profile * 2 + 8 != data.size())
    throw badInput(fmt::format("localization database size does not match its counts ({} positions, {} lines, {} "
                               "profile values): truncated or corrupt",
                               n_pos, n_lines, n_profile),
                   ErrorLocation(path, 0, "positions"));
  if (fnv1a(data.data(), data.size() - 8) != stored)
    throw badInput("localization database checksum mismatch (corrupt file)", ErrorLocation(path, 0, "checksum"));
  std::vector<localization::Database::Position> positions(n_pos);
  for (auto& p : positions) {
    p.x = r.get<float>("position.x");
    p.y = r.get<float>("position.y");
    p.first_line = r.get<std::uint32_t>("position.first_line");
    p.num_lines = r.get<std::uint32_t>("position.num_lines");
  }
  std::vector<localization::Database::LineFeature> lines(n_lines);
  for (auto& l : lines) {
    l.normal_angle = r.get<float>("line.normal_angle");
    l.distance = r.get<float>("line.distance");
    l.length = r.get<float>("line.length");
  }
  std::vector<float> profiles(n_profile);
  for (auto& v : profiles) v = static_cast<float>(r.get<std::uint16_t>("profile") / 100.0);
  try {
    return localization::Database::fromParts(o, map_checksum, std::move(positions), std::move(lines),
                                             std::move(profiles));
  } catch (const Error& e) {
    throw badInput(e.message(), ErrorLocation(path, 0, e.where().field));
  }
}

}  // namespace lidar2d::io
