// map_server map files: the real maps in shared/data, pixel interpretation (trinary, scale, raw,
// negate), PGM P5/P2 and PNG, a write/read round trip, and malformed input.

#include <gtest/gtest.h>

#include <array>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "lidar2d/core/error.hpp"
#include "lidar2d/io/map_file.hpp"
#include "support/test_support.hpp"

namespace lidar2d::io {
namespace {

namespace fs = std::filesystem;
using lidar2d::test::dataFile;
using lidar2d::test::TempDir;
using lidar2d::test::writeFile;

struct Counts {
  std::size_t occupied = 0, free = 0, unknown = 0, other = 0;
};
Counts count(const OccupancyImage& m) {
  Counts c;
  for (auto v : m.cells()) {
    if (v == 100)
      ++c.occupied;
    else if (v == 0)
      ++c.free;
    else if (v == -1)
      ++c.unknown;
    else
      ++c.other;
  }
  return c;
}

// Expects readMap(yaml) to throw a lidar2d::Error whose message contains every `parts`.
void expectError(const fs::path& yaml, std::initializer_list<std::string> parts) {
  try {
    readMap(yaml.string());
    ADD_FAILURE() << "no error for " << yaml;
  } catch (const Error& e) {
    for (const auto& p : parts) EXPECT_NE(std::string(e.what()).find(p), std::string::npos) << e.what() << " lacks " << p;
  }
}

// ---- the real maps ----
// Expected values from the files themselves, independently of this code:
//   head -c 16 X.pgm | od -c          -> the P5 header (width, height, maxval 255)
//   /usr/bin/python3: collections.Counter over the pixel bytes -> counts of the values 0, 205, 254
//   and the positions of the first pixel of value 0 and of value 254 in image order.
// With occupied_thresh 0.65 and free_thresh 0.25 (as in these YAMLs), map_server reads 0 as
// occupied (p = 1) and both 205 (p = 0.196 < 0.25) and 254 as free: no unknown cells.

TEST(MapFile, ReadsMac9_23) {
  LIDAR2D_REQUIRE_DATA("ros2/maps/mac_1st_floor_9_23.yaml");
  const MapFile f = readMap(dataFile("ros2/maps/mac_1st_floor_9_23.yaml").string());
  const OccupancyImage& m = f.map;
  EXPECT_EQ(m.width(), 530);
  EXPECT_EQ(m.height(), 1433);
  EXPECT_DOUBLE_EQ(m.resolution(), 0.03);
  EXPECT_DOUBLE_EQ(m.origin().x(), -1.37);
  EXPECT_DOUBLE_EQ(m.origin().y(), -27.9);
  EXPECT_DOUBLE_EQ(m.origin().theta(), 0.0);
  EXPECT_DOUBLE_EQ(f.yaml.free_thresh, 0.25);
  EXPECT_EQ(f.yaml.mode, MapMode::kTrinary);
  const Counts c = count(m);
  EXPECT_EQ(c.occupied, 16670u);             // pixels of value 0
  EXPECT_EQ(c.free, 504109u + 238711u);      // pixels of value 205 and 254
  EXPECT_EQ(c.unknown, 0u);
  // First value-0 pixel: image column 146, image row 0 (the top row) -> cell row 1432.
  EXPECT_EQ(m.at(146, 1432), 100);
  EXPECT_EQ(m.at(145, 1432), 0);  // 205 before it
  EXPECT_EQ(m.at(149, 1431), 0);  // first 254: column 149, image row 1
  // Cell (0, 0) is the bottom-left pixel; its lower-left corner is the origin.
  EXPECT_TRUE(m.cellCenter(0, 0).isApprox(Eigen::Vector2d(-1.37 + 0.015, -27.9 + 0.015)));
  EXPECT_EQ(m.worldToCell(Eigen::Vector2d(-1.37 + 146.5 * 0.03, -27.9 + 1432.5 * 0.03)), Eigen::Vector2i(146, 1432));
}

TEST(MapFile, ReadsMacFinalAndThresholdsMatter) {
  LIDAR2D_REQUIRE_DATA("ros2/maps/mac_1st_floor_final.yaml");
  const MapFile f = readMap(dataFile("ros2/maps/mac_1st_floor_final.yaml").string());
  EXPECT_EQ(f.map.width(), 903);
  EXPECT_EQ(f.map.height(), 1706);
  EXPECT_DOUBLE_EQ(f.map.origin().x(), -1.12);
  EXPECT_DOUBLE_EQ(f.map.origin().y(), -39.4);
  Counts c = count(f.map);
  EXPECT_EQ(c.occupied, 16871u);
  EXPECT_EQ(c.free, 1220114u + 303533u);
  EXPECT_EQ(f.map.at(247, 1706 - 1 - 8), 100);  // first value-0 pixel: column 247, image row 8

  // The same image with map_saver's free_thresh 0.196: 205 (p = 0.19608) becomes unknown.
  TempDir tmp;
  const std::string img = dataFile("ros2/maps/mac_1st_floor_final.pgm").string();
  writeFile(tmp / "a.yaml", "image: " + img + "\nresolution: 0.03\norigin: [-1.12, -39.4, 0]\nnegate: 0\n"
                                             "occupied_thresh: 0.65\nfree_thresh: 0.196\n");
  c = count(readMap((tmp / "a.yaml").string()).map);
  EXPECT_EQ(c.unknown, 1220114u);
  EXPECT_EQ(c.free, 303533u);
  // negate: 0 -> p = 0 (free), 254 -> p = 0.996 and 205 -> p = 0.804 (occupied).
  writeFile(tmp / "b.yaml", "image: " + img + "\nresolution: 0.03\norigin: [-1.12, -39.4, 0]\nnegate: 1\n"
                                             "occupied_thresh: 0.65\nfree_thresh: 0.196\n");
  c = count(readMap((tmp / "b.yaml").string()).map);
  EXPECT_EQ(c.free, 16871u);
  EXPECT_EQ(c.occupied, 1220114u + 303533u);
}

// ---- pixel interpretation on synthetic images ----

std::string pgm(int w, int h, const std::vector<int>& px, int maxval = 255) {
  std::string s = "P5\n# a comment\n" + std::to_string(w) + " " + std::to_string(h) + "\n" + std::to_string(maxval) + "\n";
  for (int v : px) s.push_back(static_cast<char>(v));
  return s;
}

TEST(MapFile, ScaleAndRawModes) {
  TempDir tmp;
  // One row: 0, 50, 100, 150, 200, 254.
  writeFile(tmp / "m.pgm", pgm(6, 1, {0, 50, 100, 150, 200, 254}));
  writeFile(tmp / "scale.yaml", "image: m.pgm\nresolution: 0.1\norigin: [0, 0, 0]\nnegate: 0\n"
                                "occupied_thresh: 0.65\nfree_thresh: 0.196\nmode: scale\n");
  const auto s = readMap((tmp / "scale.yaml").string()).map;
  // p = (255 - v) / 255: 1 -> 100; 0.804 -> 100; 0.608 -> 1 + 98 * (0.608 - 0.196) / (0.65 - 0.196) = 89.9 -> 89;
  // 0.412 -> 1 + 98 * 0.4754 = 47.6 -> 47; 0.216 -> 1 + 98 * 0.0436 = 5.3 -> 5; 0.004 -> 0.
  EXPECT_EQ(s.cells(), (std::vector<std::int8_t>{100, 100, 89, 47, 5, 0}));
  writeFile(tmp / "tri.yaml", "image: m.pgm\nresolution: 0.1\norigin: [0, 0, 0]\nmode: trinary\n");
  EXPECT_EQ(readMap((tmp / "tri.yaml").string()).map.cells(), (std::vector<std::int8_t>{100, 100, -1, -1, -1, 0}));
  writeFile(tmp / "raw.yaml", "image: m.pgm\nresolution: 0.1\norigin: [0, 0, 0]\nmode: raw\n");
  EXPECT_EQ(readMap((tmp / "raw.yaml").string()).map.cells(), (std::vector<std::int8_t>{0, 50, 100, -1, -1, -1}));
}

TEST(MapFile, AsciiPgmSmallMaxvalAndRowOrder) {
  TempDir tmp;
  // 2 x 2, maxval 15: top row "0 15", bottom row "15 0" -> scaled to 0/255.
  writeFile(tmp / "a.pgm", "P2\n2 2\n# comment\n15\n0 15\n15 0\n");
  writeFile(tmp / "a.yaml", "image: a.pgm\nresolution: 0.5\norigin: [1, 2, 0]\n");
  const auto m = readMap((tmp / "a.yaml").string()).map;
  EXPECT_EQ(m.at(0, 1), 100);  // top-left pixel (0) is occupied
  EXPECT_EQ(m.at(1, 1), 0);
  EXPECT_EQ(m.at(0, 0), 0);
  EXPECT_EQ(m.at(1, 0), 100);
}

TEST(MapFile, Png) {
  TempDir tmp;
  // A 3 x 2 8-bit grey PNG (made with python3's zlib): top row 0 205 254, bottom row 254 0 100.
  static const unsigned char kPng[] = {
      0x89, 0x50, 0x4e, 0x47, 0x0d, 0x0a, 0x1a, 0x0a, 0x00, 0x00, 0x00, 0x0d, 0x49, 0x48, 0x44, 0x52, 0x00, 0x00, 0x00,
      0x03, 0x00, 0x00, 0x00, 0x02, 0x08, 0x00, 0x00, 0x00, 0x00, 0xb8, 0x1f, 0x39, 0xc6, 0x00, 0x00, 0x00, 0x10, 0x49,
      0x44, 0x41, 0x54, 0x78, 0x9c, 0x63, 0x60, 0x38, 0xfb, 0x8f, 0xe1, 0x1f, 0x43, 0x0a, 0x00, 0x0d, 0x2a, 0x03, 0x2e,
      0xd4, 0x37, 0xfd, 0x9c, 0x00, 0x00, 0x00, 0x00, 0x49, 0x45, 0x4e, 0x44, 0xae, 0x42, 0x60, 0x82};
  writeFile(tmp / "m.png", std::string(reinterpret_cast<const char*>(kPng), sizeof(kPng)));
  writeFile(tmp / "m.yaml", "image: m.png\nresolution: 0.05\norigin: [0, 0, 0]\n");
  const auto m = readMap((tmp / "m.yaml").string()).map;
  ASSERT_EQ(m.width(), 3);
  ASSERT_EQ(m.height(), 2);
  // Row 0 = bottom image row; 205 and 100 are between the default thresholds -> unknown.
  EXPECT_EQ(m.cells(), (std::vector<std::int8_t>{0, 100, -1, 100, -1, 0}));
}

// ---- writing ----

TEST(MapFile, WriteReadRoundTrip) {
  TempDir tmp;
  std::vector<std::int8_t> cells{-1, 0, 100, 30, 70, 25, 64, 65};
  auto m = OccupancyImage::create(4, 2, 0.05, SE2(-3.25, 7.125, 0.0), cells);
  const std::string yaml = (tmp / "out.yaml").string();
  writeMap(yaml, m);
  EXPECT_TRUE(fs::exists(tmp / "out.pgm"));
  const std::string y = test::readFile(tmp / "out.yaml");
  EXPECT_NE(y.find("image: out.pgm\n"), std::string::npos) << y;
  EXPECT_NE(y.find("mode: trinary"), std::string::npos);
  EXPECT_NE(y.find("free_thresh: 0.196"), std::string::npos);
  // Pixel bytes: top row first; 254 free, 0 occupied, 205 unknown.
  const std::string p = test::readFile(tmp / "out.pgm");
  const std::string px = p.substr(p.size() - 8);
  // Top row (70, 25, 64, 65) -> 0 254 205 0; bottom row (-1, 0, 100, 30) -> 205 254 0 205.
  EXPECT_EQ(px, std::string("\x00\xfe\xcd\x00\xcd\xfe\x00\xcd", 8));
  const MapFile back = readMap(yaml);
  EXPECT_EQ(back.map.width(), 4);
  EXPECT_EQ(back.map.height(), 2);
  EXPECT_DOUBLE_EQ(back.map.resolution(), 0.05);
  EXPECT_DOUBLE_EQ(back.map.origin().x(), -3.25);
  EXPECT_DOUBLE_EQ(back.map.origin().y(), 7.125);
  EXPECT_EQ(back.map.cells(), (std::vector<std::int8_t>{-1, 0, 100, -1, 100, 0, -1, 100}));
  // A second round trip is the identity.
  writeMap((tmp / "again.yaml").string(), back.map, (tmp / "sub.pgm").string());
  EXPECT_EQ(readMap((tmp / "again.yaml").string()).map.cells(), back.map.cells());
}

TEST(MapFile, WriteIntoMissingFolderFailsWithoutOutput) {
  TempDir tmp;
  const auto m = OccupancyImage::filled(3, 3, 0.1, SE2());
  EXPECT_THROW(writeMap((tmp / "nope" / "m.yaml").string(), m), Error);
  EXPECT_FALSE(fs::exists(tmp / "nope"));
  EXPECT_TRUE(fs::is_empty(tmp.path()));
}

// ---- invariants and malformed input ----

TEST(OccupancyImage, ChecksInvariants) {
  EXPECT_THROW(OccupancyImage::create(0, 1, 0.1, SE2(), {}), Error);
  EXPECT_THROW(OccupancyImage::create(1, 1, 0.0, SE2(), {0}), Error);
  EXPECT_THROW(OccupancyImage::create(1, 1, -0.1, SE2(), {0}), Error);
  EXPECT_THROW(OccupancyImage::create(2, 1, 0.1, SE2(), {0}), Error);
  EXPECT_THROW(OccupancyImage::create(1, 1, 0.1, SE2(), {101}), Error);
  EXPECT_THROW(OccupancyImage::create(1, 1, 0.1, SE2(std::nan(""), 0, 0), {0}), Error);
  EXPECT_THROW(OccupancyImage::filled(100000, 100000, 0.1, SE2()), Error);
  // A rotated origin: cell centres and worldToCell agree.
  const auto m = OccupancyImage::filled(10, 5, 0.2, SE2(1, 2, 0.5), 0);
  for (int r = 0; r < 5; ++r)
    for (int c = 0; c < 10; ++c) EXPECT_EQ(m.worldToCell(m.cellCenter(c, r)), Eigen::Vector2i(c, r));
  EXPECT_EQ(m.worldToCell(Eigen::Vector2d(-5, -5)), std::nullopt);
}

TEST(MapFile, MalformedInput) {
  TempDir tmp;
  writeFile(tmp / "ok.pgm", pgm(2, 2, {0, 0, 254, 254}));
  auto yaml = [&](const std::string& name, const std::string& body) {
    writeFile(tmp / name, body);
    return tmp / name;
  };
  const std::string rest = "\nresolution: 0.05\norigin: [0, 0, 0]\n";
  expectError(tmp / "missing.yaml", {"missing.yaml", "does not exist"});
  expectError(yaml("noimage.yaml", "resolution: 0.05\norigin: [0, 0, 0]\n"), {"noimage.yaml", "image", "missing"});
  expectError(yaml("res0.yaml", "image: ok.pgm\nresolution: 0\norigin: [0, 0, 0]\n"), {"res0.yaml", "resolution"});
  expectError(yaml("resneg.yaml", "image: ok.pgm\nresolution: -1\norigin: [0, 0, 0]\n"), {"resolution", "between"});
  // Absurd values that used to load, and then made `localize-index` loop without end (1e308: the
  // map's extent overflowed) or overflow its cell arithmetic (1e-300).
  expectError(yaml("reshuge.yaml", "image: ok.pgm\nresolution: 1e308\norigin: [0, 0, 0]\n"), {"resolution", "100 m"});
  expectError(yaml("restiny.yaml", "image: ok.pgm\nresolution: 1e-300\norigin: [0, 0, 0]\n"), {"resolution", "0.0001"});
  expectError(yaml("originfar.yaml", "image: ok.pgm\nresolution: 0.05\norigin: [0, -1e12, 0]\n"), {"origin", "1e+09"});
  expectError(yaml("resstr.yaml", "image: ok.pgm\nresolution: fine\norigin: [0, 0, 0]\n"), {"resolution", "numeric"});
  expectError(yaml("origin.yaml", "image: ok.pgm\nresolution: 0.05\norigin: [0, 0]\n"), {"origin"});
  expectError(yaml("thresh.yaml", "image: ok.pgm" + rest + "occupied_thresh: 0.1\nfree_thresh: 0.5\n"), {"free_thresh"});
  expectError(yaml("mode.yaml", "image: ok.pgm" + rest + "mode: fancy\n"), {"mode", "fancy"});
  expectError(yaml("bad.yaml", "image: [unclosed\n"), {"bad.yaml", "malformed YAML"});
  expectError(yaml("noimg.yaml", "image: nothere.pgm" + rest), {"nothere.pgm", "does not exist"});
  writeFile(tmp / "trunc.pgm", pgm(4, 4, {0, 0, 0}));
  expectError(yaml("trunc.yaml", "image: trunc.pgm" + rest), {"trunc.pgm", "truncated"});
  writeFile(tmp / "hdr.pgm", "P5\n4 ");
  expectError(yaml("hdr.yaml", "image: hdr.pgm" + rest), {"hdr.pgm", "height"});
  writeFile(tmp / "magic.pgm", "P6\n2 2\n255\n............");
  expectError(yaml("magic.yaml", "image: magic.pgm" + rest), {"magic.pgm", "magic", "P6"});
  writeFile(tmp / "junk.pgm", "this is not an image at all");
  expectError(yaml("junk.yaml", "image: junk.pgm" + rest), {"junk.pgm", "magic"});
  writeFile(tmp / "huge.pgm", "P5\n100000 100000\n255\n\x01\x02");
  expectError(yaml("huge.yaml", "image: huge.pgm" + rest), {"huge.pgm", "10^9"});
  writeFile(tmp / "deep.pgm", "P5\n1 1\n65535\n\x01\x02");
  expectError(yaml("deep.yaml", "image: deep.pgm" + rest), {"deep.pgm", "8-bit"});
  writeFile(tmp / "empty.pgm", "");
  expectError(yaml("empty.yaml", "image: empty.pgm" + rest), {"empty.pgm", "empty"});
  // Not files: a directory, and a device that never ends (read whole, it ran out of memory).
  expectError(yaml("dir.yaml", "image: " + tmp.path().string() + rest), {"is a directory", "image file"});
  expectError(yaml("dev.yaml", "image: /dev/zero" + rest), {"/dev/zero", "device", "image file"});
  expectError("/dev/zero", {"/dev/zero", "device", "map YAML"});
  expectError(tmp.path(), {"is a directory", "map YAML"});
  writeFile(tmp / "big.yaml", "image: ok.pgm" + rest + "# " + std::string(2 << 20, 'x') + "\n");
  expectError(tmp / "big.yaml", {"big.yaml", "MiB limit"});
}

TEST(MapFile, OccupancyImageRejectsAbsurdGeometry) {
  const SE2 o(0, 0, 0);
  EXPECT_TRUE(test::throwsError([&] { OccupancyImage::filled(2, 2, 1e308, o); }, ErrorKind::kInvalidArgument, {"resolution"}));
  EXPECT_TRUE(test::throwsError([&] { OccupancyImage::filled(2, 2, 1e-5, o); }, ErrorKind::kInvalidArgument, {"resolution"}));
  EXPECT_TRUE(test::throwsError([&] { OccupancyImage::filled(2, 2, 0.05, SE2(2e9, 0, 0)); }, ErrorKind::kInvalidArgument, {"origin"}));
  EXPECT_NO_THROW(OccupancyImage::filled(2, 2, 100.0, SE2(-1e9, 1e9, 0)));
}

}  // namespace
}  // namespace lidar2d::io
