#include "lidar2d/io/map_file.hpp"

#include <fmt/format.h>
#include <yaml-cpp/yaml.h>

#include <cassert>
#include <cctype>
#include <cmath>
#include <algorithm>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "lidar2d/core/error.hpp"
#include "lidar2d/io/atomic_file.hpp"
#include "lidar2d/io/image.hpp"
#include "src/io/internal/read_file.hpp"

namespace lidar2d::io {
namespace fs = std::filesystem;

namespace {

// ---- YAML ----

template <typename T>
T scalar(const YAML::Node& root, const char* key, const std::string& file) {
  const YAML::Node n = root[key];
  try {
    return n.as<T>();
  } catch (const YAML::Exception&) {
    throw badInput(fmt::format("expected a {} value", std::is_same_v<T, std::string> ? "text" : "numeric"),
                   {file, n.Mark().line >= 0 ? static_cast<std::size_t>(n.Mark().line) + 1 : 0, key});
  }
}

// A map YAML holds a few short keys; anything near this size is not one.
constexpr std::uint64_t kMaxYamlBytes = std::uint64_t{1} << 20;

MapYaml parseYaml(const std::string& file) {
  YAML::Node root;
  try {
    // (Read by lidar2d rather than YAML::LoadFile, which would read a device such as /dev/zero
    // without end and reports an unreadable path without the file's name.)
    root = YAML::Load(internal::readWholeFile(file, kMaxYamlBytes, "map YAML file"));
  } catch (const YAML::ParserException& e) {
    throw badInput(fmt::format("malformed YAML: {}", e.msg), {file, static_cast<std::size_t>(e.mark.line) + 1});
  }
  if (!root.IsMap()) throw badInput("expected a YAML mapping with image, resolution and origin", {file});
  MapYaml y;
  for (const char* key : {"image", "resolution", "origin"})
    if (!root[key]) throw badInput("missing required key", {file, 0, key});
  y.image = scalar<std::string>(root, "image", file);
  if (y.image.empty()) throw badInput("image path is empty", {file, 0, "image"});
  y.resolution = scalar<double>(root, "resolution", file);
  if (!(y.resolution >= OccupancyImage::kMinResolution && y.resolution <= OccupancyImage::kMaxResolution))
    throw badInput(fmt::format("must be between {} and {} m, got {}", OccupancyImage::kMinResolution,
                               OccupancyImage::kMaxResolution, y.resolution),
                   {file, 0, "resolution"});
  const YAML::Node o = root["origin"];
  if (!o.IsSequence() || o.size() != 3) throw badInput("expected [x, y, yaw]", {file, 0, "origin"});
  double v[3];
  for (std::size_t i = 0; i < 3; ++i) {
    try {
      v[i] = o[i].as<double>();
    } catch (const YAML::Exception&) {
      throw badInput("expected three numbers [x, y, yaw]", {file, 0, "origin"});
    }
    if (!std::isfinite(v[i])) throw badInput("values must be finite", {file, 0, "origin"});
    if (i < 2 && std::abs(v[i]) > OccupancyImage::kMaxOriginAbs)
      throw badInput(fmt::format("x and y must be within +-{:g} m, got {}", OccupancyImage::kMaxOriginAbs, v[i]),
                     {file, 0, "origin"});
  }
  y.origin = SE2(v[0], v[1], v[2]);
  if (root["negate"]) {
    try {
      y.negate = root["negate"].as<int>() != 0;
    } catch (const YAML::Exception&) {
      y.negate = scalar<bool>(root, "negate", file);
    }
  }
  if (root["occupied_thresh"]) y.occupied_thresh = scalar<double>(root, "occupied_thresh", file);
  if (root["free_thresh"]) y.free_thresh = scalar<double>(root, "free_thresh", file);
  if (!(y.free_thresh >= 0 && y.free_thresh < y.occupied_thresh && y.occupied_thresh <= 1))
    throw badInput(fmt::format("thresholds must satisfy 0 <= free_thresh < occupied_thresh <= 1, got {} and {}",
                               y.free_thresh, y.occupied_thresh),
                   {file, 0, "free_thresh"});
  if (root["mode"]) {
    const std::string m = scalar<std::string>(root, "mode", file);
    if (m == "trinary")
      y.mode = MapMode::kTrinary;
    else if (m == "scale")
      y.mode = MapMode::kScale;
    else if (m == "raw")
      y.mode = MapMode::kRaw;
    else
      throw badInput(fmt::format("unknown mode '{}', expected trinary, scale or raw", m), {file, 0, "mode"});
  }
  return y;
}

std::int8_t classify(int grey, int alpha, const MapYaml& y) {
  // ROS1 map_server image_loader.cpp (loadMapFromFile), pixel by pixel.
  if (y.negate) grey = 255 - grey;
  if (y.mode == MapMode::kRaw) return grey <= 100 ? static_cast<std::int8_t>(grey) : OccupancyImage::kUnknown;
  const double occ = (255 - grey) / 255.0;
  if (occ > y.occupied_thresh) return OccupancyImage::kOccupied;
  if (occ < y.free_thresh) return OccupancyImage::kFree;
  if (y.mode == MapMode::kTrinary || alpha < 1) return OccupancyImage::kUnknown;
  const double ratio = (occ - y.free_thresh) / (y.occupied_thresh - y.free_thresh);
  return static_cast<std::int8_t>(1 + 98 * ratio);
}

// The map of `out.image_path` under `out.yaml`'s interpretation.
void readImageInto(MapFile& out, const std::string& field) {
  const GreyImage g = readGreyImage(out.image_path, field);
  std::vector<std::int8_t> cells(g.value.size());
  for (int r = 0; r < g.height; ++r) {
    const int row = out.yaml.rows_up ? r : g.height - 1 - r;  // map_server: image top row = map's top (largest y)
    for (int c = 0; c < g.width; ++c) {
      const std::size_t i = static_cast<std::size_t>(r) * static_cast<std::size_t>(g.width) + static_cast<std::size_t>(c);
      cells[static_cast<std::size_t>(row) * static_cast<std::size_t>(g.width) + static_cast<std::size_t>(c)] =
          classify(g.value[i], g.alpha.empty() ? 255 : g.alpha[i], out.yaml);
    }
  }
  out.map = OccupancyImage::create(g.width, g.height, out.yaml.resolution, out.yaml.origin, std::move(cells));
}

}  // namespace

MapFile readMap(const std::string& yaml_path) {
  MapFile out;
  out.yaml = parseYaml(yaml_path);
  const fs::path img(out.yaml.image);
  out.image_path = img.is_absolute() ? img.string() : (fs::path(yaml_path).parent_path() / img).string();
  readImageInto(out, "image");
  return out;
}

bool isMapImage(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  char head[8] = {};
  in.read(head, sizeof head);
  const std::size_t n = static_cast<std::size_t>(in.gcount());
  static constexpr unsigned char kPng[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
  if (n == 8 && std::equal(head, head + 8, kPng, [](char a, unsigned char b) { return static_cast<unsigned char>(a) == b; }))
    return true;
  return n >= 3 && head[0] == 'P' && (head[1] == '5' || head[1] == '2') && std::isspace(static_cast<unsigned char>(head[2]));
}

MapFile readMapImage(const std::string& image_path, const MapYaml& yaml) {
  const MapYaml& y = yaml;
  if (!(y.resolution >= OccupancyImage::kMinResolution && y.resolution <= OccupancyImage::kMaxResolution))
    throw badInput(fmt::format("must be between {} and {} m, got {}", OccupancyImage::kMinResolution,
                               OccupancyImage::kMaxResolution, y.resolution),
                   {image_path, 0, "resolution"});
  if (!y.origin.isFinite() || std::abs(y.origin.x()) > OccupancyImage::kMaxOriginAbs ||
      std::abs(y.origin.y()) > OccupancyImage::kMaxOriginAbs)
    throw badInput(fmt::format("x and y must be finite and within +-{:g} m", OccupancyImage::kMaxOriginAbs),
                   {image_path, 0, "origin"});
  if (!(y.free_thresh >= 0 && y.free_thresh < y.occupied_thresh && y.occupied_thresh <= 1))
    throw badInput("thresholds must satisfy 0 <= free_thresh < occupied_thresh <= 1", {image_path, 0, "free_thresh"});
  MapFile out;
  out.yaml = y;
  out.yaml.image = image_path;
  out.image_path = image_path;
  readImageInto(out, "map image");
  return out;
}

void writeMap(const std::string& yaml_path, const OccupancyImage& map, const std::string& image_path, int free_max,
              int occupied_min, const std::string& comment) {
  if (map.width() < 1) throw invalidArgument("cannot write an empty map", {yaml_path});
  const std::string img = image_path.empty() ? fs::path(yaml_path).replace_extension(".pgm").string() : image_path;
  {
    AtomicFile f(img);
    auto& o = f.stream();
    o << fmt::format("P5\n# CREATOR: lidar2d {:.3f} m/pix\n{} {}\n255\n", map.resolution(), map.width(), map.height());
    std::string row(static_cast<std::size_t>(map.width()), '\0');
    for (int r = map.height() - 1; r >= 0; --r) {
      for (int c = 0; c < map.width(); ++c) {
        const int v = map.at(c, r);
        row[static_cast<std::size_t>(c)] =
            static_cast<char>(v >= 0 && v <= free_max ? 254 : (v >= occupied_min ? 0 : 205));
      }
      o.write(row.data(), static_cast<std::streamsize>(row.size()));
    }
    f.commit();
  }
  // The image path in the YAML is relative to the YAML's folder (map_server resolves it so).
  const fs::path yaml_dir = fs::absolute(fs::path(yaml_path)).parent_path();
  const fs::path rel = fs::absolute(fs::path(img)).lexically_normal().lexically_relative(yaml_dir.lexically_normal());
  const SE2& o = map.origin();
  std::string header;
  if (!comment.empty()) {
    std::istringstream lines(comment);
    for (std::string line; std::getline(lines, line);) header += "# " + line + "\n";
  }
  writeFileAtomically(yaml_path, header + fmt::format("image: {}\nresolution: {}\norigin: [{}, {}, {}]\nnegate: 0\n"
                                                      "occupied_thresh: 0.65\nfree_thresh: 0.196\nmode: trinary\n",
                                                      rel.empty() ? img : rel.string(), map.resolution(), o.x(), o.y(),
                                                      o.theta()));
}

}  // namespace lidar2d::io
