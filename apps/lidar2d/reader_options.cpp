#include <fmt/format.h>

#include <charconv>
#include <cmath>
#include <map>
#include <memory>
#include <numbers>
#include <string>
#include <vector>

#include "commands.hpp"

namespace lidar2d::cli {
namespace {

// --ranges R --angles A --poses P: a range table given file by file, instead of LOG (a folder
// holding poses.txt, angles.txt and ranges.txt is simply given as LOG). With --ranges, LOG is no
// longer required, and must not be given. A command with a --poses
// of its own (map: a trajectory) takes it as the table's poses file when --ranges is given.
void addRangeTableOptions(CLI::App* sub, io::ReaderOptions& options) {
  CLI::Option* log = sub->get_option_no_throw("LOG");
  if (!log) return;  // commands without a LOG (eval's EST) take logs by path only
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
  sub->parse_complete_callback([files, ranges, poses, log, &options] {
    if (ranges->count() == 0) return;
    if (log->count() > 0)
      throw CLI::ValidationError("LOG", "give a log or the range table's --ranges, --angles and --poses, not both");
    files->poses = poses->as<std::string>();
    options.range_table = *files;
    // LOG names the table in the command's messages and outputs: the ranges file. (CLI11 writes
    // an option's variable from its results; run_callback does so now, after parsing.)
    log->add_result(files->ranges);
    log->run_callback();
  });
}

}  // namespace

void addReaderOptions(CLI::App* sub, io::ReaderOptions& options) {
  sub->add_option("--scan-topic", options.scan_topic, "ROS bags: LaserScan topic (default: auto-detect)");
  sub->add_option("--odom-topic", options.odom_topic,
                  "ROS bags: Odometry topic (default: auto-detect; 'none' ignores odometry)");
  sub->add_option("--carmen-laser", options.carmen_laser,
                  "CARMEN logs: laser message to read, e.g. FLASER, RLASER, ROBOTLASER1 (default: first found)");
  addChoice<io::CarmenPoses>(
      sub, "--carmen-poses", options.carmen_poses,
      {{"auto", io::CarmenPoses::kAuto}, {"truth", io::CarmenPoses::kTruth}, {"odometry", io::CarmenPoses::kOdometry}},
      "CARMEN logs: meaning of the laser messages' poses: auto, truth or odometry")
      ->default_str("auto");
  sub->add_option_function<std::string>(
         "--laser-mount",
         [&options](const std::string& v) {
           // Three comma-separated finite numbers: x and y [m], theta [deg].
           std::vector<double> xs;
           std::size_t start = 0;
           while (start <= v.size()) {
             const std::size_t end = std::min(v.find(',', start), v.size());
             const std::string field = v.substr(start, end - start);
             double x = 0.0;
             const auto [ptr, ec] = std::from_chars(field.data(), field.data() + field.size(), x);
             if (field.empty() || ec != std::errc() || ptr != field.data() + field.size() || !std::isfinite(x))
               throw CLI::ValidationError("--laser-mount", "'" + field + "' is not a finite number (expected X,Y,THETA_DEG)");
             xs.push_back(x);
             start = end + 1;
           }
           if (xs.size() != 3)
             throw CLI::ValidationError("--laser-mount", "expected 3 comma-separated values X,Y,THETA_DEG, got " +
                                                             std::to_string(xs.size()));
           if (!io::laserMountOffsetOk(xs[0], xs[1]))
             throw CLI::ValidationError("--laser-mount", fmt::format("X and Y must be within +-{:g} m of the robot's centre",
                                                                     io::kMaxLaserMountOffset));
           options.laser_mount = SE2(xs[0], xs[1], xs[2] * std::numbers::pi / 180.0);
         },
         "the laser's pose on the robot, X,Y [m],THETA [deg], replacing the log's (tf, CARMEN offset)")
      ->type_name("X,Y,THETA_DEG");
  addRangeTableOptions(sub, options);
}

}  // namespace lidar2d::cli
