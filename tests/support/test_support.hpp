#pragma once
// Shared test helpers: data location, temporary folders, running the CLI, pose matchers.

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <exception>
#include <filesystem>
#include <initializer_list>
#include <string>

#include "lidar2d/core/error.hpp"
#include "lidar2d/core/se2.hpp"

namespace lidar2d::test {

/// ../shared/data, or $LIDAR2D_DATA_DIR when set.
std::filesystem::path dataDir();
/// Path of a data file; when missing, the calling test should GTEST_SKIP (see REQUIRE_DATA).
std::filesystem::path dataFile(const std::string& relative);
/// Path of a file of the source tree (docs, headers), for tests that check them.
std::filesystem::path sourceFile(const std::string& relative);
/// The lidar2d program built with the tests.
std::string cliPath();
/// The folder of the fixtures the build generates (tools/make-test-bags.py, tests/CMakeLists.txt).
std::filesystem::path fixtureDir();

/// Skips the current test with a message when a data file is missing.
#define LIDAR2D_REQUIRE_DATA(relative)                                                            \
  do {                                                                                            \
    if (!std::filesystem::exists(::lidar2d::test::dataFile(relative)))                            \
      GTEST_SKIP() << "test data " << ::lidar2d::test::dataFile(relative)                         \
                   << " is missing (set LIDAR2D_DATA_DIR to the shared/data folder)";           \
  } while (0)

/// A fresh temporary folder, removed when the object dies.
class TempDir {
 public:
  TempDir();
  ~TempDir();
  TempDir(const TempDir&) = delete;
  TempDir& operator=(const TempDir&) = delete;
  const std::filesystem::path& path() const { return path_; }
  std::filesystem::path operator/(const std::string& name) const { return path_ / name; }

 private:
  std::filesystem::path path_;
};

/// Result of running the lidar2d CLI.
struct CliResult {
  int exit_code = -1;
  std::string out;  ///< stdout
  std::string err;  ///< stderr
};
/// Runs the built lidar2d binary with `args` (shell-quoted here), capturing stdout and stderr.
CliResult runCli(const std::vector<std::string>& args);

/// Writes `content` to `path` (for malformed-input tests).
void writeFile(const std::filesystem::path& path, const std::string& content);
/// The whole content of the file at `path` (empty when it cannot be read).
std::string readFile(const std::filesystem::path& path);
/// Writes gzip-compressed `content` to `path`.
void writeGzip(const std::filesystem::path& path, const std::string& content);

/// gtest predicate: poses agree within tolerances; prints both on failure.
::testing::AssertionResult IsNearPose(const SE2& expected, const SE2& actual, double tol_m, double tol_deg);

/// Runs `f`, expecting a lidar2d::Error of `kind` whose message contains every string of `parts`.
template <typename F>
::testing::AssertionResult throwsError(F&& f, ErrorKind kind, std::initializer_list<std::string> parts) {
  try {
    f();
  } catch (const Error& e) {
    if (e.kind() != kind) return ::testing::AssertionFailure() << "wrong kind, message: " << e.what();
    const std::string what = e.what();
    for (const auto& p : parts)
      if (what.find(p) == std::string::npos)
        return ::testing::AssertionFailure() << "message '" << what << "' lacks '" << p << "'";
    return ::testing::AssertionSuccess();
  } catch (const std::exception& e) {
    return ::testing::AssertionFailure() << "not a lidar2d::Error: " << e.what();
  }
  return ::testing::AssertionFailure() << "no exception";
}

/// Running mean and (population) standard deviation of a sample.
struct Stats {
  double n = 0, sum = 0, sum2 = 0;
  void add(double v) {
    n += 1;
    sum += v;
    sum2 += v * v;
  }
  double mean() const { return sum / n; }
  double stddev() const { return std::sqrt(std::max(0.0, sum2 / n - mean() * mean())); }
};

}  // namespace lidar2d::test
