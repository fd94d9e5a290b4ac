#pragma once
/// @file
/// 8-bit images for maps, masks and pictures: PGM (P5 binary, P2 plain) and PNG in, PNG out.
/// PNG goes through libpng (not OpenCV's imgcodecs, whose GDAL dependency pulls about 120 shared
/// libraries into every process: 90 ms of dynamic linking per start on this machine kind).

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

namespace lidar2d::io {

/// A decoded image: a grey value per pixel (the integer mean of the colour channels, as ROS's
/// map_server computes it) and the alpha channel (empty when the image has none), top row first.
struct GreyImage {
  int width = 0, height = 0;
  std::vector<std::uint8_t> value;
  std::vector<std::uint8_t> alpha;
};

/// Decodes the bytes of a PGM (P5 or P2, maxval up to 255) or an 8-bit PNG (grey, grey+alpha,
/// palette, RGB, RGBA). Throws `lidar2d::Error` (kBadInput) naming `path` and the field (magic,
/// width, maxval, pixels, depth) on anything else, a truncated file, or more than 10^9 pixels.
GreyImage decodeGreyImage(const std::string& bytes, const std::string& path);

/// Reads and decodes `path`. A missing or unreadable file is a kIo error naming `path` and `field`.
GreyImage readGreyImage(const std::string& path, const std::string& field = "image");

/// Encodes 8-bit pixels as PNG: `channels` 1 (grey) or 3 (blue, green, red: OpenCV's order), rows
/// top first, `row_stride` bytes apart. `path` names the output in errors.
std::vector<std::uint8_t> encodePng(const std::uint8_t* pixels, int width, int height, int channels,
                                    std::size_t row_stride, const std::string& path);

}  // namespace lidar2d::io
