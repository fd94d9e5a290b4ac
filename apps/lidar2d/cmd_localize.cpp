// lidar2d localize MAP.yaml LOG [--db DB] -o FILE [--json FILE] [--eval] [--scans all|even|odd]:
// the global pose of every scan of LOG in the map, each scan on its own (no odometry, no earlier
// answer). Output: one line per scan, `t x y theta score` (the robot's pose in the map's world frame
// [s, m, m, rad] and the fraction of the scan's points on obstacles), `t nan nan nan 0` when the
// localizer declines. --json writes a summary with timings (and, with --eval, the success rate
// against the log's truth; with odometry in the log, how consistent consecutive answers are with it).
//
// lidar2d localize-index MAP.yaml -o DB [--step 0.2] [--beams N] [--fov DEG] [--max-range R]:
// builds the descriptor database of the map and writes it (io/localization_db.hpp).

#include <fmt/format.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <iostream>
#include <map>
#include <memory>
#include <nlohmann/json.hpp>
#include <numbers>
#include <numeric>
#include <optional>
#include <string>
#include <vector>

#include "commands.hpp"
#include "lidar2d/core/error.hpp"
#include "lidar2d/eval/localization_score.hpp"
#include "lidar2d/eval/metrics.hpp"
#include "lidar2d/io/atomic_file.hpp"
#include "lidar2d/io/localization_db.hpp"
#include "lidar2d/io/map_file.hpp"
#include "lidar2d/localization/localizer.hpp"
#include "lidar2d/localization/mirror_check.hpp"
#include "map_input.hpp"
#include "progress.hpp"

