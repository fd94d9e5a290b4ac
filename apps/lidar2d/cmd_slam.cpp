// lidar2d slam LOG -o DIR [--resume STATE]: full 2D SLAM; writes DIR/trajectory.txt,
// DIR/map.{pgm,yaml,png}, DIR/graph.txt, DIR/state.l2d, DIR/summary.json and DIR/report.html. With
// --resume, LOG is a new session of the saved map: the earlier sessions' trajectories go to
// DIR/trajectory_session<k>.txt, and the map and state hold every session.

#include <fmt/format.h>

#include <algorithm>
#include <chrono>
#include <filesystem>
#include <functional>
#include <iostream>
#include <map>
#include <memory>
#include <nlohmann/json.hpp>
#include <optional>

#include "commands.hpp"
#include "lidar2d/core/error.hpp"
#include "lidar2d/eval/metrics.hpp"
#include "lidar2d/io/atomic_file.hpp"
#include "lidar2d/io/prefetch.hpp"
#include "lidar2d/io/trajectory.hpp"
#include "lidar2d/mapping/export.hpp"
#include "lidar2d/mapping/map_builder.hpp"
#include "lidar2d/mapping/occupancy_map.hpp"
#include "lidar2d/slam/slam.hpp"
#include "lidar2d/slam/state_file.hpp"
#include "map_output.hpp"
#include "progress.hpp"
#include "slam_config.hpp"
#include "slam_report.hpp"

namespace lidar2d::cli {
namespace {

/// The frames of a log within `--from`/`--to` (seconds after its first scan's time, by file order):
/// the others are skipped, in the SLAM pass and in the map's second reading alike.
class TimeWindow {
 public:
  TimeWindow(std::optional<double> from_s, std::optional<double> to_s) : from_(from_s), to_(to_s) {}
  bool active() const { return from_ || to_; }
  /// The next frame of `next` within the window (the first frame of the log sets its start).
  template <class Next>
  auto pull(Next&& next) {
    while (true) {
      auto f = next();
      if (!f) return f;
      if (!started_) {
        t0_ = f->time;
        started_ = true;
      }
      const double t = f->time - t0_;
      if (from_ && t < *from_) continue;
      if (to_ && t >= *to_) continue;
      return f;
    }
  }

