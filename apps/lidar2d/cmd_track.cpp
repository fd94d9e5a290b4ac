// lidar2d track MAP LOG -o FILE [--db DB] [--json FILE] [--eval] [--no-odometry]: localization in a
// known map without an initial pose (localization::Tracker). MAP is a map_server YAML, a bare image,
// or a SLAM state (state.l2d), whose node scans are rendered into an occupancy grid at their
// optimised poses (the mapping code of `slam`'s map.pgm). Output: one line per scan,
// `t x y theta status score`, status `global` (placed by global localization), `tracking` (matched
// from the odometry or constant-velocity prior, checked against the map) or `lost` (pose `nan`).
// --json writes a summary: share of each status, time to the first fix, relocalizations, timings,
// and with --eval the accuracy against the log's truth.

#include <fmt/format.h>

#include <chrono>
#include <cmath>
#include <fstream>
#include <iostream>
#include <memory>
#include <nlohmann/json.hpp>
#include <numbers>
#include <optional>
#include <string>
#include <vector>

#include "commands.hpp"
#include "lidar2d/core/error.hpp"
#include "lidar2d/eval/metrics.hpp"
#include "lidar2d/io/atomic_file.hpp"
#include "lidar2d/io/localization_db.hpp"
#include "lidar2d/io/map_file.hpp"
#include "lidar2d/localization/mirror_check.hpp"
#include "lidar2d/localization/tracker.hpp"
#include "lidar2d/mapping/export.hpp"
#include "lidar2d/mapping/occupancy_map.hpp"
#include "lidar2d/slam/state_file.hpp"
#include "map_input.hpp"
#include "progress.hpp"

