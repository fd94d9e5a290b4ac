// Malformed CARMEN logs: every case throws lidar2d::Error naming the file, the line and (where there
// is one) the field; through the CLI, `lidar2d info` exits 1 with exactly one line on stderr.

#include <gtest/gtest.h>

#include <ostream>

#include <filesystem>
#include <fstream>
#include <random>
#include <string>
#include <vector>

#include "lidar2d/core/error.hpp"
#include "lidar2d/io/frame_source.hpp"
#include "src/io/internal/readers.hpp"
#include "support/test_support.hpp"

namespace lidar2d::test {
namespace {

// A valid FLASER line with n beams of 1.5 m at time t.
std::string flaser(int n, double t = 1.0) {
  std::string s = "FLASER " + std::to_string(n);
  for (int i = 0; i < n; ++i) s += " 1.5";
  return s + " 0 0 0 0 0 0 " + std::to_string(t) + " host " + std::to_string(t) + "\n";
}

// A valid ROBOTLASER1 line with the given field of view and resolution (4 beams).
std::string robotlaser(const std::string& fov, const std::string& res, const std::string& max_range = "20") {
  return "ROBOTLASER1 0 -1.5 " + fov + " " + res + " " + max_range +
         " 0.01 0 4 1 2 3 4 0 0 0 0 0 0 0 0 0 0 0 0 5.5 host 5.5\n";
}

std::string readAllAndFail(const std::string& path) {
  auto src = io::openLog(path);
  while (src->next()) {
  }
  return {};
}

constexpr std::size_t kSomeLine = static_cast<std::size_t>(-1);

struct Case {
  const char* name;
  std::string content;     // written as a file (see `how`)
  enum How { kPlain, kGzip, kTruncatedGzip, kCorruptGzip, kDirectory, kMissing } how = kPlain;
  std::size_t line;        // expected line in what(), 0 = none, kSomeLine = a line (number varies)
  std::string field;       // expected field text in what(), or empty
  std::string message;     // expected message text in what()
  bool cli = false;        // also checked through `lidar2d info`
};
// gtest prints parameters in test listings; a name instead of a byte dump keeps ctest readable.
[[maybe_unused]] void PrintTo(const Case&, std::ostream* os) { *os << "Case"; }


std::string log180() {
  std::string s = "# header\nPARAM robot_frontlaser_offset 0.0\n";
  for (int k = 0; k < 400; ++k) s += flaser(180, k) + "ODOM 0 0 0 0 0 0 " + std::to_string(k) + " h " + std::to_string(k) + "\n";
  return s;
}

std::string randomBytes(std::size_t n, unsigned seed) {
  std::mt19937 rng(seed);
  std::string s(n, '\0');
  for (auto& c : s) c = static_cast<char>(rng() & 0xff);
  return s;
}

std::vector<Case> cases() {
  const std::string ok = flaser(4, 1.0);
  std::vector<Case> c = {
      {"TruncatedGzip", log180(), Case::kTruncatedGzip, kSomeLine, "", "truncated gzip data", true},
      {"CorruptGzip", log180(), Case::kCorruptGzip, kSomeLine, "", "corrupt gzip data (incorrect data check)", true},
      {"FewerRangesThanAnnounced", ok + "FLASER 10 1 2 3 0 0 0 0 0 0 5 host 5\n", Case::kPlain, 2,
       "FLASER num_readings", "announces 10 values but the line has only 12 fields after it (17 needed)", true},
      {"NonNumericRange", ok + "FLASER 20 1 1 1 1 1 1 1 1 1 1 1 1 1 1 1 1 1 abc 1 1 0 0 0 0 0 0 2 h 2\n", Case::kPlain,
       2, "FLASER range 17", "'abc' is not a number", true},
      {"NonNumericPose", "FLASER 2 1 1 0 zero 0 0 0 0 2 h 2\n", Case::kPlain, 1, "FLASER y", "'zero' is not a number",
       false},
      {"NegativeBeamCount", ok + ok + "FLASER -5 1 1 1 0 0 0 0 0 0 3 h 3\n", Case::kPlain, 3, "FLASER num_readings",
       "negative count", true},
      {"HugeBeamCount", "FLASER 1000000000 1 1 1 0 0 0 0 0 0 3 h 3\n", Case::kPlain, 1, "FLASER num_readings",
       "more than the limit", false},
      {"FractionalBeamCount", "FLASER 2.5 1 1 0 0 0 0 0 0 3 h 3\n", Case::kPlain, 1, "FLASER num_readings",
       "not a whole number", false},
      {"ZeroBeams", "FLASER 0 0 0 0 0 0 0 3 h 3\n", Case::kPlain, 1, "FLASER num_readings", "at least one beam", false},
      {"NanPose", ok + "FLASER 2 1 1 nan 0 0 0 0 0 2 h 2\n", Case::kPlain, 2, "FLASER x", "'nan' is not finite", true},
      {"InfRange", "FLASER 3 1 inf 1 0 0 0 0 0 0 2 h 2\n", Case::kPlain, 1, "FLASER range 1", "'inf' is not finite",
       true},
      {"NegativeRange", "FLASER 3 1 1 -0.5 0 0 0 0 0 0 2 h 2\n", Case::kPlain, 1, "FLASER range 2",
       "'-0.5' is negative", false},
      {"NanTimestamp", ok + "FLASER 2 1 1 0 0 0 0 0 0 NaN h 2\n", Case::kPlain, 2, "FLASER ipc_timestamp",
       "'NaN' is not finite", false},
      {"RobotLaserBadFov", robotlaser("0", "1.0"), Case::kPlain, 1, "ROBOTLASER1 field_of_view", "not in (0, 2 pi]",
       true},
      {"RobotLaserHugeFov", robotlaser("100", "1.0"), Case::kPlain, 1, "ROBOTLASER1 field_of_view", "not in (0, 2 pi]",
       false},
      {"RobotLaserZeroResolution", robotlaser("3", "0"), Case::kPlain, 1, "ROBOTLASER1 angular_resolution",
       "must be non-zero", false},
      {"RobotLaserResolutionTooCoarse", robotlaser("3", "2"), Case::kPlain, 1, "ROBOTLASER1 angular_resolution",
       "more than the field of view", false},
      {"RobotLaserBadMaxRange", robotlaser("3", "1", "-1"), Case::kPlain, 1, "ROBOTLASER1 maximum_range",
       "must be positive", false},
      {"OnlyComments", "# a comment\n# another\n\nNEFF 3\n", Case::kPlain, 4, "", "no laser scans found", true},
      {"EmptyFile", "", Case::kPlain, 0, "", "empty", false},
      {"BinaryGarbage", randomBytes(4000, 1), Case::kPlain, 1, "", "not a text log", true},
      {"GzipOfGarbage", randomBytes(4000, 2), Case::kGzip, 1, "", "not a text log", false},
      {"Directory", "", Case::kDirectory, 0, "", "directory", false},
      {"Missing", "", Case::kMissing, 0, "", "no such file", false},
      // A log compressed by a tool other than gzip is named by its format, not read as a text line.
      {"Bzip2Compressed", "BZh91AY&SY" + randomBytes(200, 3), Case::kPlain, 0, "",
       "bzip2-compressed file: decompress it first", false},
      {"XzCompressed",
       std::string("\xfd"
                   "7zXZ\0",
                   6) +
           randomBytes(200, 4),
       Case::kPlain, 0, "", "xz-compressed file: decompress it first", true},
      {"Lz4Compressed", std::string("\x04\x22\x4d\x18", 4) + randomBytes(200, 5), Case::kPlain, 0, "",
       "lz4-compressed file: decompress it first", false},
      {"ZipArchive", std::string("PK\x03\x04", 4) + randomBytes(200, 6), Case::kPlain, 0, "",
       "zip-compressed file: decompress it first", false},
      {"LineCutAtEof", ok + ok + "FLASER 4 1.5 1.5 1.5 1.5 0 0 0 0", Case::kPlain, 3, "FLASER num_readings",
       "announces 4 values but the line has only 8 fields after it", true},
      {"FlaserMissingTimestamp", ok + "FLASER 4 1.5 1.5 1.5 1.5 0 0 0 0 0 0\n", Case::kPlain, 2, "FLASER num_readings",
       "only 10 fields after it (11 needed)", false},
      {"OdomMissingFields", ok + "ODOM 1 2 0.5 0 0\n", Case::kPlain, 2, "ODOM accel", "missing field", true},
      {"OdomNonNumeric", ok + "ODOM 1 2 x 0 0 0 1 h 1\n", Case::kPlain, 2, "ODOM theta", "'x' is not a number", false},
      {"TrueposNanTime", ok + "TRUEPOS 1 2 0 1 2 0 nan h 1\n", Case::kPlain, 2, "TRUEPOS ipc_timestamp",
       "is not finite", false},
      {"ParamBadResolution", "PARAM laser_front_laser_resolution fast 0 h 0\n" + ok, Case::kPlain, 1,
       "PARAM laser_front_laser_resolution", "'fast' is not a finite number", false},
      {"RemissionCountTooLarge", "ROBOTLASER1 0 -1.5 3 1 20 0.01 0 4 1 2 3 4 99 0 0 0 0 0 0 0 0 0 0 0 5.5 h 5.5\n",
       Case::kPlain, 1, "ROBOTLASER1 num_remissions", "announces 99 values", false},
      {"RawLaserMissingTimestamp", "RAWLASER1 0 -1.5 3 1 20 0.01 0 4 1 2 3 4 0\n", Case::kPlain, 1,
       "RAWLASER1 num_remissions", "announces 0 values but the line has only 0 fields", false},
  };
  return c;
}

class BadCarmen : public ::testing::TestWithParam<Case> {
 protected:
  std::string prepare(const Case& c) {
    const auto path = dir_ / (std::string(c.name) + (c.how == Case::kPlain ? ".log" : ".log.gz"));
    switch (c.how) {
      case Case::kPlain:
        writeFile(path, c.content);
        break;
      case Case::kGzip:
        writeGzip(path, c.content);
        break;
      case Case::kTruncatedGzip:
      case Case::kCorruptGzip: {
        writeGzip(path, c.content);
        std::ifstream in(path, std::ios::binary);
        std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
        in.close();
        if (c.how == Case::kTruncatedGzip) {
          bytes.resize(bytes.size() * 2 / 3);
        } else {
          // Damage the CRC-32 in the gzip trailer: all data inflates, only the check fails, so a
          // reader that ignored zlib's final status would stop silently "successfully".
          for (std::size_t i = bytes.size() - 8; i < bytes.size() - 4; ++i) bytes[i] = static_cast<char>(~bytes[i]);
        }
        writeFile(path, bytes);
        break;
      }
      case Case::kDirectory:
        std::filesystem::create_directory(path);
        break;
      case Case::kMissing:
        break;
    }
    return path.string();
  }
  TempDir dir_;
};

TEST_P(BadCarmen, LibraryThrowsErrorNamingFileLineField) {
  const Case& c = GetParam();
  const std::string path = prepare(c);
  for (bool direct : {false, true}) {
    if (direct && (c.how == Case::kDirectory || c.how == Case::kMissing)) {
      // openCarmen itself must also refuse these (openLog's format detection normally does).
      EXPECT_THROW(io::internal::openCarmen(path, {}), Error);
      continue;
    }
    try {
      if (direct) {
        auto src = io::internal::openCarmen(path, {});
        while (src->next()) {
        }
      } else {
        readAllAndFail(path);
      }
      ADD_FAILURE() << c.name << ": no error thrown";
    } catch (const Error& e) {
      const std::string what = e.what();
      SCOPED_TRACE(what);
      EXPECT_EQ(what.rfind(path, 0), 0u) << "what() must start with the file";
      if (c.line == kSomeLine) {
        EXPECT_GT(e.where().line, 0u);
        EXPECT_NE(what.find(path + ":" + std::to_string(e.where().line) + ":"), std::string::npos);
      } else if (c.line) {
        EXPECT_NE(what.find(path + ":" + std::to_string(c.line) + ":"), std::string::npos);
        EXPECT_EQ(e.where().line, c.line);
      } else {
        EXPECT_EQ(e.where().line, 0u);
      }
      if (!c.field.empty()) {
        EXPECT_NE(what.find(c.field), std::string::npos) << "field " << c.field;
      }
      if (!c.field.empty()) {
        EXPECT_EQ(e.where().field, c.field);
      }
      EXPECT_NE(what.find(c.message), std::string::npos) << "message " << c.message;
      if (c.how != Case::kMissing) {
        EXPECT_NE(e.kind(), ErrorKind::kInvalidArgument);
      }
    }
  }
}

TEST_P(BadCarmen, CliPrintsOneLineAndExits1) {
  const Case& c = GetParam();
  const std::string path = prepare(c);
  const CliResult r = runCli({"info", path});
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_TRUE(r.out.empty()) << r.out;
  ASSERT_FALSE(r.err.empty());
  EXPECT_EQ(r.err.find('\n'), r.err.size() - 1) << "exactly one line: " << r.err;
  EXPECT_NE(r.err.find(path), std::string::npos) << r.err;
  if (c.line == kSomeLine) {
    EXPECT_NE(r.err.find(path + ":"), std::string::npos) << r.err;
  } else if (c.line) {
    EXPECT_NE(r.err.find(path + ":" + std::to_string(c.line) + ":"), std::string::npos) << r.err;
  }
  EXPECT_NE(r.err.find(c.message), std::string::npos) << r.err;
}

INSTANTIATE_TEST_SUITE_P(Cases, BadCarmen, ::testing::ValuesIn(cases()),
                         [](const auto& info) { return std::string(info.param.name); });

TEST(BadCarmenTruncation, ErrorIsAtTheLineWhereTheDataStops) {
  // The complete lines before the cut are read; the error names the first line that is incomplete.
  // Lines: 1 comment, 1 PARAM, then FLASER (line 2k+3) and ODOM (line 2k+4) for scan k.
  TempDir dir;
  const auto path = dir / "cut.log.gz";
  std::string log = "# header\nPARAM robot_frontlaser_offset 0.0\n";
  for (int k = 0; k < 3000; ++k) {
    std::string ranges;
    for (int i = 0; i < 180; ++i) ranges.append(" ").append(std::to_string((k * 7 + i * 13) % 997 / 100.0));
    log.append("FLASER 180").append(ranges).append(" 0 0 0 0 0 0 ").append(std::to_string(k));
    log.append(" h 0\nODOM 0 0 0 0 0 0 ").append(std::to_string(k)).append(" h 0\n");
  }
  writeGzip(path, log);
  std::ifstream in(path, std::ios::binary);
  std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  in.close();
  bytes.resize(bytes.size() * 2 / 3);
  writeFile(path, bytes);
  std::size_t frames = 0;
  try {
    auto src = io::openLog(path.string());
    while (src->next()) ++frames;
    FAIL() << "no error";
  } catch (const Error& e) {
    EXPECT_GT(frames, 1000u);
    EXPECT_LT(frames, 2500u);
    // The scan after the last emitted one may wait in the look-ahead buffer, so the cut is 1 or 2
    // lines after its FLASER line (2 * (frames + 1) + 3 - 1).
    EXPECT_GE(e.where().line, 2 * frames + 4);
    EXPECT_LE(e.where().line, 2 * frames + 5);
    EXPECT_NE(std::string(e.what()).find("truncated gzip data"), std::string::npos);
  }
}

}  // namespace
}  // namespace lidar2d::test
