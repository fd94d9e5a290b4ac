#include <fmt/format.h>

#include <charconv>
#include <cmath>
#include <functional>
#include <iostream>
#include <map>
#include <memory>
#include <numbers>
#include <optional>
#include <string>
#include <vector>

#include "commands.hpp"

namespace lidar2d::cli {
namespace {

// --ranges R --angles A --poses P: a range table given file by file, instead of LOG (a folder
// holding poses.txt, angles.txt and ranges.txt is simply given as LOG). With --ranges, LOG is no
// longer required, and must not be given. A command with a --poses
// of its own (map: a trajectory) takes it as the table's poses file when --ranges is given.
// Returns what to run once the command line is parsed (nothing for commands without a LOG).
std::function<void()> addRangeTableOptions(CLI::App* sub, io::ReaderOptions& options) {
  CLI::Option* log = sub->get_option_no_throw("LOG");
  if (!log) return {};  // commands without a LOG (eval's EST) take logs by path only
  auto files = std::make_shared<io::RangeTableFiles>();
  // Triggered as soon as it is parsed, before CLI11 checks that LOG is given (as slam's
  // --dump-config does).
  auto* ranges = sub->add_option_function<std::string>(
                        "--ranges",
                        [files, log](const std::string& v) {
                          files->ranges = v;
                          log->required(false);
                        },
                        "range table instead of LOG: one line of ranges [m] per scan (with --angles, --poses)")
                     ->trigger_on_parse();
  auto* angles = sub->add_option("--angles", files->angles, "range table: one line of beam angles [rad]");
  CLI::Option* poses = sub->get_option_no_throw("--poses");
  if (!poses) poses = sub->add_option("--poses", files->poses, "range table: one pose x,y,theta [m, m, rad] per scan");
  ranges->needs(angles)->needs(poses);
  angles->needs(ranges);
  return [files, ranges, poses, log, &options] {
    if (ranges->count() == 0) return;
    if (log->count() > 0)
      throw CLI::ValidationError("LOG", "give a log or the range table's --ranges, --angles and --poses, not both");
    files->poses = poses->as<std::string>();
    options.range_table = *files;
    // LOG names the table in the command's messages and outputs: the ranges file. (CLI11 writes
    // an option's variable from its results; run_callback does so now, after parsing.)
    log->add_result(files->ranges);
    log->run_callback();
  };
}

}  // namespace

namespace {

constexpr double kDeg = std::numbers::pi / 180.0;

// The value of --laser-mount: three comma-separated finite numbers X,Y [m],THETA [deg], then an
// optional word 'flipped' (upside down) or 'upright'; or six numbers X,Y,Z [m],ROLL,PITCH,YAW [deg].
LaserMount parseLaserMount(const std::string& v) {
  constexpr const char* kExpected = "expected X,Y,THETA_DEG[,flipped] or X,Y,Z,ROLL_DEG,PITCH_DEG,YAW_DEG";
  std::vector<std::string> fields;
  for (std::size_t start = 0; start <= v.size();) {
    const std::size_t end = std::min(v.find(',', start), v.size());
    fields.push_back(v.substr(start, end - start));
    start = end + 1;
  }
  std::optional<bool> flipped;
  if (fields.size() == 4 && (fields[3] == "flipped" || fields[3] == "upright")) {
    flipped = fields[3] == "flipped";
    fields.pop_back();
  }
  std::vector<double> xs;
  for (const std::string& field : fields) {
    double x = 0.0;
    const auto [ptr, ec] = std::from_chars(field.data(), field.data() + field.size(), x);
    if (field.empty() || ec != std::errc() || ptr != field.data() + field.size() || !std::isfinite(x))
      throw CLI::ValidationError("--laser-mount", fmt::format("'{}' is not a finite number ({})", field, kExpected));
    xs.push_back(x);
  }
  if (xs.size() != 3 && !(xs.size() == 6 && !flipped))
    throw CLI::ValidationError("--laser-mount", fmt::format("{}, got {} values", kExpected, fields.size()));
  if (!io::laserMountOffsetOk(xs[0], xs[1]) || (xs.size() == 6 && !io::laserMountOffsetOk(xs[2], 0.0)))
    throw CLI::ValidationError("--laser-mount", fmt::format("X, Y and Z must be within +-{:g} m of the robot's centre",
                                                            io::kMaxLaserMountOffset));
  if (xs.size() == 3) return LaserMount::planar(SE2(xs[0], xs[1], xs[2] * kDeg), flipped.value_or(false));
  return LaserMount::fromRollPitchYaw(xs[0], xs[1], xs[2], xs[3] * kDeg, xs[4] * kDeg, xs[5] * kDeg);
}

}  // namespace

namespace {

// The lasers named on the command line (--scan-topic, --carmen-laser: repeated or comma lists) and
// the mountings (--laser-mount, repeated), resolved into ReaderOptions once parsing is complete:
// one laser -> scan_topic / carmen_laser and laser_mount; two or more -> lasers and laser_mounts.
struct LaserChoice {
  std::vector<std::string> topics, carmen;
  std::vector<LaserMount> mounts;