namespace lidar2d::cli {
namespace {

using Clock = std::chrono::steady_clock;
constexpr double kDeg = std::numbers::pi / 180.0;

struct TrackArgs {
  std::string map;
  BareMapOptions bare;
  std::string log;
  std::string db;
  std::string output;
  std::string json;
  bool eval = false;
  bool no_odometry = false;
  bool quiet = false;
  localization::TrackerOptions options;
  io::ReaderOptions reader;
};

nlohmann::json timing(const std::vector<double>& ms) {
  if (ms.empty()) return nullptr;
  return {{"count", ms.size()},
          {"median", eval::percentile(ms, 0.5)},
          {"p99", eval::percentile(ms, 0.99)},
          {"max", eval::percentile(ms, 1.0)}};
}

/// Whether the file at `path` starts like a SLAM state file (otherwise it is read as a map).
bool isStateFile(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::string head(slam::kStateMagic.size(), '\0');
  return in.read(head.data(), static_cast<std::streamsize>(head.size())) && head == slam::kStateMagic;
}

/// The map of MAP: a state.l2d's node scans inserted at their optimised poses into a log-odds grid
/// of `--resolution` (default 0.05 m; no --origin), or the map_server YAML or bare image.
OccupancyImage readTrackMap(const TrackArgs& a) {
  if (!isStateFile(a.map)) return readMapChecked(a.map, a.bare).map;
  if (a.bare.origin)
    throw CLI::ValidationError(a.bare.origin_flag, "applies to a bare image MAP, not to a SLAM state");
  if (a.bare.rows_up)
    throw CLI::ValidationError(a.bare.rows_up_flag, "applies to a bare image MAP, not to a SLAM state");
  const slam::State state = slam::readStateFile(a.map);
  mapping::MapOptions mo;
  mo.resolution_m = a.bare.resolution.value_or(0.05);
  if (!(mo.resolution_m > 0.0) || mo.resolution_m > 10.0)
    throw badInput("must be in (0, 10] m", ErrorLocation("command line", 0, a.bare.resolution_flag));
  mo.insert.max_range_m = state.options.max_range_m;
  const auto map = mapping::makeMap(mapping::MapModel::kLogOdds, mo);
  slam::insertNodeScans(state, *map);
  return mapping::toOccupancyImage(*map);
}

void runTrack(const TrackArgs& a) {
  const CreatedFolders out_folders = prepareOutputFile(a.output);
  std::optional<CreatedFolders> json_folders;
  if (!a.json.empty()) json_folders.emplace(prepareOutputFile(a.json));
  const auto t0 = Clock::now();
  const OccupancyImage map = readTrackMap(a);
  std::optional<localization::Database> db;
  if (!a.db.empty()) db = io::readLocalizationDatabase(a.db);
  std::unique_ptr<localization::Tracker> tracker;
  try {
    tracker = std::make_unique<localization::Tracker>(map, std::move(db), a.options);
  } catch (const Error& e) {
    throw Error(e.kind(), e.message(), ErrorLocation(a.db.empty() ? a.map : a.db, 0, e.where().field));
  }
  const double setup_s = std::chrono::duration<double>(Clock::now() - t0).count();

  auto source = io::openLog(a.log, a.reader);
  io::AtomicFile out(a.output);
  out.stream() << "# lidar2d track: t x y theta status score (status global|tracking|lost; nan pose when lost)\n";
  std::size_t scans = 0, counts[3] = {0, 0, 0}, relocalizations = 0;
  std::size_t within = 0, tracking_within = 0, wrong_tracking = 0, wrong_global = 0;
  std::size_t beyond_map = 0, beyond_map_within = 0, odometry_frozen = 0;
  std::optional<double> first_time, first_fix_time, previous_time;
  // Scans before the first fix; and whether the log's time advanced at every scan up to it (a
  // log whose timestamps repeat or go backwards gives no meaningful time to the first fix).
  std::optional<std::size_t> scans_to_first_fix;
  bool time_advances = true;
  std::vector<double> track_ms, global_ms, fix_ms, scan_ms;
  localization::MirrorCheck mirror_check;
  RateProgress progress(a.quiet, "tracking", "scans", source->sizeHint());
  while (auto f = source->next()) {
    progress.update(f->index);
    if (a.no_odometry) f->T_odom_robot.reset();
    if (a.eval && !f->T_world_robot)
      throw badInput(fmt::format("scan {} (time {:.6f}) has no ground-truth pose; --eval needs a log with truth",
                                 f->index, f->time),
                     ErrorLocation(a.log));
    const localization::TrackResult r = tracker->add(*f);
    ++scans;
    ++counts[static_cast<int>(r.status)];
    if (!first_time) first_time = f->time;
    if (!scans_to_first_fix && previous_time && !(f->time > *previous_time)) time_advances = false;
    previous_time = f->time;
    if (!first_fix_time && r.status != localization::TrackStatus::kLost) {
      first_fix_time = f->time;
      scans_to_first_fix = scans - 1;
    }
    relocalizations += r.relocalized ? 1 : 0;
    beyond_map += r.beyond_map ? 1 : 0;
    odometry_frozen += r.odometry_frozen ? 1 : 0;
    if (r.status == localization::TrackStatus::kTracking) track_ms.push_back(r.track_ms);
    if (r.global_ms > 0) global_ms.push_back(r.global_ms);
    if (r.status == localization::TrackStatus::kGlobal) fix_ms.push_back(r.global_ms);
    scan_ms.push_back(r.track_ms + r.global_ms);
    if (r.status == localization::TrackStatus::kLost) {
      mirror_check.add(f->scan, f->T_robot_laser);
      out.stream() << fmt::format("{:.9f} nan nan nan lost 0\n", f->time);
    } else {
      const SE2& T = r.T_world_robot;
      out.stream() << fmt::format("{:.9f} {:.6f} {:.6f} {:.6f} {} {:.4f}\n", f->time, T.x(), T.y(), T.theta(),
                                  localization::toString(r.status), r.score);
    }
    if (a.eval && r.status != localization::TrackStatus::kLost) {
      const SE2 e = f->T_world_robot->inverse() * r.T_world_robot;
      const bool ok = e.translation().norm() <= 0.1 && std::abs(e.theta()) <= 2.0 * kDeg;
      const bool wrong = e.translation().norm() > 0.5 || std::abs(e.theta()) > 10.0 * kDeg;
      within += ok;
      const bool tracking = r.status == localization::TrackStatus::kTracking;
      tracking_within += ok && tracking;
      beyond_map_within += ok && r.beyond_map;
      wrong_tracking += wrong && tracking;
      wrong_global += wrong && !tracking;
    }
  }
  progress.clear();
  if (scans == 0) throw badInput("the log has no scan to track", ErrorLocation(a.log));
  out.commit();
  const std::vector<std::string> log_warnings = warnAboutLog(a.log, *source);
  // A log of which almost nothing is placed: are the scans and the map mirror images of each other?
  const nlohmann::json mirror_check_json =
      reportMirrorCheck(mirror_check.runIfFewPlaced(tracker->localizer(), scans), a.map, counts[2], scans);

  const auto share = [&](std::size_t n) { return static_cast<double>(n) / static_cast<double>(scans); };
  nlohmann::json j;
  j["map"] = a.map;
  j["log"] = a.log;
  j["database"] = a.db.empty() ? nlohmann::json("built in memory") : nlohmann::json(a.db);
  j["setup_s"] = setup_s;
  j["scans"] = scans;
  j["log_warnings"] = log_warnings;
  j["status"] = {{"global", share(counts[0])}, {"tracking", share(counts[1])}, {"lost", share(counts[2])}};
  j["status_counts"] = {{"global", counts[0]}, {"tracking", counts[1]}, {"lost", counts[2]}};
  j["time_to_first_fix_s"] =
      first_fix_time && time_advances ? nlohmann::json(*first_fix_time - *first_time) : nlohmann::json(nullptr);
  j["scans_to_first_fix"] = scans_to_first_fix ? nlohmann::json(*scans_to_first_fix) : nlohmann::json(nullptr);
  if (first_fix_time && !time_advances)
    std::cerr << fmt::format(
        "lidar2d: warning: {}: the log's timestamps repeat or go backwards before the first fix; the summary gives "
        "no time to it (time_to_first_fix_s null), only the {} scans before it (scans_to_first_fix)\n",
        a.log, *scans_to_first_fix);
  j["relocalizations"] = relocalizations;
  j["odometry_frozen_scans"] = odometry_frozen;
  j["odometry_scale"] = {{"factor", tracker->odometryScale()}, {"evidence_m", tracker->odometryScaleEvidenceM()}};
  if (!mirror_check_json.is_null()) j["mirror_check"] = mirror_check_json;
  j["tracking_beyond_map"] = {{"scans", beyond_map}, {"share", share(beyond_map)}};
  j["tracked_scan_ms"] = timing(track_ms);
  j["global_fix_ms"] = timing(fix_ms);
  j["global_query_ms"] = timing(global_ms);
  j["scan_ms"] = timing(scan_ms);
  j["total_s"] = std::chrono::duration<double>(Clock::now() - t0).count();
  if (a.eval) {
    j["eval"] = {{"tracking_within_share", share(tracking_within)},
                 {"beyond_map_within_share", share(beyond_map_within)},
                 {"within_share", share(within)},
                 {"wrong_while_tracking", wrong_tracking},
                 {"wrong_global", wrong_global},
                 {"definition",
                  "within: 0.1 m and 2 deg of the truth (shares of all scans); wrong: more than 0.5 m or 10 deg off"}};
  }
  if (!a.json.empty()) io::writeFileAtomically(a.json, j.dump(2) + "\n");
  if (!a.quiet) {
    std::cerr << fmt::format(
        "tracked {} scans: {:.1f}% tracking ({:.1f}% beyond the map), {:.1f}% global, {:.1f}% lost; {} relocalizations",
        scans, 100 * share(counts[1]), 100 * share(beyond_map), 100 * share(counts[0]), 100 * share(counts[2]),
        relocalizations);
    if (!track_ms.empty()) std::cerr << fmt::format("; median {:.2f} ms per tracked scan", eval::percentile(track_ms, 0.5));
    if (a.eval)
      std::cerr << fmt::format("; {:.1f}% tracking within 10 cm / 2 deg, {} wrong while tracking",
                               100 * share(tracking_within), wrong_tracking);
    std::cerr << fmt::format(" -> {}\n", a.output);
  }
}

}  // namespace

void addTrackCommand(CLI::App& app) {
  auto a = std::make_shared<TrackArgs>();
  auto* sub = app.add_subcommand(
      "track",
      "Localization in a known map without an initial pose: global localization, then tracking from odometry, "
      "recovering by itself; writes 't x y theta status score' per scan (status global|tracking|lost)");
  sub->add_option("MAP", a->map,
                  "map: a SLAM state (state.l2d, from 'lidar2d slam'), a map_server YAML, or a bare PGM/PNG image with "
                  "--resolution")
      ->required();
  addBareMapOptions(sub, a->bare, "MAP");
  sub->get_option(a->bare.resolution_flag)
      ->description("MAP as a bare PGM/PNG image (no YAML): its cell size [m] (required then; a YAML states its own); "
                    "MAP as a SLAM state: the cell size of the grid its scans are drawn into (default 0.05)");
  sub->add_option("LOG", a->log, "log file (any format lidar2d reads)")->required();
  sub->add_option("-o,--output", a->output, "output file, one line per scan")->required();
  sub->add_option("--db", a->db, "database from 'lidar2d localize-index' (default: built in memory)");
  sub->add_option("--json", a->json, "write a JSON summary (status shares, first fix, timings; accuracy with --eval)");
  sub->add_flag("--eval", a->eval,
                "compare with the log's truth: share within 10 cm / 2 deg, poses more than 0.5 m / 10 deg off");
  sub->add_flag("--no-odometry", a->no_odometry, "ignore the log's odometry (constant-velocity prior)");
  sub->add_option("--min-score", a->options.min_track_score,
                  "a tracked scan explaining less than this fraction of its points fails")
      ->capture_default_str();
  sub->add_option("--correction-score-slope", a->options.correction_score_slope,
                  "with odometry, a tracked match must explain min-score + this x its correction from the prior "
                  "(a share of 0.5 m / 15 deg)")
      ->capture_default_str();
  sub->add_option("--slide-score-margin", a->options.slide_score_margin,
                  "without odometry, a tracked match fails when matched again from 0.5 or 1 m along its weakest "
                  "direction it settles elsewhere scoring within this of it (0: off)")
      ->check(CLI::Range(0.0, 1.0))
      ->capture_default_str();
  sub->add_option("--prior-score-margin", a->options.prior_score_margin,
                  "with odometry, a tracked match moved over 0.2 m from the prior gives way to the prior's position "
                  "(with the match's heading) when that scores within this of it (0: off)")
      ->check(CLI::Range(0.0, 1.0))
      ->capture_default_str();
  sub->add_option("--max-degenerate-path", a->options.max_degenerate_path_m,
                  "with odometry, degenerate scans (a corridor) keep the odometry's position along it; after this "
                  "much path over such scans in a row [m] they are reported lost (0: off, the map match places them)")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  sub->add_option("--min-global-score", a->options.min_global_score,
                  "a global fix scoring below this is not taken (the scan stays lost)")
      ->capture_default_str();
  sub->add_option("--confirm-fixes", a->options.confirm_fixes,
                  "global answers in a row, agreeing with the odometry between them, needed for a fix")
      ->capture_default_str();
  sub->add_option("--confirm-fixes-against-odometry", a->options.confirm_fixes_against_odometry,
                  "... for an answer away from where the odometry since the last placed scan puts the robot "
                  "(no sure fix then), and for every answer without odometry")
      ->capture_default_str();
  sub->add_option("--sure-fix-score", a->options.sure_fix_score,
                  "a global answer scoring at least this is a fix at once (above 1: never)")
      ->capture_default_str();
  sub->add_option("--max-lost", a->options.max_lost_scans,
                  "failed scans in a row after which the prior is dropped (global localization only)")
      ->capture_default_str();
  sub->add_option("--max-speed", a->options.max_speed_m_per_s,
                  "without odometry, the fastest the robot may have driven since its last placed scan: a global "
                  "answer farther than that from the prior waits for agreeing answers even when its score is sure "
                  "[m/s]")
      ->capture_default_str();
  sub->add_option("--recent-scans", a->options.recent_scans,
                  "with odometry, where the map explains too little of a scan, it is matched against this many "
                  "last placed scans too and tracked when both together explain it (0: off)")
      ->capture_default_str();
  sub->add_option("--max-beyond-map", a->options.max_beyond_map_m,
                  "odometry path since the map alone last explained a scan beyond which the recent scans no longer "
                  "track one [m]")
      ->capture_default_str();
  sub->add_flag_callback(
      "--no-odometry-scale", [a] { a->options.learn_odometry_scale = false; },
      "with odometry, take its distances as read (default: scaled by the metres the map matches measure per metre "
      "of it on 0.5 m chords between scans the map pins, once 5 m of them are measured)");
  sub->add_flag("-q,--quiet", a->quiet, "no summary on stderr");
  addReaderOptions(sub, a->reader);
  sub->callback([a] { runTrack(*a); });
}

}  // namespace lidar2d::cli
