// lidar2d poses LOG --source truth|odometry -o FILE [--format plain|tum]: the poses a log carries, as
// a trajectory file (for `map --poses`, `eval`, or other tools).

#include <fmt/format.h>

#include <iostream>
#include <map>
#include <memory>

#include "commands.hpp"
#include "lidar2d/core/error.hpp"
#include "lidar2d/io/frame_source.hpp"
#include "lidar2d/io/trajectory.hpp"

namespace lidar2d::cli {
namespace {

enum class PoseKind { kTruth, kOdometry };

struct PosesArgs {
  std::string log;
  std::string output;
  PoseKind source = PoseKind::kTruth;
  io::TrajectoryFormat format = io::TrajectoryFormat::kPlain;
  io::ReaderOptions reader;
};

void run(const PosesArgs& a) {
  const CreatedFolders out_folders = prepareOutputFile(a.output);
  auto src = io::openLog(a.log, a.reader);
  Trajectory traj;
  const char* what = a.source == PoseKind::kTruth ? "truth" : "odometry";
  while (auto f = src->next()) {
    const std::optional<SE2>& pose = a.source == PoseKind::kTruth ? f->T_world_robot : f->T_odom_robot;
    if (!pose)
      throw badInput(fmt::format("scan {} (time {:.6f}) has no {} pose", f->index, f->time, what), ErrorLocation(a.log));
    traj.push_back({f->time, *pose});
  }
  if (traj.empty()) throw badInput("log has no scans", ErrorLocation(a.log));
  io::writeTrajectory(a.output, traj, a.format);
  std::cerr << fmt::format("wrote {} {} poses -> {}\n", traj.size(), what, a.output);
}

}  // namespace

void addPosesCommand(CLI::App& app) {
  auto a = std::make_shared<PosesArgs>();
  auto* sub = app.add_subcommand("poses", "Write the truth or odometry poses of a log's scans as a trajectory file");
  sub->add_option("LOG", a->log, "log file (any format lidar2d reads)")->required();
  sub->add_option("-o,--output", a->output, "trajectory file to write")->required();
  addChoice<PoseKind>(sub, "--source", a->source, {{"truth", PoseKind::kTruth}, {"odometry", PoseKind::kOdometry}},
                      "which poses: truth or odometry")
      ->default_str("truth");
  addChoice<io::TrajectoryFormat>(sub, "--format", a->format,
                                  {{"plain", io::TrajectoryFormat::kPlain}, {"tum", io::TrajectoryFormat::kTum}},
                                  "plain (t x y theta) or tum (t tx ty tz qx qy qz qw)")
      ->default_str("plain");
  addReaderOptions(sub, a->reader);
  sub->callback([a] { run(*a); });
}

}  // namespace lidar2d::cli
