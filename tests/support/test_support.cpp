#include "support/test_support.hpp"

#include <sys/wait.h>
#include <unistd.h>
#include <zlib.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <numbers>
#include <random>
#include <sstream>

namespace lidar2d::test {

std::filesystem::path dataDir() {
  if (const char* env = std::getenv("LIDAR2D_DATA_DIR"); env && *env) return env;
  return LIDAR2D_DEFAULT_DATA_DIR;
}

std::filesystem::path dataFile(const std::string& relative) { return dataDir() / relative; }

std::filesystem::path sourceFile(const std::string& relative) {
  return std::filesystem::path(LIDAR2D_SOURCE_DIR) / relative;
}

std::string cliPath() { return LIDAR2D_CLI_PATH; }

std::filesystem::path fixtureDir() { return LIDAR2D_FIXTURE_DIR; }

TempDir::TempDir() {
  std::string templ = (std::filesystem::temp_directory_path() / "lidar2d-test-XXXXXX").string();
  if (!::mkdtemp(templ.data())) throw std::runtime_error("mkdtemp failed");
  path_ = templ;
}

TempDir::~TempDir() {
  std::error_code ec;
  std::filesystem::remove_all(path_, ec);
}

namespace {

std::string shellQuote(const std::string& s) {
  std::string out = "'";
  for (char c : s) {
    if (c == '\'')
      out += "'\\''";
    else
      out += c;
  }
  return out + "'";
}

std::string slurp(const std::filesystem::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

}  // namespace

CliResult runCli(const std::vector<std::string>& args) {
  TempDir tmp;
  std::string cmd = shellQuote(LIDAR2D_CLI_PATH);
  for (const auto& a : args) cmd.append(" ").append(shellQuote(a));
  // append() rather than "literal" + std::string: GCC 12 raises a false -Wrestrict on the latter.
  cmd.append(" </dev/null >").append(shellQuote((tmp / "out").string()));
  cmd.append(" 2>").append(shellQuote((tmp / "err").string()));
  const int status = std::system(cmd.c_str());
  CliResult r;
  r.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : 128 + (WIFSIGNALED(status) ? WTERMSIG(status) : 0);
  r.out = slurp(tmp / "out");
  r.err = slurp(tmp / "err");
  return r;
}

void writeFile(const std::filesystem::path& path, const std::string& content) {
  std::ofstream out(path, std::ios::binary);
  out << content;
}

std::string readFile(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

void writeGzip(const std::filesystem::path& path, const std::string& content) {
  gzFile f = gzopen(path.string().c_str(), "wb");
  if (!f) throw std::runtime_error("gzopen failed");
  gzwrite(f, content.data(), static_cast<unsigned>(content.size()));
  gzclose(f);
}

::testing::AssertionResult IsNearPose(const SE2& expected, const SE2& actual, double tol_m, double tol_deg) {
  const double dt = std::hypot(expected.x() - actual.x(), expected.y() - actual.y());
  const double dr = std::abs(angleDiff(expected.theta(), actual.theta())) * 180.0 / std::numbers::pi;
  if (dt <= tol_m && dr <= tol_deg) return ::testing::AssertionSuccess();
  return ::testing::AssertionFailure() << "expected (" << expected.x() << ", " << expected.y() << ", "
                                       << expected.theta() << ") got (" << actual.x() << ", " << actual.y() << ", "
                                       << actual.theta() << "): off by " << dt << " m (tol " << tol_m << ") and " << dr
                                       << " deg (tol " << tol_deg << ")";
}

}  // namespace lidar2d::test
