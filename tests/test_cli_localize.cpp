// lidar2d localize-index / localize end to end: output format (one line per scan, "t nan nan nan 0"
// when declining), the JSON summary, a database from another map, and bad input (exit 1, one line,
// no output file).

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>

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
  static void TearDownTestSuite() { delete dir_; }
  static std::string path(const std::string& name) { return (*dir_ / name).string(); }
  static std::vector<std::vector<std::string>> rows(const std::string& file) {
    std::ifstream in(file);
    std::vector<std::vector<std::string>> out;
    for (std::string line; std::getline(in, line);) {
      if (line.empty() || line[0] == '#') continue;
      std::istringstream ss(line);
      std::vector<std::string> f;
      for (std::string w; ss >> w;) f.push_back(w);
      out.push_back(f);
    }
    return out;
  }
  static test::TempDir* dir_;
};
test::TempDir* CliLocalize::dir_ = nullptr;

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
}

}  // namespace
}  // namespace lidar2d