  void resolve(io::ReaderOptions& options) const {
    if (topics.size() >= 2 && carmen.size() >= 2)
      throw CLI::ValidationError("--scan-topic/--carmen-laser",
                                 "several lasers are listed for both ROS bags and CARMEN logs; list them for one");
    const std::vector<std::string>& lasers = topics.size() >= 2 ? topics : carmen;
    if (lasers.size() >= 2) {
      if (!mounts.empty() && mounts.size() != lasers.size())
        throw CLI::ValidationError("--laser-mount", fmt::format("{} given for {} lasers: give one per laser, in the "
                                                                "lasers' order, or none to take them from the log",
                                                                mounts.size(), lasers.size()));
      options.lasers = lasers;
      options.laser_mounts = mounts;
      return;
    }
    if (!topics.empty()) options.scan_topic = topics.front();
    if (!carmen.empty()) options.carmen_laser = carmen.front();
    if (mounts.size() > 1)
      throw CLI::ValidationError("--laser-mount",
                                 fmt::format("{} given for one laser (several lasers: list them with --scan-topic "
                                             "or --carmen-laser)",
                                             mounts.size()));
    if (!mounts.empty()) options.laser_mount = mounts.front();
  }
};

}  // namespace

void addReaderOptions(CLI::App* sub, io::ReaderOptions& options) {
  auto lasers = std::make_shared<LaserChoice>();
  sub->add_option("--scan-topic", lasers->topics,
                  "ROS bags: LaserScan topic (default: the one with the most messages); two or more (a comma list, "
                  "or the option repeated) are merged into one scan per frame, the first one's scans setting the "
                  "times (docs/file-formats.md, two or more lasers)")
      ->delimiter(',')
      ->allow_extra_args(false)
      ->type_name("TOPIC[,TOPIC...]");
  sub->add_option("--odom-topic", options.odom_topic,
                  "ROS bags: Odometry topic (default: auto-detect; 'none' ignores odometry)")
      ->type_name("TOPIC|none");
  sub->add_option("--carmen-laser", lasers->carmen,
                  "CARMEN logs: laser message to read (default: the first found); FLASER,RLASER merges the front and "
                  "rear lasers")
      ->delimiter(',')
      ->allow_extra_args(false)
      ->type_name("FLASER|RLASER|ROBOTLASER1|ROBOTLASER2|RAWLASER1..4[,...]");
  sub->add_option("--laser-sync-tolerance", options.laser_sync_tolerance_s,
                  "two or more lasers: largest time difference between the first laser's scan and another's merged "
                  "into it [s]; scans without such a partner are left out")
      ->check(positiveNumber())
      ->default_str("0.05");
  addChoice<io::CarmenPoses>(
      sub, "--carmen-poses", options.carmen_poses,
      {{"auto", io::CarmenPoses::kAuto}, {"truth", io::CarmenPoses::kTruth}, {"odometry", io::CarmenPoses::kOdometry}},
      "CARMEN logs: meaning of the laser messages' poses: auto, truth or odometry")
      ->default_str("auto");
  sub->add_option_function<std::vector<std::string>>(
         "--laser-mount",
         [lasers](const std::vector<std::string>& v) {
           lasers->mounts.clear();
           for (const std::string& m : v) lasers->mounts.push_back(parseLaserMount(m));
         },
         "the laser's mounting on the robot, replacing the log's (tf, CARMEN offset): X,Y [m],THETA [deg], "
         "optionally followed by ',flipped' for a laser mounted upside down (its scans mirrored), or "
         "X,Y,Z [m],ROLL,PITCH,YAW [deg] (docs/file-formats.md, laser mounting); with several lasers, repeated once "
         "per laser in their order (default: from the log)")
      ->allow_extra_args(false)
      ->type_name("X,Y,THETA_DEG[,flipped]|X,Y,Z,R,P,Y");
  sub->add_option_function<double>(
         "--laser-range-max", [&options](double r) { options.laser_range_max = r; },
         "the laser's range max [m], replacing the log's: readings at or beyond it are no return, those below it "
         "returns (default: the log's; a CARMEN log whose first scans read beyond it, under a no-return code, is "
         "read to that code, and every command that reads the log says so)")
      ->check(positiveNumber())
      ->type_name("METRES");
  sub->add_option("--max-tilt", options.max_laser_tilt_deg,
                  "a scan plane tilted from the robot's plane by at most this is taken as level [deg]")
      ->check(CLI::Range(0.0, 45.0))
      ->default_str("2");
  sub->add_flag("--allow-tilted", options.allow_tilted_laser,
                "read a laser tilted by more than --max-tilt: its beams are projected onto the floor plane, each "
                "range shortened by the tilt (default: such a log is refused)");
  const std::function<void()> range_table = addRangeTableOptions(sub, options);
  sub->parse_complete_callback([range_table, lasers, &options] {
    lasers->resolve(options);
    if (range_table) range_table();
  });
}

void printLogWarnings(const std::string& log, const std::vector<std::string>& warnings) {
  for (const std::string& w : warnings) std::cerr << fmt::format("lidar2d: warning: {}: {}\n", log, w);
}

std::vector<std::string> warnAboutLog(const std::string& log, const io::FrameSource& source) {
  std::vector<std::string> warnings = source.notes().warnings;
  printLogWarnings(log, warnings);
  return warnings;
}

}  // namespace lidar2d::cli