namespace lidar2d::cli {
namespace {

using Clock = std::chrono::steady_clock;
constexpr double kDeg = std::numbers::pi / 180.0;

double seconds(Clock::time_point a) { return std::chrono::duration<double>(Clock::now() - a).count(); }

struct DbArgs {
  std::string map;
  BareMapOptions bare;
  std::string output;
  localization::DatabaseOptions options;
  double fov_deg = 360.0;
  bool quiet = false;
};

// Builds the database of `map`, with its progress on a terminal unless `quiet` (a large map's
// positions take minutes); errors name `map_path`.
localization::Database buildDatabase(const OccupancyImage& map, const localization::DatabaseOptions& o, bool quiet,
                                     const std::string& map_path) {
  RateProgress line(quiet, "indexing", "positions", std::nullopt);
  auto report = [](std::size_t done, std::size_t total, void* user) {
    auto* p = static_cast<RateProgress*>(user);
    p->setTotal(total);
    p->update(done, done == total);
  };
  std::optional<localization::Database> db;
  try {
    db = localization::Database::build(map, o, 0, line.enabled() ? +report : nullptr, &line);
  } catch (const Error& e) {
    throw Error(e.kind(), e.message(), ErrorLocation(map_path, 0, e.where().field));
  }
  line.clear();
  // Below half of the free space indexed, a good share of the scans taken in the map has no
  // virtual scan near it (thin passages, free space next to unknown areas of a map from other tools).
  constexpr double kLowCoverage = 0.5;
  if (db->coverage() < kLowCoverage)
    std::cerr << fmt::format(
        "lidar2d: warning: {}: the localization database indexes only {:.0f}% of the map's free space ({} positions "
        "keep {} m from obstacles and unknown cells); scans elsewhere may be declined (try a smaller --clearance)\n",
        map_path, 100.0 * db->coverage(), db->positions().size(), o.clearance_m);
  return std::move(*db);
}

void runIndex(DbArgs& a) {
  const CreatedFolders out_folders = prepareOutputFile(a.output);
  const auto t0 = Clock::now();
  a.options.fov_rad = a.fov_deg * kDeg;
  const io::MapFile map = readMapChecked(a.map, a.bare);
  const localization::Database db = buildDatabase(map.map, a.options, a.quiet, a.map);
  io::writeLocalizationDatabase(a.output, db);
  if (!a.quiet)
    std::cerr << fmt::format(
        "indexed {} positions ({:.0f}% of the free space), {} lines, {} line pairs ({:.1f} MB in memory) in {:.2f} s "
        "-> {}\n",
        db.positions().size(), 100.0 * db.coverage(), db.lines().size(), db.numPairs(), db.memoryBytes() / 1e6,
        seconds(t0), a.output);
}

enum class Scans { kAll, kEven, kOdd };

struct LocArgs {
  std::string map;
  BareMapOptions bare;
  std::size_t candidates = 0;
  std::string log;
  std::string db;
  std::string output;
  std::string json;
  bool eval = false;
  bool quiet = false;
  Scans scans = Scans::kAll;
  localization::LocalizerOptions options;
  localization::DatabaseOptions db_options;
  double success_m = 0.3;
  double success_deg = 5.0;
  io::ReaderOptions reader;
};

void runLocalize(const LocArgs& a) {
  const CreatedFolders out_folders = prepareOutputFile(a.output);
  std::optional<CreatedFolders> json_folders;
  if (!a.json.empty()) json_folders.emplace(prepareOutputFile(a.json));
  const auto t0 = Clock::now();
  const io::MapFile map = readMapChecked(a.map, a.bare);
  std::optional<localization::Database> db;
  double db_s = 0;
  const auto tdb = Clock::now();
  if (!a.db.empty()) {
    db = io::readLocalizationDatabase(a.db);
  } else {
    db = buildDatabase(map.map, a.db_options, a.quiet, a.map);
  }
  db_s = seconds(tdb);
  std::unique_ptr<localization::Localizer> loc;
  try {
    loc = std::make_unique<localization::Localizer>(map.map, std::move(*db), a.options);
  } catch (const Error& e) {
    throw Error(e.kind(), e.message(), ErrorLocation(a.db.empty() ? a.map : a.db, 0, e.where().field));
  }
  auto source = io::openLog(a.log, a.reader);
  io::AtomicFile out(a.output);
  out.stream() << "# lidar2d localize: t x y theta score (nan nan nan 0 = declined)\n";
  std::unique_ptr<io::AtomicFile> cand_out;
  if (a.candidates > 0) {
    cand_out = std::make_unique<io::AtomicFile>(a.output + ".candidates");
    cand_out->stream() << fmt::format(
        "# lidar2d localize --candidates {}: t rank x y theta score fit, the best distinct verified poses of each "
        "scan (rank 1 = best, ranked by fit), whatever their score\n",
        a.candidates);
  }

  std::vector<double> times_ms;
  std::map<std::string, std::size_t> reasons;
  eval::LocalizationTally tally;
  localization::MirrorCheck mirror_check;
  tally.tolerance = {a.success_m, a.success_deg * kDeg};
  // Progress on a terminal (a long log takes minutes at tens of milliseconds per scan).
  RateProgress progress(a.quiet, "localizing", "scans", source->sizeHint());
  while (auto f = source->next()) {
    progress.update(f->index);
    if ((a.scans == Scans::kEven && f->index % 2 != 0) || (a.scans == Scans::kOdd && f->index % 2 != 1)) continue;
    const localization::LocalizationResult r = loc->localize(f->scan, f->T_robot_laser);
    times_ms.push_back(r.total_ms);
    if (cand_out)
      for (std::size_t k = 0; k < r.candidates.size() && k < a.candidates; ++k) {
        const SE2& T = r.candidates[k].T_world_robot;
        cand_out->stream() << fmt::format("{:.9f} {} {:.6f} {:.6f} {:.6f} {:.4f} {:.4f}\n", f->time, k + 1, T.x(),
                                          T.y(), T.theta(), r.candidates[k].score, r.candidates[k].fit);
      }
    if (r.declined) {
      ++reasons[r.reason];
      mirror_check.add(f->scan, f->T_robot_laser);
      out.stream() << fmt::format("{:.9f} nan nan nan 0\n", f->time);
    } else {
      const SE2& T = r.T_world_robot;
      out.stream() << fmt::format("{:.9f} {:.6f} {:.6f} {:.6f} {:.4f}\n", f->time, T.x(), T.y(), T.theta(), r.score);
    }
    if (a.eval && !f->T_world_robot)
      throw badInput(fmt::format("scan {} (time {:.6f}) has no ground-truth pose; --eval needs a log with truth",
                                 f->index, f->time),
                     ErrorLocation(a.log));
    tally.add(r.declined ? std::nullopt : std::optional<SE2>(r.T_world_robot),
              a.eval ? f->T_world_robot : std::nullopt, f->T_odom_robot);
  }
  progress.clear();
  const std::size_t scans = tally.scans;
  if (scans == 0) throw badInput("the log has no scan to localize", ErrorLocation(a.log));
  out.commit();
  const std::vector<std::string> log_warnings = warnAboutLog(a.log, *source);
  if (cand_out) cand_out->commit();
  // A log of which almost nothing is placed: are the scans and the map mirror images of each other?
  const nlohmann::json mirror_check_json =
      reportMirrorCheck(mirror_check.runIfFewPlaced(*loc, scans), a.map, tally.declined, scans);
  const double total_s = seconds(t0);
  nlohmann::json j;
  j["map"] = a.map;
  j["log"] = a.log;
  j["database"] = a.db.empty() ? nlohmann::json("built in memory") : nlohmann::json(a.db);
  j["database_s"] = db_s;
  if (!std::isnan(loc->database().coverage())) j["database_coverage"] = loc->database().coverage();
  j["database_positions"] = loc->database().positions().size();
  j["database_pairs"] = loc->database().numPairs();
  j["database_mb"] = loc->database().memoryBytes() / 1e6;
  j["scans"] = scans;
  j["log_warnings"] = log_warnings;
  j["answered"] = tally.answered;
  j["declined"] = tally.declined;
  j["decline_rate"] = static_cast<double>(tally.declined) / static_cast<double>(scans);
  j["decline_reasons"] = reasons;
  if (!mirror_check_json.is_null()) j["mirror_check"] = mirror_check_json;
  j["query_ms"] = {{"median", eval::percentile(times_ms, 0.5)},
                   {"p95", eval::percentile(times_ms, 0.95)},
                   {"max", eval::percentile(times_ms, 1.0)},
                   {"mean", std::accumulate(times_ms.begin(), times_ms.end(), 0.0) / static_cast<double>(scans)}};
  j["total_s"] = total_s;
  if (a.eval) {
    j["success_rate"] = tally.successRate();
    j["precision"] = tally.answered ? nlohmann::json(tally.precision()) : nlohmann::json(nullptr);
    j["success_definition"] = fmt::format("within {} m and {} deg of the truth", a.success_m, a.success_deg);
  }
  if (tally.odometry_pairs) {
    j["odometry_consistency"] = {
        {"pairs", tally.odometry_pairs},
        {"consistent", tally.odometry_consistent},
        {"rate", tally.odometryConsistency()},
        {"definition", fmt::format("consecutive answered scans whose relative pose agrees with odometry within {} m "
                                   "and {} deg",
                                   a.success_m, a.success_deg)}};
  }
  if (!a.json.empty()) io::writeFileAtomically(a.json, j.dump(2) + "\n");
  if (!a.quiet) {
    std::cerr << fmt::format("localized {} scans: {} answered, {} declined; median {:.1f} ms, p95 {:.1f} ms per scan",
                             scans, tally.answered, tally.declined, eval::percentile(times_ms, 0.5), eval::percentile(times_ms, 0.95));
    if (a.eval)
      std::cerr << fmt::format(
          "; success {:.1f}%, precision {:.1f}%",
          100.0 * tally.successRate(), tally.answered ? 100.0 * tally.precision() : 0.0);
    std::cerr << fmt::format(" -> {}\n", a.output);
  }
}

void addDbOptions(CLI::App* sub, localization::DatabaseOptions& o, double* fov_deg) {
  sub->add_option("--step", o.step_m, "spacing of the database positions [m]")->capture_default_str();
  sub->add_option("--beams", o.beams, "beams per virtual scan")->capture_default_str();
  if (fov_deg) sub->add_option("--fov", *fov_deg, "field of view of the virtual scans [deg]")->capture_default_str();
  sub->add_option("--max-range", o.max_range_m, "range of the virtual scans [m]")->capture_default_str();
  sub->add_option("--clearance", o.clearance_m, "positions keep this distance from obstacles and unknown space [m]")
      ->capture_default_str();
  sub->add_option("--profile-bins", o.profile_bins,
                  "sectors of each position's range profile, the second signature (0: none, else 8..720)")
      ->capture_default_str();
}

}  // namespace

void addLocalizeCommands(CLI::App& app) {
  auto d = std::make_shared<DbArgs>();
  auto* idx = app.add_subcommand("localize-index",
                                 "Build the global localizer's descriptor database of a map_server map (versioned "
                                 "binary file, tied to that map)");
  idx->add_option("MAP", d->map, "map: a map_server YAML, or a bare PGM/PNG image with --resolution")->required();
  addBareMapOptions(idx, d->bare, "MAP");
  idx->add_option("-o,--output", d->output, "database file to write")->required();
  addDbOptions(idx, d->options, &d->fov_deg);
  idx->add_flag("-q,--quiet", d->quiet, "no summary on stderr");
  idx->callback([d] { runIndex(*d); });

  auto a = std::make_shared<LocArgs>();
  auto* sub = app.add_subcommand(
      "localize",
      "Global pose of every scan of LOG in a known map, each on its own (no odometry); writes 't x y theta score' per "
      "scan, 't nan nan nan 0' when it declines");
  sub->add_option("MAP", a->map, "map: a map_server YAML, or a bare PGM/PNG image with --resolution")->required();
  addBareMapOptions(sub, a->bare, "MAP");
  sub->add_option("LOG", a->log, "log file (any format lidar2d reads)")->required();
  sub->add_option("-o,--output", a->output, "output file, one line per scan")->required();
  sub->add_option("--db", a->db, "database from 'lidar2d localize-index' (default: built in memory)");
  sub->add_option("--json", a->json, "write a JSON summary (timings; success rate with --eval) to this file");
  sub->add_flag("--eval", a->eval, "compare with the log's truth: success (within 0.3 m and 5 deg), precision");
  addChoice<Scans>(sub, "--scans", a->scans, {{"all", Scans::kAll}, {"even", Scans::kEven}, {"odd", Scans::kOdd}},
                   "which scans to localize: all, even or odd (0-based index in the log)")
      ->default_str("all");
  sub->add_option("--min-score", a->options.min_score,
                  "decline below this score (share of points on obstacles less contradictions: docs/localization.md)")
      ->capture_default_str();
  sub->add_option("--ambiguity", a->options.ambiguity_ratio,
                  "decline when a distinct alternative scores at least this fraction of the best")
      ->capture_default_str();
  sub->add_option("--ambiguity-nats", a->options.ambiguity_nats_per_point,
                  "decline when the distinct alternatives together are as likely as the best: each one's odds are "
                  "exp(-NATS x points scored x its fit gap to the best), summed (docs/localization.md); 0: off")
      ->check(CLI::Range(0.0, 100.0))
      ->capture_default_str();
  sub->add_option("--unconfident-nats", a->options.unconfident_nats_per_point,
                  "the same weight for a best pose scoring under 0.8, which must stand further above its rivals "
                  "(docs/localization.md)")
      ->check(CLI::Range(0.0, 100.0))
      ->capture_default_str();
  sub->add_option("--candidates", a->candidates,
                  "also write the best K distinct candidate poses of every scan, whatever their score, to OUTPUT.candidates "
                  "('t rank x y theta score fit' per line, ranked by fit; 0: none)")
      ->capture_default_str();
  sub->add_option("--prescored", a->options.max_candidates, "best-voted pose bins pre-scored per scan")
      ->capture_default_str();
  sub->add_option("--profile-candidates", a->options.profile_candidates,
                  "candidates from the range profiles, for scans with few lines (0: off)")
      ->capture_default_str();
  sub->add_option("--budget-ms", a->options.budget_ms,
                  "when no candidate scores, search the whole map by branch and bound until the scan has taken this "
                  "long [ms] (0: never)")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  sub->add_option("--regions", a->options.max_regions,
                  "candidate regions searched by branch and bound over every heading when the descriptors are not "
                  "confident (0: none)")
      ->capture_default_str();
  sub->add_flag("--fallback", a->options.fallback_branch_and_bound,
                "the whole-map search without the budget (exhaustive; seconds per scan)");
  addDbOptions(sub, a->db_options, nullptr);
  sub->add_flag("-q,--quiet", a->quiet, "no summary on stderr");
  addReaderOptions(sub, a->reader);
  sub->callback([a] { runLocalize(*a); });
}

}  // namespace lidar2d::cli
