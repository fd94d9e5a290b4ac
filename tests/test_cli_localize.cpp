// lidar2d localize-index / localize end to end: output format (one line per scan, "t nan nan nan 0"
// when declining), the JSON summary, a database from another map, and bad input (exit 1, one line,
// no output file).

#include <fmt/format.h>
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <vector>

#include "lidar2d/io/image.hpp"
#include "lidar2d/io/map_file.hpp"
#include "support/table_rows.hpp"
#include "support/test_support.hpp"

namespace lidar2d {
namespace {

namespace fs = std::filesystem;
using test::runCli;

class CliLocalize : public ::testing::Test {
 protected:
  // The logs and maps are made on first use (once per process), by the first test that needs them.
  static void SetUpTestSuite() { dir_ = new test::TempDir(); }
  static void needOffice() {
    if (fs::exists(path("office.yaml"))) return;
    auto r = runCli({"simulate", "--world", "office", "--scans", "300", "--seed", "5", "-o", path("office.log")});
    ASSERT_EQ(r.exit_code, 0) << r.err;
    r = runCli({"simulate", "--world", "office", "--scans", "20", "--seed", "9", "-o", path("query.log")});
    ASSERT_EQ(r.exit_code, 0) << r.err;
    r = runCli({"map", path("office.log"), "-o", path("office"), "-q"});
    ASSERT_EQ(r.exit_code, 0) << r.err;
  }
  static void needSymmetric() {
    if (fs::exists(path("sym.yaml"))) return;
    auto r = runCli({"simulate", "--world", "symmetric", "--scans", "200", "--seed", "5", "-o", path("sym.log")});
    ASSERT_EQ(r.exit_code, 0) << r.err;
    r = runCli({"map", path("sym.log"), "-o", path("sym"), "-q"});
    ASSERT_EQ(r.exit_code, 0) << r.err;
  }
  // The open world (its rooms are not their own mirror images, as the office's are): a map, query
  // scans, and the map's image with its rows in reverse order (as an array written row = y is).
  static void needOpen() {
    if (fs::exists(path("open-rev.png"))) return;
    auto r = runCli({"simulate", "--world", "open", "--scans", "200", "--seed", "5", "-o", path("open.log")});
    ASSERT_EQ(r.exit_code, 0) << r.err;
    r = runCli({"simulate", "--world", "open", "--scans", "24", "--seed", "9", "-o", path("openq.log")});
    ASSERT_EQ(r.exit_code, 0) << r.err;
    r = runCli({"map", path("open.log"), "-o", path("open"), "-q"});
    ASSERT_EQ(r.exit_code, 0) << r.err;
    const io::MapFile m = io::readMap(path("open.yaml"));
    const io::GreyImage g = io::readGreyImage(m.image_path);
    std::vector<std::uint8_t> rev(g.value.size());
    const auto w = static_cast<std::size_t>(g.width), h = static_cast<std::size_t>(g.height);
    for (std::size_t row = 0; row < h; ++row)
      std::copy_n(g.value.begin() + static_cast<std::ptrdiff_t>((h - 1 - row) * w), w,
                  rev.begin() + static_cast<std::ptrdiff_t>(row * w));
    const auto png = io::encodePng(rev.data(), g.width, g.height, 1, w, path("open-rev.png"));
    test::writeFile(path("open-rev.png"), std::string(png.begin(), png.end()));
    open_resolution_ = fmt::format("{}", m.yaml.resolution);
    open_origin_ = fmt::format("{},{},{}", m.yaml.origin.x(), m.yaml.origin.y(), m.yaml.origin.theta());
  }
  static void TearDownTestSuite() { delete dir_; }
  static std::string path(const std::string& name) { return (*dir_ / name).string(); }
  static std::vector<std::vector<std::string>> rows(const std::string& file) { return test::tableRows(file); }
  static test::TempDir* dir_;
  static std::string open_resolution_, open_origin_;  ///< open.yaml's, as the command line gives them
};
test::TempDir* CliLocalize::dir_ = nullptr;
std::string CliLocalize::open_resolution_, CliLocalize::open_origin_;

TEST_F(CliLocalize, IndexThenLocalizeWritesOneLinePerScanAndJson) {
  ASSERT_NO_FATAL_FAILURE(needOffice());
  auto r = runCli({"localize-index", path("office.yaml"), "-o", path("office.db"), "--step", "0.3"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  ASSERT_TRUE(fs::exists(path("office.db")));
  r = runCli({"localize", path("office.yaml"), path("query.log"), "--db", path("office.db"), "-o", path("loc.txt"),
              "--json", path("loc.json"), "--eval"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto lines = rows(path("loc.txt"));
  ASSERT_EQ(lines.size(), 20u);
  std::size_t answered = 0;
  for (const auto& f : lines) {
    ASSERT_EQ(f.size(), 5u);
    if (f[1] == "nan") {
      EXPECT_EQ(f[2], "nan");
      EXPECT_EQ(f[3], "nan");
      EXPECT_EQ(f[4], "0");
    } else {
      ++answered;
      EXPECT_TRUE(std::isfinite(std::stod(f[1])));
      const double score = std::stod(f[4]);
      EXPECT_GT(score, 0.0);
      EXPECT_LE(score, 1.0);
    }
  }
  EXPECT_GE(answered, 12u);
  std::ifstream in(path("loc.json"));
  const auto j = nlohmann::json::parse(in);
  EXPECT_EQ(j.at("scans").get<int>(), 20);
  EXPECT_EQ(j.at("answered").get<std::size_t>(), answered);
  EXPECT_TRUE(j.at("query_ms").contains("median"));
  EXPECT_TRUE(j.at("query_ms").contains("p95"));
  EXPECT_GE(j.at("success_rate").get<double>(), 0.6);
  EXPECT_GE(j.at("precision").get<double>(), 0.9);
}

TEST_F(CliLocalize, WithoutDatabaseBuildsItInMemoryAndSelectsScans) {
  ASSERT_NO_FATAL_FAILURE(needOffice());
  const auto r = runCli({"localize", path("office.yaml"), path("query.log"), "-o", path("odd.txt"), "--scans", "odd",
                         "--step", "0.3", "-q"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(r.err.empty()) << r.err;
  EXPECT_EQ(rows(path("odd.txt")).size(), 10u);
}

TEST_F(CliLocalize, SymmetricWorldDeclines) {
  ASSERT_NO_FATAL_FAILURE(needSymmetric());
  const auto r = runCli(
      {"localize", path("sym.yaml"), path("sym.log"), "-o", path("sym.txt"), "--scans", "odd", "--step", "0.3", "-q"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto lines = rows(path("sym.txt"));
  ASSERT_EQ(lines.size(), 100u);
  std::size_t declined = 0;
  for (const auto& f : lines) declined += f[1] == "nan";
  EXPECT_GE(declined, 80u);
}

TEST_F(CliLocalize, DatabaseOfAnotherMapIsRefused) {
  ASSERT_NO_FATAL_FAILURE(needOffice());
  ASSERT_NO_FATAL_FAILURE(needSymmetric());
  auto r = runCli({"localize-index", path("sym.yaml"), "-o", path("sym.db"), "--step", "0.3", "-q"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  r = runCli({"localize", path("office.yaml"), path("query.log"), "--db", path("sym.db"), "-o", path("x.txt")});
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("another map"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("sym.db"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(path("x.txt")));
}

TEST_F(CliLocalize, BadInputIsOneLineAndExitOne) {
  ASSERT_NO_FATAL_FAILURE(needOffice());
  // YAML whose image is missing.
  test::writeFile(path("noimage.yaml"), "image: missing.pgm\nresolution: 0.05\norigin: [0, 0, 0]\n");
  auto r = runCli({"localize-index", path("noimage.yaml"), "-o", path("n.db")});
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("lidar2d: error:"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(path("n.db")));
  r = runCli({"localize", path("noimage.yaml"), path("query.log"), "-o", path("n.txt")});
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_FALSE(fs::exists(path("n.txt")));
  // A map without free space: an all-occupied 10 x 10 PGM.
  std::string pgm = "P5\n10 10\n255\n" + std::string(100, '\0');
  test::writeFile(path("full.pgm"), pgm);
  test::writeFile(path("full.yaml"), "image: full.pgm\nresolution: 0.05\norigin: [0, 0, 0]\n");
  r = runCli({"localize-index", path("full.yaml"), "-o", path("f.db")});
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("free"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("full.yaml"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(path("f.db")));
  // Not a database.
  test::writeFile(path("junk.db"), "hello");
  r = runCli({"localize", path("office.yaml"), path("query.log"), "--db", path("junk.db"), "-o", path("j.txt")});
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("not a lidar2d localization database"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(path("j.txt")));
  // A device as the database: read whole, /dev/zero ran out of memory.
  r = runCli({"localize", path("office.yaml"), path("query.log"), "--db", "/dev/zero", "-o", path("z.txt")});
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("/dev/zero: is a device"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(path("z.txt")));
  // The office map with 50 m cells: a grid of 10^8 positions, refused up front (it ran out of
  // memory; with `resolution: 1e308`, now refused by the YAML check, it looped without end).
  const std::string office_yaml = test::readFile(path("office.yaml"));
  const std::size_t at = office_yaml.find("resolution:");
  ASSERT_NE(at, std::string::npos);
  const std::size_t eol = office_yaml.find('\n', at);
  test::writeFile(path("huge.yaml"), office_yaml.substr(0, at) + "resolution: 50" + office_yaml.substr(eol));
  r = runCli({"localize-index", path("huge.yaml"), "-o", path("h.db")});
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("step: the map spans"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("use a step of at least"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(path("h.db")));
  // A negative weight for the look-alikes' odds.
  r = runCli({"localize", path("office.yaml"), path("query.log"), "--ambiguity-nats", "-1", "-o", path("a.txt")});
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.err.find("--ambiguity-nats"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(path("a.txt")));
}

// A bare image stored with its first row at the lowest y reads, with --image-rows-up, as the map it
// is (the same database, byte for byte, as the map's own YAML). Read without it, the map is the
// room's mirror image: no scan is placed, and the command says why (their mirror images are).
TEST_F(CliLocalize, AMapImageWithItsRowsUpIsReadWithImageRowsUpAndOtherwiseToldMirrored) {
  ASSERT_NO_FATAL_FAILURE(needOpen());
  const std::string rev = path("open-rev.png");
  auto r = runCli({"localize-index", path("open.yaml"), "-o", path("open.db"), "-q"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  r = runCli({"localize-index", rev, "--resolution", open_resolution_, "--origin", open_origin_, "--image-rows-up",
              "-o", path("open-rev.db"), "-q"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(test::readFile(path("open.db")) == test::readFile(path("open-rev.db")));

  r = runCli({"localize", rev, path("openq.log"), "--resolution", open_resolution_, "--origin", open_origin_, "-o",
              path("mirrored.txt"), "--json", path("mirrored.json"), "-q"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  auto j = nlohmann::json::parse(test::readFile(path("mirrored.json")));
  EXPECT_LE(j.at("answered").get<int>(), 4) << j.dump();
  EXPECT_TRUE(j.at("mirror_check").at("mirrored").get<bool>()) << j.dump();
  EXPECT_NE(r.err.find("mirror images of each other"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("--image-rows-up"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("flipped"), std::string::npos) << r.err;

  r = runCli({"localize", rev, path("openq.log"), "--resolution", open_resolution_, "--origin", open_origin_,
              "--image-rows-up", "-o", path("rows-up.txt"), "--json", path("rows-up.json"), "--eval", "-q"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  j = nlohmann::json::parse(test::readFile(path("rows-up.json")));
  EXPECT_GE(j.at("success_rate").get<double>(), 0.8) << j.dump();
  EXPECT_FALSE(j.contains("mirror_check")) << j.dump();
  EXPECT_EQ(r.err.find("mirror"), std::string::npos) << r.err;

  // The option belongs to a bare image: with a YAML (which states map_server's row order) it is a usage error.
  r = runCli({"localize", path("open.yaml"), path("openq.log"), "--image-rows-up", "-o", path("x.txt")});
  EXPECT_EQ(r.exit_code, 2) << r.err;
  EXPECT_NE(r.err.find("--image-rows-up"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(path("x.txt")));
}

// A bare PNG/PGM map (no YAML) with its resolution and origin on the command line reads as the
// YAML stating them would: the same database, byte for byte. The real case: a course's hand-made
// 300 x 300 px map at 0.05 m/px.
TEST(CliLocalizeBareMap, PngWithResolutionAndOriginEqualsItsYaml) {
  LIDAR2D_REQUIRE_DATA("bags/rplidar-flipped/gridmap.png");
  test::TempDir tmp;
  const std::string png = test::dataFile("bags/rplidar-flipped/gridmap.png").string();
  test::writeFile(tmp / "g.yaml", "image: " + png + "\nresolution: 0.05\norigin: [-7.5, -5.5, 0.1]\n");
  auto r = runCli({"localize-index", (tmp / "g.yaml").string(), "-o", (tmp / "yaml.db").string(), "-q"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  r = runCli({"localize-index", png, "--resolution", "0.05", "--origin", "-7.5,-5.5,0.1", "-o", (tmp / "png.db").string(),
              "-q"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const std::string a = test::readFile(tmp / "yaml.db"), b = test::readFile(tmp / "png.db");
  ASSERT_GT(a.size(), 1000u);
  EXPECT_TRUE(a == b) << "the bare image's database differs from its YAML's";
  // Another origin is another map: its database differs (the checksum covers the origin).
  r = runCli({"localize-index", png, "--resolution", "0.05", "-o", (tmp / "png0.db").string(), "-q"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_FALSE(test::readFile(tmp / "png0.db") == a);

  // localize on the bare image, with the top 3 candidates of every scan.
  r = runCli({"simulate", "--map", (tmp / "g.yaml").string(), "--scans", "12", "--seed", "4", "-o",
              (tmp / "sim.log").string()});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  r = runCli({"localize", png, (tmp / "sim.log").string(), "--resolution", "0.05", "--origin", "-7.5,-5.5,0.1", "--db",
              (tmp / "png.db").string(), "--candidates", "3", "--eval", "--json", (tmp / "s.json").string(), "-o",
              (tmp / "loc.txt").string(), "-q"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_GE(nlohmann::json::parse(test::readFile(tmp / "s.json"))["success_rate"].get<double>(), 0.9);
  std::map<std::string, std::vector<std::pair<int, double>>> per_scan;  // t -> (rank, fit)
  std::map<std::string, std::string> best;                                // t -> "x y theta score" of rank 1
  std::istringstream cand(test::readFile(tmp / "loc.txt.candidates"));
  for (std::string line; std::getline(cand, line);) {
    if (line.empty() || line[0] == '#') continue;
    std::istringstream ls(line);
    std::string t, x, y, th, sc, fit;
    int rank = 0;
    ASSERT_TRUE(ls >> t >> rank >> x >> y >> th >> sc >> fit) << line;
    per_scan[t].push_back({rank, std::stod(fit)});  // ranked by fit
    if (rank == 1) best[t] = x + " " + y + " " + th + " " + sc;
  }
  EXPECT_EQ(per_scan.size(), 12u);
  for (const auto& [t, c] : per_scan) {
    ASSERT_LE(c.size(), 3u) << t;
    for (std::size_t k = 0; k < c.size(); ++k) {
      EXPECT_EQ(c[k].first, static_cast<int>(k) + 1) << t;
      if (k > 0) {
        EXPECT_LE(c[k].second, c[k - 1].second) << t;
      }
    }
  }
  // Rank 1 is the pose the main output answers.
  std::istringstream loc(test::readFile(tmp / "loc.txt"));
  std::size_t answered = 0;
  for (std::string line; std::getline(loc, line);) {
    if (line.empty() || line[0] == '#' || line.find("nan") != std::string::npos) continue;
    const std::size_t sp = line.find(' ');
    EXPECT_EQ(best[line.substr(0, sp)], line.substr(sp + 1)) << line;
    ++answered;
  }
  EXPECT_GE(answered, 11u);
}

TEST(CliLocalizeBareMap, BadUseAndBadImagesAreClearErrors) {
  test::TempDir tmp;
  // A tiny valid PGM: 4 x 3 px, free with a wall.
  const std::string pgm = (tmp / "m.pgm").string();
  test::writeFile(pgm, std::string("P5\n4 3\n255\n") + std::string(8, '\xfe') + std::string(4, '\0'));
  test::writeFile(tmp / "m.yaml", "image: m.pgm\nresolution: 0.05\norigin: [0, 0, 0]\n");
  const std::string db = (tmp / "x.db").string();
  auto usage = [&](std::vector<std::string> args, const std::string& says) {
    const auto r = runCli(args);
    EXPECT_EQ(r.exit_code, 2) << says << ": " << r.err;
    EXPECT_NE(r.err.find(says), std::string::npos) << r.err;
    EXPECT_FALSE(fs::exists(db));
  };
  usage({"localize-index", pgm, "-o", db}, "is a bare image: give its cell size, --resolution");
  usage({"localize-index", (tmp / "m.yaml").string(), "--resolution", "0.05", "-o", db}, "states its own");
  usage({"localize-index", pgm, "--resolution", "0", "-o", db}, "--resolution");
  usage({"localize-index", pgm, "--resolution", "nan", "-o", db}, "--resolution");
  usage({"localize-index", pgm, "--resolution", "0.05", "--origin", "1,2", "-o", db}, "expected 3 comma-separated");
  usage({"localize-index", pgm, "--resolution", "0.05", "--origin", "1,inf,0", "-o", db}, "not a finite number");
  usage({"localize", pgm, "x.log", "-o", db}, "is a bare image");
  auto bad = [&](std::vector<std::string> args, std::initializer_list<std::string> says) {
    const auto r = runCli(args);
    EXPECT_EQ(r.exit_code, 1) << r.err;
    EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
    for (const auto& s : says) EXPECT_NE(r.err.find(s), std::string::npos) << r.err;
    EXPECT_FALSE(fs::exists(db));
  };
  bad({"localize-index", pgm, "--resolution", "1000", "-o", db}, {"m.pgm", "resolution", "must be between"});
  bad({"localize-index", pgm, "--resolution", "0.05", "--origin", "1e12,0,0", "-o", db}, {"m.pgm", "origin"});
  // A truncated image: the PGM's header promises more pixels than the file holds.
  const std::string cut = (tmp / "cut.pgm").string();
  test::writeFile(cut, std::string("P5\n40 30\n255\n") + std::string(100, '\xfe'));
  bad({"localize-index", cut, "--resolution", "0.05", "-o", db}, {"cut.pgm"});
  // A PNG cut after its signature.
  const std::string png = (tmp / "cut.png").string();
  test::writeFile(png, std::string("\x89PNG\r\n\x1a\n\0\0\0\x0dIHDR", 16));
  bad({"localize-index", png, "--resolution", "0.05", "-o", db}, {"cut.png"});
}

}  // namespace
}  // namespace lidar2d