 private:
  std::optional<double> from_, to_;
  bool started_ = false;
  double t0_ = 0.0;
};

using Json = nlohmann::ordered_json;
using Clock = std::chrono::steady_clock;

struct SlamArgs {
  std::string log;
  std::string dir;
  std::string config;
  std::string resume;
  std::optional<double> from_s, to_s;  // the time window, relative to the log's first scan
  bool no_odometry = false;
  bool laser_frame = false;
  bool quiet = false;
  bool dump_config = false;
  bool markdown = false;
  mapping::MapModel model = mapping::MapModel::kLogOdds;
  double resolution = 0.05;
  io::ReaderOptions reader;
};

double secondsSince(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

/// SLAM's progress line: a bar with percentage when the log's size is known, a running count
/// otherwise (CARMEN text logs), with the nodes and loop closures so far and the time.
class SlamProgress {
 public:
  SlamProgress(bool quiet, std::optional<std::size_t> total) : line_(quiet), total_(total) {}
  /// `slam`'s counters as its back end last published them (reading them does not wait for it).
  void update(std::size_t done, const slam::Slam& slam, bool force = false) {
    line_.update(
        [&] {
          const slam::SlamStats s = slam.statsSoFar();
          return fmt::format("slam {}{} scans, {} nodes, {} loop closures, {:.1f} s ",
                             total_ && *total_ > 0 ? progressBar(done, *total_) + " " : "", done, s.nodes,
                             s.loop_accepted, secondsSince(start_));
        },
        force);
  }
  /// Keeps the last line on screen.
  void done() { line_.finish(); }

 private:
  ProgressLine line_;
  std::optional<std::size_t> total_;
  Clock::time_point start_ = Clock::now();
};

void writeGraph(const std::string& path, const slam::Slam& slam) {
  io::AtomicFile f(path);
  auto& o = f.stream();
  o << "# lidar2d slam pose graph\n"
       "# NODE id scan_index time x y theta submap degenerate(0/1) degenerate_dir_rad\n"
       "# EDGE kind from to dx dy dtheta accepted(0/1) searched(0/1) score explained reason\n";
  const auto& nodes = slam.nodes();
  for (std::size_t i = 0; i < nodes.size(); ++i) {
    const auto& n = nodes[i];
    o << fmt::format("NODE {} {} {:.6f} {:.6f} {:.6f} {:.6f} {} {} {:.6f}\n", i, n.scan, n.time, n.T_world_robot.x(),
                     n.T_world_robot.y(), n.T_world_robot.theta(), n.submap, n.degenerate ? 1 : 0, n.degenerate_dir_rad);
  }
  for (const auto& c : slam.constraints())
    o << fmt::format("EDGE {} {} {} {:.6f} {:.6f} {:.6f} {} {} {:.3f} {:.3f} {}\n", c.descriptor ? "loop_descriptor" : slam::toString(c.kind), c.from, c.to,
                     c.T_from_to.x(), c.T_from_to.y(), c.T_from_to.theta(), c.accepted ? 1 : 0, c.searched ? 1 : 0,
                     c.score, c.explained, c.reason.empty() ? "-" : c.reason);
  f.commit();
}

void run(const SlamArgs& a) {
  const auto t_start = Clock::now();
  // A resumed map goes on with the options it was made with: another --config would make its
  // sessions disagree (submap sizes, thresholds), so the two are refused together.
  if (!a.resume.empty() && !a.config.empty())
    throw CLI::ValidationError("--config", "cannot be combined with --resume: the saved map's options are used");
  std::optional<slam::State> saved;
  double state_load_s = 0.0;
  if (!a.resume.empty()) {
    const auto t_load = Clock::now();
    saved = slam::readStateFile(a.resume);
    state_load_s = secondsSince(t_load);
  }
  slam::SlamOptions options = saved ? saved->options : readSlamConfig(a.config);
  // --no-odometry is about the new log: it applies to a resumed run too.
  if (a.no_odometry) options.use_odometry = false;
  if (a.dump_config) {
    std::cout << (a.markdown ? slamOptionsMarkdown(options) : slamConfigYaml(options));
    return;
  }
  if (a.from_s && a.to_s && !(*a.from_s < *a.to_s))
    throw CLI::ValidationError("--from/--to", "--from must be before --to");
  if (!(a.resolution > 0.0) || a.resolution > 10.0)
    throw badInput("must be in (0, 10] m", ErrorLocation("command line", 0, "--resolution"));
  namespace fs = std::filesystem;
  std::error_code ec;
  if (fs::exists(a.dir, ec) && !fs::is_directory(a.dir, ec))
    throw ioError("exists and is not a directory", ErrorLocation(a.dir, 0, "-o"));
  const CreatedFolders out_folders = prepareOutputDir(a.dir);

  // Frames are processed as the reader thread (prefetch) parses them, so parsing overlaps with
  // SLAM on the other core. Of each frame only its laser mounting is kept (for --pose-frame laser):
  // the final map reads the log again.
  std::vector<SE2> T_robot_laser;
  auto source = io::prefetch(io::openLog(a.log, a.reader));
  const std::size_t earlier_sessions = saved ? saved->sessions.size() : 0;
  std::unique_ptr<slam::Slam> slam_ptr;
  if (saved) {
    saved->options = options;
    slam_ptr = std::make_unique<slam::Slam>(std::move(*saved), a.log);
    saved.reset();
  } else {
    slam_ptr = std::make_unique<slam::Slam>(options, a.log);
  }
  slam::Slam& slam = *slam_ptr;
  SlamProgress bar(a.quiet, source->sizeHint());
  const auto t_slam = Clock::now();
  TimeWindow window(a.from_s, a.to_s);
  while (auto f = window.pull([&] { return source->next(); })) {
    T_robot_laser.push_back(f->T_robot_laser);
    slam.add(*f);
    bar.update(T_robot_laser.size(), slam);
  }
  const std::vector<std::string> log_warnings = source->notes().warnings;
  source.reset();
  const std::size_t num_scans = T_robot_laser.size();
  if (num_scans == 0)
    throw badInput(window.active() ? "log has no scans in the --from/--to window" : "log has no scans",
                   ErrorLocation(a.log));
  slam.finish();
  bar.update(num_scans, slam, true);
  bar.done();
  printLogWarnings(a.log, log_warnings);  // once the progress line is done: it would overwrite them
  const double slam_seconds = secondsSince(t_slam);
  const auto all_scans = slam.trajectory();
  const slam::State state = slam.state();
  // This log's scans: the newest recording's (State::sessions.back()).
  const std::vector<slam::ScanEstimate> trajectory(all_scans.end() - static_cast<std::ptrdiff_t>(num_scans),
                                                   all_scans.end());

  // Map from every scan of the log, read again, at its optimised pose (the pose with the scan's
  // index and exactly its time).
  const auto t_map = Clock::now();
  mapping::MapOptions mo;
  mo.resolution_m = a.resolution;
  mo.insert.max_range_m = options.max_range_m;
  auto map = mapping::makeMap(a.model, mo);
  // The earlier sessions' logs are not read again: their node scans (kept in the state) stand for them.
  slam::insertNodeScans(state, *map, earlier_sessions);
  {
    Trajectory optimised;
    optimised.reserve(trajectory.size());
    for (const auto& e : trajectory) optimised.push_back({e.time, e.T_world_robot});
    mapping::MapBuilder builder(*map, mapping::FramePoses::fromTrajectory(std::move(optimised), 0.0, a.log),
                                {.source_name = a.log});
    auto again = io::openLog(a.log, a.reader);
    TimeWindow window_again(a.from_s, a.to_s);
    if (builder.insert([&] { return window_again.pull([&] { return again->next(); }); }) != num_scans)
      throw ioError("the log changed while it was being read", ErrorLocation(a.log));
  }
  const OccupancyImage image = mapping::toOccupancyImage(*map);
  const double map_seconds = secondsSince(t_map);

  fs::create_directories(a.dir, ec);
  if (ec) throw ioError(fmt::format("cannot create the output folder: {}", ec.message()), ErrorLocation(a.dir));
  // Every output is staged and they appear together: a failed write leaves the folder as it was.
  io::OutputSet outputs(a.dir);
  Trajectory traj;
  traj.reserve(trajectory.size());
  for (std::size_t i = 0; i < trajectory.size(); ++i) {
    const auto& e = trajectory[i];
    traj.push_back({e.time, a.laser_frame ? e.T_world_robot * T_robot_laser[i] : e.T_world_robot});
  }
  io::writeTrajectory(outputs.stage("trajectory.txt"), traj);
  for (std::size_t k = 0; k < earlier_sessions; ++k) {
    const std::size_t end = state.sessions[k + 1].first_scan;
    Trajectory earlier;
    for (std::size_t i = state.sessions[k].first_scan; i < end; ++i) {
      const auto& e = all_scans[i];
      earlier.push_back({e.time, a.laser_frame ? e.T_world_robot * state.nodes[e.node].T_robot_laser : e.T_world_robot});
    }
    io::writeTrajectory(outputs.stage(fmt::format("trajectory_session{}.txt", k + 1)), earlier);
  }
  writeMapFiles(outputs, "map", image);
  writeGraph(outputs.stage("graph.txt"), slam);
  const auto t_save = Clock::now();
  const std::string state_bytes = slam::encodeState(state);
  io::writeFileAtomically(outputs.stage("state.l2d"), state_bytes);
  const double state_save_s = secondsSince(t_save);

  const slam::SlamStats& s = slam.stats();
  std::vector<double> per_scan;
  per_scan.reserve(trajectory.size());
  for (const auto& e : trajectory) per_scan.push_back(e.seconds * 1e3);
  Json j;
  j["log"] = a.log;
  Json sessions = Json::array();
  for (std::size_t k = 0; k < state.sessions.size(); ++k) {
    const std::size_t end = k + 1 < state.sessions.size() ? state.sessions[k + 1].first_scan : state.scans.size();
    sessions.push_back({{"log", state.sessions[k].name},
                        {"scans", end - state.sessions[k].first_scan},
                        {"trajectory", k + 1 == state.sessions.size() ? std::string("trajectory.txt")
                                                                       : fmt::format("trajectory_session{}.txt", k + 1)}});
  }
  j["sessions"] = sessions;
  if (!a.resume.empty()) j["resumed_from"] = a.resume;
  j["scans"] = s.scans;
  j["nodes"] = s.nodes;
  j["submaps"] = s.submaps;
  j["matched"] = s.matched;
  j["unmatched"] = s.unmatched;
  j["correlative_fallbacks"] = s.correlative_fallbacks;
  j["prior_overridden"] = s.prior_overridden;
  j["prior_kept"] = s.prior_kept;
  j["fragments"] = s.fragments;
  j["relocalizations"] = s.relocalizations;
  j["odometry_wins"] = s.odometry_wins;
  j["odometry_scale"] = s.odometry_scale;
  j["odometry_scale_evidence_m"] = s.odometry_scale_evidence_m;
  j["degenerate_scans"] = s.degenerate;
  j["moving_points"] = s.moving_points;
  j["scans_with_moving_points"] = s.moving_scans;
  j["loop_searches"] = s.loop_searches;
  j["loop_closures_accepted"] = s.loop_accepted;
  j["loop_closures_rejected"] = s.loop_rejected;
  j["loop_closures_downweighted"] = s.loop_downweighted;
  j["loop_cycles"] = s.loop_cycles;
  j["cycle_odometry_deg"] = s.cycle_odometry_deg;
  j["cycle_front_end_deg"] = s.cycle_front_end_deg;
  j["cycle_odometry_m"] = s.cycle_odometry_m;
  j["cycle_front_end_m"] = s.cycle_front_end_m;
  j["odometry_weighted_by_cycles"] = s.odometry_weighted_by_cycles;
  j["descriptor_queries"] = s.descriptor_queries;
  j["descriptor_hypotheses"] = s.descriptor_hypotheses;
  j["descriptor_closures_accepted"] = s.descriptor_accepted;
  j["descriptor_seconds"] = s.descriptor_seconds;
  j["optimizations"] = s.optimizations;
  j["optimization_s"] = s.optimization_seconds;
  j["slam_s"] = slam_seconds;
  j["map_s"] = map_seconds;
  j["state_bytes"] = state_bytes.size();
  j["state_save_s"] = state_save_s;
  if (!a.resume.empty()) j["state_load_s"] = state_load_s;
  j["ms_per_scan_mean"] = slam_seconds * 1e3 / static_cast<double>(num_scans);
  j["ms_per_scan_median"] = eval::percentile(per_scan, 0.5);
  j["ms_per_scan_p95"] = eval::percentile(per_scan, 0.95);
  j["ms_per_scan_p99"] = eval::percentile(per_scan, 0.99);
  j["ms_per_scan_max"] = eval::percentile(per_scan, 1.0);
  j["used_odometry"] = options.use_odometry;
  j["pose_frame"] = a.laser_frame ? "laser" : "robot";
  j["options"] = slamOptionsJson(options);
  Json ev = Json::array();
  for (const auto& e : slam.events()) ev.push_back({{"scan", e.frame_index}, {"time", e.time}, {"what", e.what}});
  j["events"] = ev;
  j["log_warnings"] = log_warnings;

  ReportInput report{a.log, slam, all_scans, image, j};
  {
    io::AtomicFile f(outputs.stage("report.html"));
    f.stream() << slamReportHtml(report);
    f.commit();
  }
  j["total_s"] = secondsSince(t_start);
  {
    io::AtomicFile f(outputs.stage("summary.json"));
    f.stream() << j.dump(2) << "\n";
    f.commit();
  }
  const std::vector<std::string> written = outputs.commit();
  if (!a.quiet) {
    std::cerr << fmt::format(
        "slam: {} scans, {} nodes, {} loop closures ({} rejected), {} events; {:.2f} s ({:.2f} ms per scan), total "
        "{:.2f} s\n",
        s.scans, s.nodes, s.loop_accepted, s.loop_rejected, slam.events().size(), slam_seconds,
        slam_seconds * 1e3 / static_cast<double>(num_scans), secondsSince(t_start));
    for (const auto& w : written) std::cout << w << "\n";
  }
}

}  // namespace

void addSlamCommand(CLI::App& app) {
  auto a = std::make_shared<SlamArgs>();
  auto* sub = app.add_subcommand("slam", "Full 2D SLAM: trajectory of every scan, map, pose graph and an HTML report");
  auto* log = sub->add_option("LOG", a->log, "log file (any format lidar2d reads)")->required();
  auto* dir = sub->add_option("-o,--output", a->dir, "output folder (created if missing)")->required();
  sub->add_option("--config", a->config, "YAML file of SLAM options overriding the defaults (--dump-config lists them)");
  sub->add_option("--resume", a->resume,
                  "continue the map of a state.l2d (written by an earlier 'slam') with LOG as a new session, placed by "
                  "global localization; its options are used (no --config)");
  // Triggered as soon as it is parsed, before CLI11 checks that LOG and -o are given.
  auto* dump = sub->add_flag_callback(
                      "--dump-config",
                      [a, log, dir] {
                        a->dump_config = true;
                        log->required(false);
                        dir->required(false);
                      },
                      "print every SLAM option (with --config and --no-odometry applied) as a YAML config file, "
                      "with its unit, range and meaning, and exit")
                   ->trigger_on_parse();
  sub->add_flag("--markdown", a->markdown, "with --dump-config: print the options as the Markdown table of docs/slam.md")
      ->needs(dump);
  sub->add_flag("--no-odometry", a->no_odometry, "ignore the log's odometry (scan matching only)");
  sub->add_option("--from", a->from_s,
                  "map only the scans logged at least this long after the log's first scan [s] (e.g. the second half "
                  "of a log, to --resume the first)")
      ->check(CLI::NonNegativeNumber);
  sub->add_option("--to", a->to_s, "map only the scans logged less than this long after the log's first scan [s]")
      ->check(CLI::PositiveNumber);
  addChoice<bool>(sub, "--pose-frame", a->laser_frame, {{"robot", false}, {"laser", true}},
                  "frame of the poses in trajectory.txt: robot (base_link) or laser (the robot pose times the laser "
                  "mounting; what the Radish relation files measure)")
      ->default_str("robot");
  addChoice<mapping::MapModel>(sub, "--map-model", a->model,
                               {{"logodds", mapping::MapModel::kLogOdds},
                                {"count", mapping::MapModel::kCount},
                                {"tsdf", mapping::MapModel::kTsdf}},
                               "model of the output map: logodds, count or tsdf")
      ->default_str("logodds");
  sub->add_option("--resolution", a->resolution, "cell size of the output map [m]")->default_val(0.05);
  sub->add_flag("-q,--quiet", a->quiet, "no progress bar and no summary");
  addReaderOptions(sub, a->reader);
  sub->callback([a] { run(*a); });
}

}  // namespace lidar2d::cli
