#include "map_output.hpp"

#include "lidar2d/core/error.hpp"
#include "lidar2d/io/atomic_file.hpp"
#include "lidar2d/io/image.hpp"

namespace lidar2d::cli {

std::vector<std::uint8_t> encodeMapPng(const OccupancyImage& map, const std::string& path) {
  const auto w = static_cast<std::size_t>(map.width());
  std::vector<std::uint8_t> img(w * static_cast<std::size_t>(map.height()));
  for (int row = 0; row < map.height(); ++row)
    for (int col = 0; col < map.width(); ++col) {
      const std::int8_t v = map.at(col, row);
      img[static_cast<std::size_t>(map.height() - 1 - row) * w + static_cast<std::size_t>(col)] =
          v == OccupancyImage::kOccupied ? 0 : (v == OccupancyImage::kFree ? 255 : 160);
    }
  return io::encodePng(img.data(), map.width(), map.height(), 1, w, path);
}

void writeMapFiles(io::OutputSet& outputs, const std::string& name, const OccupancyImage& map,
                   const std::string& yaml_comment) {
  const std::string pgm = outputs.stage(name + ".pgm");
  const std::string yaml = outputs.stage(name + ".yaml");
  const std::string png = outputs.stage(name + ".png");
  // Our images are already trinary (-1/0/100), so the writer's thresholds only pass them through.
  // The YAML names the image relative to itself: the staged files share a folder, as the outputs do.
  io::writeMap(yaml, map, pgm, 25, 65, yaml_comment);
  const auto bytes = encodeMapPng(map, png);
  io::writeFileAtomically(png, std::string(bytes.begin(), bytes.end()));
}

}  // namespace lidar2d::cli
