#include "lidar2d/io/image.hpp"

#include <fmt/format.h>
#include <png.h>

#include <cctype>
#include <limits>

#include "lidar2d/core/error.hpp"
#include "lidar2d/io/map_file.hpp"
#include "src/io/internal/read_file.hpp"

namespace lidar2d::io {
namespace {

using Grey = GreyImage;

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

/// libpng's simplified API (png_image_*): it handles every PNG colour type and bit depth and
/// reports errors in `image.message` instead of longjmp-ing through our stack frames.
Grey decodePng(const std::string& data, const std::string& path) {
  png_image image{};
  image.version = PNG_IMAGE_VERSION;
  if (!png_image_begin_read_from_memory(&image, data.data(), data.size()))
    throw badInput(fmt::format("unreadable PNG: {}", image.message), {path, 0, "header"});
  struct Release {
    png_image* p;
    ~Release() { png_image_free(p); }
  } release{&image};
  if (image.format & PNG_FORMAT_FLAG_LINEAR) throw badInput("only 8-bit images are supported", {path, 0, "depth"});
  if (image.width == 0 || image.height == 0 ||
      static_cast<std::uint64_t>(image.width) * image.height > OccupancyImage::kMaxCells)
    throw badInput(fmt::format("{} x {} pixels: empty or above the limit of 10^9", image.width, image.height),
                   {path, 0, "width"});
  const bool colour = image.format & PNG_FORMAT_FLAG_COLOR;
  const bool has_alpha = image.format & PNG_FORMAT_FLAG_ALPHA;
  // Read as RGBA (palettes expanded, grey replicated) and take the plain mean of the colour
  // channels like map_server, not libpng's weighted luminance.
  image.format = PNG_FORMAT_RGBA;
  const std::size_t n = static_cast<std::size_t>(image.width) * image.height;
  std::vector<std::uint8_t> rgba(4 * n);
  if (!png_image_finish_read(&image, nullptr, rgba.data(), 0, nullptr))
    throw badInput(fmt::format("corrupt or truncated PNG: {}", image.message), {path, 0, "pixels"});
  Grey g;
  g.width = static_cast<int>(image.width);
  g.height = static_cast<int>(image.height);
  g.value.resize(n);
  if (has_alpha) g.alpha.resize(n);
  for (std::size_t i = 0; i < n; ++i) {
    const std::uint8_t* p = &rgba[4 * i];
    g.value[i] = colour ? static_cast<std::uint8_t>((p[0] + p[1] + p[2]) / 3) : p[0];
    if (has_alpha) g.alpha[i] = p[3];
  }
  return g;
}

}  // namespace

GreyImage decodeGreyImage(const std::string& data, const std::string& path) {
  if (data.empty()) throw badInput("image file is empty", {path, 0, "magic"});
  if (data.size() >= 2 && data[0] == 'P' && (data[1] == '5' || data[1] == '2')) return parsePgm(data, path);
  if (data.size() >= 2 && data[0] == 'P' && data[1] >= '1' && data[1] <= '7')
    throw badInput(fmt::format("PGM magic P5 or P2 expected, found P{}", data[1]), {path, 0, "magic"});
  static constexpr unsigned char kPngSignature[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
  if (data.size() >= 8 && std::equal(kPngSignature, kPngSignature + 8, data.begin(),
                                     [](unsigned char a, char b) { return a == static_cast<unsigned char>(b); }))
    return decodePng(data, path);
  throw badInput("unrecognised image format (expected PGM P5/P2 or PNG)", {path, 0, "magic"});
}

GreyImage readGreyImage(const std::string& path, const std::string& field) {
  // The largest image decodeGreyImage accepts (OccupancyImage::kMaxCells pixels) as ASCII PGM
  // takes up to 4 bytes a pixel.
  constexpr std::uint64_t kMaxBytes = std::uint64_t{4} << 30;
  return decodeGreyImage(internal::readWholeFile(path, kMaxBytes, "image file", field), path);
}

std::vector<std::uint8_t> encodePng(const std::uint8_t* pixels, int width, int height, int channels,
                                    std::size_t row_stride, const std::string& path) {
  if (width < 1 || height < 1 || (channels != 1 && channels != 3) ||
      row_stride < static_cast<std::size_t>(width) * static_cast<std::size_t>(channels) ||
      row_stride > static_cast<std::size_t>(std::numeric_limits<png_int_32>::max()))
    throw invalidArgument(fmt::format("cannot encode a {} x {} image with {} channels as PNG", width, height, channels),
                          ErrorLocation(path));
  png_image image{};
  image.version = PNG_IMAGE_VERSION;
  image.width = static_cast<png_uint_32>(width);
  image.height = static_cast<png_uint_32>(height);
  image.format = channels == 1 ? PNG_FORMAT_GRAY : PNG_FORMAT_BGR;
  const auto stride = static_cast<png_int_32>(row_stride);
  // One compression pass into a buffer of libpng's upper bound on the encoded size
  // (PNG_IMAGE_PNG_SIZE_MAX), rather than a first pass that only sizes the output: the compression
  // is most of the cost (half of writing a map's files). Should the bound still fall short, libpng
  // reports the size it needs (png.h, png_image_write_to_memory) and the second call has it.
  std::vector<std::uint8_t> out(PNG_IMAGE_PNG_SIZE_MAX(image));
  for (int attempt = 0; attempt < 2; ++attempt) {
    png_alloc_size_t size = out.size();
    if (png_image_write_to_memory(&image, out.data(), &size, 0, pixels, stride, nullptr)) {
      out.resize(size);
      return out;
    }
    if (size <= out.size()) break;  // unchanged: an error, not a short buffer
    out.resize(size);
    png_image_free(&image);
    image.warning_or_error = 0;
  }
  throw ioError(fmt::format("PNG encoding failed: {}", image.message), ErrorLocation(path));
}

}  // namespace lidar2d::io
