#include "lidar2d/io/map_file.hpp"

#include <fmt/format.h>
#include <yaml-cpp/yaml.h>

#include <cassert>
#include <cctype>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <sstream>

#include "lidar2d/core/error.hpp"
#include "lidar2d/io/atomic_file.hpp"

namespace lidar2d::io {
namespace fs = std::filesystem;

// ---- OccupancyImage ----

OccupancyImage OccupancyImage::create(int width, int height, double resolution_m, const SE2& origin,
                                      std::vector<std::int8_t> cells) {
  const ErrorLocation where({}, 0, "occupancy image");
  if (width < 1 || height < 1) throw invalidArgument(fmt::format("width and height must be >= 1, got {} x {}", width, height), where);
  if (static_cast<std::uint64_t>(width) * static_cast<std::uint64_t>(height) > kMaxCells)
    throw invalidArgument(fmt::format("{} x {} cells exceed the limit of 10^9", width, height), where);
  if (!std::isfinite(resolution_m) || resolution_m <= 0)
    throw invalidArgument(fmt::format("resolution must be finite and > 0, got {}", resolution_m), where);
  if (!origin.isFinite()) throw invalidArgument("origin must be finite", where);
  if (cells.size() != static_cast<std::size_t>(width) * static_cast<std::size_t>(height))
    throw invalidArgument(fmt::format("{} cells given for {} x {}", cells.size(), width, height), where);
  for (std::size_t i = 0; i < cells.size(); ++i)
    if (cells[i] < -1 || cells[i] > 100)
      throw invalidArgument(fmt::format("cell {} has value {}, expected -1 or 0..100", i, static_cast<int>(cells[i])), where);
  OccupancyImage m;
  m.width_ = width;
  m.height_ = height;
  m.resolution_ = resolution_m;
  m.origin_ = origin;
  m.cells_ = std::move(cells);
  return m;
}

OccupancyImage OccupancyImage::filled(int width, int height, double resolution_m, const SE2& origin,
                                      std::int8_t value) {
  if (width < 1 || height < 1 || static_cast<std::uint64_t>(width) * static_cast<std::uint64_t>(height) > kMaxCells)
    return create(width, height, resolution_m, origin, {});  // throws with the right message
  return create(width, height, resolution_m, origin,
                std::vector<std::int8_t>(static_cast<std::size_t>(width) * static_cast<std::size_t>(height), value));
}

std::int8_t OccupancyImage::at(int col, int row) const {
  assert(contains(col, row));
  return cells_[static_cast<std::size_t>(row) * static_cast<std::size_t>(width_) + static_cast<std::size_t>(col)];
}

void OccupancyImage::set(int col, int row, std::int8_t value) {
  assert(contains(col, row) && value >= -1 && value <= 100);
  cells_[static_cast<std::size_t>(row) * static_cast<std::size_t>(width_) + static_cast<std::size_t>(col)] = value;
}

Eigen::Vector2d OccupancyImage::cellCenter(int col, int row) const {
  return origin_ * Eigen::Vector2d((col + 0.5) * resolution_, (row + 0.5) * resolution_);
}

std::optional<Eigen::Vector2i> OccupancyImage::worldToCell(const Eigen::Vector2d& p_world) const {
  const Eigen::Vector2d p = origin_.inverse() * p_world;
  const double cx = std::floor(p.x() / resolution_), cy = std::floor(p.y() / resolution_);
  if (!(cx >= 0 && cy >= 0 && cx < width_ && cy < height_)) return std::nullopt;
  return Eigen::Vector2i(static_cast<int>(cx), static_cast<int>(cy));
}

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

MapYaml parseYaml(const std::string& file) {
  YAML::Node root;
  try {
    root = YAML::LoadFile(file);
  } catch (const YAML::BadFile&) {
    throw ioError(fs::exists(file) ? "cannot read map YAML" : "map YAML does not exist", {file});
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
  if (!std::isfinite(y.resolution) || y.resolution <= 0)
    throw badInput(fmt::format("must be finite and > 0, got {}", y.resolution), {file, 0, "resolution"});
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

// ---- images ----

/// A decoded image: grey value (mean of the colour channels) and alpha per pixel, top row first.
struct Grey {
  int width = 0, height = 0;
  std::vector<std::uint8_t> value;
  std::vector<std::uint8_t> alpha;  // empty: opaque
};

std::string readAll(const std::string& path, const std::string& yaml_file) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw ioError(fs::exists(path) ? "cannot read map image" : "map image does not exist", {path, 0, "image"});
  std::stringstream ss;
  ss << in.rdbuf();
  (void)yaml_file;
  return ss.str();
}

Grey parsePgm(const std::string& data, const std::string& path) {
  const bool binary = data[1] == '5';
  std::size_t pos = 2;
  auto skipSpaceAndComments = [&] {
    while (pos < data.size()) {
      if (std::isspace(static_cast<unsigned char>(data[pos]))) {
        ++pos;
      } else if (data[pos] == '#') {
        while (pos < data.size() && data[pos] != '\n') ++pos;
      } else {
        break;
      }
    }
  };
  auto number = [&](const char* field) -> std::uint64_t {
    skipSpaceAndComments();
    if (pos >= data.size() || !std::isdigit(static_cast<unsigned char>(data[pos])))
      throw badInput("truncated or malformed PGM header", {path, 0, field});
    std::uint64_t v = 0;
    while (pos < data.size() && std::isdigit(static_cast<unsigned char>(data[pos]))) {
      v = v * 10 + static_cast<std::uint64_t>(data[pos] - '0');
      if (v > 100000000000ULL) throw badInput("value too large", {path, 0, field});
      ++pos;
    }
    return v;
  };
  const std::uint64_t w = number("width"), h = number("height");
  const std::uint64_t maxval = number("maxval");
  if (w == 0 || h == 0) throw badInput(fmt::format("image is {} x {} pixels", w, h), {path, 0, "width"});
  if (w * h > OccupancyImage::kMaxCells)
    throw badInput(fmt::format("{} x {} pixels exceed the limit of 10^9", w, h), {path, 0, "width"});
  if (maxval == 0 || maxval > 255)
    throw badInput(fmt::format("maxval {} not supported (8-bit images only)", maxval), {path, 0, "maxval"});
  Grey g;
  g.width = static_cast<int>(w);
  g.height = static_cast<int>(h);
  const std::size_t n = static_cast<std::size_t>(w * h);
  g.value.resize(n);
  if (binary) {
    // Exactly one whitespace byte separates maxval from the pixels (Netpbm spec).
    if (pos >= data.size() || !std::isspace(static_cast<unsigned char>(data[pos])))
      throw badInput("truncated PGM header", {path, 0, "maxval"});
    ++pos;
    if (data.size() - pos < n)
      throw badInput(fmt::format("truncated PGM: {} pixel bytes expected, {} present", n, data.size() - pos),
                     {path, 0, "pixels"});
    for (std::size_t i = 0; i < n; ++i) g.value[i] = static_cast<std::uint8_t>(data[pos + i]);
  } else {
    for (std::size_t i = 0; i < n; ++i) {
      skipSpaceAndComments();
      if (pos >= data.size())
        throw badInput(fmt::format("truncated PGM: {} pixels expected, {} present", n, i), {path, 0, "pixels"});
      const std::uint64_t v = number("pixels");
      if (v > maxval) throw badInput(fmt::format("pixel {} value {} exceeds maxval {}", i, v, maxval), {path, 0, "pixels"});
      g.value[i] = static_cast<std::uint8_t>(v);
    }
  }
  if (maxval != 255)
    for (auto& v : g.value) v = static_cast<std::uint8_t>((v * 255u + static_cast<unsigned>(maxval) / 2) / maxval);
  return g;
}

Grey decodeOther(const std::string& data, const std::string& path) {
  cv::Mat img;
  try {
    const cv::Mat buf(1, static_cast<int>(data.size()), CV_8UC1, const_cast<char*>(data.data()));
    img = cv::imdecode(buf, cv::IMREAD_UNCHANGED);
  } catch (const cv::Exception&) {
    img.release();
  }
  if (img.empty()) throw badInput("unrecognised image format (expected PGM P5/P2 or PNG)", {path, 0, "magic"});
  if (img.depth() != CV_8U) throw badInput("only 8-bit images are supported", {path, 0, "depth"});
  const int ch = img.channels();
  const bool has_alpha = ch == 2 || ch == 4;
  const int colour = has_alpha ? ch - 1 : ch;
  Grey g;
  g.width = img.cols;
  g.height = img.rows;
  if (static_cast<std::uint64_t>(g.width) * static_cast<std::uint64_t>(g.height) > OccupancyImage::kMaxCells)
    throw badInput("image exceeds the limit of 10^9 pixels", {path, 0, "width"});
  g.value.resize(static_cast<std::size_t>(g.width) * static_cast<std::size_t>(g.height));
  if (has_alpha) g.alpha.resize(g.value.size());
  for (int r = 0; r < img.rows; ++r) {
    const std::uint8_t* p = img.ptr<std::uint8_t>(r);
    for (int c = 0; c < img.cols; ++c, p += ch) {
      int sum = 0;
      for (int k = 0; k < colour; ++k) sum += p[k];
      const std::size_t i = static_cast<std::size_t>(r) * static_cast<std::size_t>(g.width) + static_cast<std::size_t>(c);
      g.value[i] = static_cast<std::uint8_t>(sum / colour);  // integer mean, as map_server
      if (has_alpha) g.alpha[i] = p[ch - 1];
    }
  }
  return g;
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

}  // namespace

MapFile readMap(const std::string& yaml_path) {
  MapFile out;
  out.yaml = parseYaml(yaml_path);
  const fs::path img(out.yaml.image);
  out.image_path = img.is_absolute() ? img.string() : (fs::path(yaml_path).parent_path() / img).string();
  const std::string data = readAll(out.image_path, yaml_path);
  if (data.empty()) throw badInput("map image is empty", {out.image_path, 0, "magic"});
  Grey g;
  if (data.size() >= 2 && data[0] == 'P' && (data[1] == '5' || data[1] == '2'))
    g = parsePgm(data, out.image_path);
  else if (data.size() >= 2 && data[0] == 'P' && data[1] >= '1' && data[1] <= '7')
    throw badInput(fmt::format("PGM magic P5 or P2 expected, found P{}", data[1]), {out.image_path, 0, "magic"});
  else
    g = decodeOther(data, out.image_path);
  std::vector<std::int8_t> cells(g.value.size());
  for (int r = 0; r < g.height; ++r) {
    const int row = g.height - 1 - r;  // image top row = map's top (largest y)
    for (int c = 0; c < g.width; ++c) {
      const std::size_t i = static_cast<std::size_t>(r) * static_cast<std::size_t>(g.width) + static_cast<std::size_t>(c);
      cells[static_cast<std::size_t>(row) * static_cast<std::size_t>(g.width) + static_cast<std::size_t>(c)] =
          classify(g.value[i], g.alpha.empty() ? 255 : g.alpha[i], out.yaml);
    }
  }
  out.map = OccupancyImage::create(g.width, g.height, out.yaml.resolution, out.yaml.origin, std::move(cells));
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
