#include <map>

#include "commands.hpp"

namespace lidar2d::cli {

void addReaderOptions(CLI::App* sub, io::ReaderOptions& options) {
  sub->add_option("--scan-topic", options.scan_topic, "ROS bags: LaserScan topic (default: auto-detect)");
  sub->add_option("--odom-topic", options.odom_topic,
                  "ROS bags: Odometry topic (default: auto-detect; 'none' ignores odometry)");
  sub->add_option("--carmen-laser", options.carmen_laser,
                  "CARMEN logs: laser message to read, e.g. FLASER, RLASER, ROBOTLASER1 (default: first found)");
  const std::map<std::string, io::CarmenPoses> poses{{"auto", io::CarmenPoses::kAuto},
                                                     {"truth", io::CarmenPoses::kTruth},
                                                     {"odometry", io::CarmenPoses::kOdometry}};
  sub->add_option("--carmen-poses", options.carmen_poses,
                  "CARMEN logs: meaning of the laser messages' poses: auto, truth or odometry")
      ->transform(CLI::CheckedTransformer(poses, CLI::ignore_case))
      ->default_str("auto");
}

}  // namespace lidar2d::cli
