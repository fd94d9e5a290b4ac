// io/image: PGM and PNG decoding to grey (+ alpha), PNG encoding, and bad image files. The PNGs
// here are assembled chunk by chunk with zlib (not with libpng, which the code under test uses),
// so the decoder is checked against the format itself.

#include <gtest/gtest.h>
#include <zlib.h>

#include <cstdint>
#include <string>
#include <vector>

#include "lidar2d/core/error.hpp"
#include "lidar2d/io/image.hpp"
#include "support/test_support.hpp"

namespace lidar2d::io {
namespace {

using test::throwsError;

void put32(std::string& s, std::uint32_t v) {
  for (int k = 3; k >= 0; --k) s.push_back(static_cast<char>((v >> (8 * k)) & 0xff));
}

void chunk(std::string& png, const char* type, const std::string& data) {
  put32(png, static_cast<std::uint32_t>(data.size()));
  const std::string body = std::string(type, 4) + data;
  png += body;
  put32(png, static_cast<std::uint32_t>(crc32(0, reinterpret_cast<const Bytef*>(body.data()), static_cast<uInt>(body.size()))));
}

/// A PNG of `width` x `height` with the given colour type and bit depth; `rows` holds the raw
/// scanlines without filter bytes (filter 0 is added), `plte` the palette when colour type 3.
std::string makePng(int width, int height, int colour_type, int depth, const std::string& rows,
                    const std::string& plte = "") {
  std::string png("\x89PNG\r\n\x1a\n", 8);
  std::string ihdr;
  put32(ihdr, static_cast<std::uint32_t>(width));
  put32(ihdr, static_cast<std::uint32_t>(height));
  ihdr += {static_cast<char>(depth), static_cast<char>(colour_type), 0, 0, 0};
  chunk(png, "IHDR", ihdr);
  if (!plte.empty()) chunk(png, "PLTE", plte);
  const std::size_t row_bytes = rows.size() / static_cast<std::size_t>(height);
  std::string raw;
  for (int r = 0; r < height; ++r) raw += '\0' + rows.substr(static_cast<std::size_t>(r) * row_bytes, row_bytes);
  uLongf n = compressBound(static_cast<uLong>(raw.size()));
  std::string z(n, '\0');
  compress(reinterpret_cast<Bytef*>(z.data()), &n, reinterpret_cast<const Bytef*>(raw.data()), static_cast<uLong>(raw.size()));
  z.resize(n);
  chunk(png, "IDAT", z);
  chunk(png, "IEND", "");
  return png;
}

std::string bytes(std::initializer_list<int> v) {
  std::string s;
  for (int x : v) s.push_back(static_cast<char>(x));
  return s;
}

TEST(Image, PngGreyAlphaPaletteAndColour) {
  // Grey + alpha (colour type 4), 2 x 1.
  auto g = decodeGreyImage(makePng(2, 1, 4, 8, bytes({10, 255, 200, 0})), "ga.png");
  EXPECT_EQ(g.width, 2);
  EXPECT_EQ(g.value, (std::vector<std::uint8_t>{10, 200}));
  EXPECT_EQ(g.alpha, (std::vector<std::uint8_t>{255, 0}));
  // RGB (type 2): the plain mean of the channels, as map_server takes it (not luminance).
  g = decodeGreyImage(makePng(1, 2, 2, 8, bytes({255, 0, 0, 30, 60, 90})), "rgb.png");
  EXPECT_EQ(g.value, (std::vector<std::uint8_t>{85, 60}));
  EXPECT_TRUE(g.alpha.empty());
  // Palette (type 3), 4 bits per pixel, 3 x 1: indices 1 0 1.
  g = decodeGreyImage(makePng(3, 1, 3, 4, bytes({0x10, 0x10}), bytes({0, 0, 0, 240, 240, 240})), "pal.png");
  EXPECT_EQ(g.value, (std::vector<std::uint8_t>{240, 0, 240}));
  // 1-bit grey, 3 x 2, top row first.
  g = decodeGreyImage(makePng(3, 2, 0, 1, bytes({0xa0, 0x40})), "bits.png");
  EXPECT_EQ(g.value, (std::vector<std::uint8_t>{255, 0, 255, 0, 255, 0}));
}

TEST(Image, PngEncodeRoundTrip) {
  const std::vector<std::uint8_t> grey{0, 1, 2, 127, 128, 254, 255, 7};  // 4 x 2, stride 4
  const auto png = encodePng(grey.data(), 4, 2, 1, 4, "g.png");
  const auto g = decodeGreyImage(std::string(png.begin(), png.end()), "g.png");
  EXPECT_EQ(g.width, 4);
  EXPECT_EQ(g.height, 2);
  EXPECT_EQ(g.value, grey);
  // Three-channel input in blue, green, red order with padded rows (stride 8 for 2 pixels).
  const std::vector<std::uint8_t> bgr{0, 0, 255, 30, 60, 90, 99, 99, 9, 9, 9, 12, 12, 12, 99, 99};
  const auto png3 = encodePng(bgr.data(), 2, 2, 3, 8, "c.png");
  const auto c = decodeGreyImage(std::string(png3.begin(), png3.end()), "c.png");
  EXPECT_EQ(c.value, (std::vector<std::uint8_t>{85, 60, 9, 12}));
  EXPECT_TRUE(throwsError([&] { encodePng(grey.data(), 4, 2, 2, 8, "x.png"); }, ErrorKind::kInvalidArgument,
                          {"x.png", "channels"}));
  EXPECT_TRUE(throwsError([&] { encodePng(grey.data(), 4, 2, 1, 3, "x.png"); }, ErrorKind::kInvalidArgument,
                          {"x.png"}));
}

TEST(Image, BadFilesNameTheFileAndField) {
  const std::string good = makePng(2, 2, 0, 8, bytes({1, 2, 3, 4}));
  EXPECT_TRUE(throwsError([&] { decodeGreyImage("", "e.png"); }, ErrorKind::kBadInput, {"e.png", "empty"}));
  EXPECT_TRUE(throwsError([&] { decodeGreyImage("GIF89a....", "a.gif"); }, ErrorKind::kBadInput,
                          {"a.gif", "unrecognised image format"}));
  EXPECT_TRUE(throwsError([&] { decodeGreyImage("P6\n1 1\n255\nabc", "c.ppm"); }, ErrorKind::kBadInput,
                          {"c.ppm", "P5 or P2"}));
  EXPECT_TRUE(throwsError([&] { decodeGreyImage(good.substr(0, good.size() - 20), "t.png"); }, ErrorKind::kBadInput,
                          {"t.png", "PNG"}));
  std::string bad_crc = good;
  bad_crc[29] ^= 1;  // inside IHDR's CRC
  EXPECT_TRUE(throwsError([&] { decodeGreyImage(bad_crc, "crc.png"); }, ErrorKind::kBadInput, {"crc.png", "PNG"}));
  EXPECT_TRUE(throwsError([&] { decodeGreyImage(makePng(1, 1, 0, 16, bytes({1, 2})), "deep.png"); },
                          ErrorKind::kBadInput, {"deep.png", "8-bit"}));
  EXPECT_TRUE(throwsError([&] { decodeGreyImage(makePng(0, 1, 0, 8, ""), "zero.png"); }, ErrorKind::kBadInput,
                          {"zero.png"}));
  EXPECT_TRUE(throwsError([&] { readGreyImage("/nonexistent/m.png", "prior"); }, ErrorKind::kIo,
                          {"/nonexistent/m.png", "does not exist", "prior"}));
}

}  // namespace
}  // namespace lidar2d::io
