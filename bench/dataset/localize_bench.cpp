// Global localization (issues 6, 34) on the protocol of ../shared/DESIGN.md:
// - the seven corrected logs: a log-odds map (5 cm) from the even-numbered scans with truth
//   poses; every odd-numbered scan localized on its own. Success = within 0.3 m and 5 deg of the
//   truth; precision = successes among answered scans; decline rate; median/p95 wall ms and median
//   CPU ms (every thread) per query;
//   database build time and size. Baseline: exhaustive branch-and-bound correlative search over the
//   whole map and all orientations (registration::matchCorrelativeGlobal) on a subset of the scans.
// - the simulator's `symmetric` world: the localizer must decline or list every symmetric pose.
// - the ROS2 bag in ros2/ localized in ros2/maps/mac_1st_floor_final, and the rplidar-flipped bag
//   in its room's gridmap.png: no truth, so the consistency of consecutive answers with odometry.

#include <fmt/format.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <limits>
#include <map>
#include <numbers>
#include <stdexcept>

#include "dataset_bench.hpp"
#include "lidar2d/core/laser_mount.hpp"
#include "lidar2d/eval/metrics.hpp"
#include "lidar2d/io/frame_source.hpp"
#include "lidar2d/io/localization_db.hpp"
#include "lidar2d/io/map_file.hpp"
#include "lidar2d/localization/localizer.hpp"
#include "lidar2d/localization/mirror_check.hpp"
#include "lidar2d/mapping/export.hpp"
#include "lidar2d/mapping/occupancy_map.hpp"
#include "lidar2d/registration/correlative.hpp"
#include "lidar2d/sim/path.hpp"
#include "lidar2d/sim/simulator.hpp"
#include "lidar2d/sim/worlds.hpp"

namespace lidar2d::bench {
namespace {

using Clock = std::chrono::steady_clock;
constexpr double kDeg = std::numbers::pi / 180.0;

double sec(Clock::time_point a) { return std::chrono::duration<double>(Clock::now() - a).count(); }

bool near(const SE2& a, const SE2& b, double m = 0.3, double deg = 5.0) {
  const SE2 e = a.inverse() * b;
  return e.translation().norm() <= m && std::abs(e.theta()) <= deg * kDeg;
}

// `ms`: wall ms per query; `cpu_ms`: CPU ms per query of every thread (empty: not measured).
void row(const std::string& name, const std::string& method, std::size_t n, std::size_t ok, std::size_t answered,
         std::size_t declined, const std::vector<double>& ms, const std::vector<double>& cpu_ms,
         const std::string& db) {
  std::cout << fmt::format(
      "| {} | {} | {} | {:.1f}% | {} | {:.1f}% | {:.1f} | {:.1f} | {} | {} |\n", name, method, n,
      100.0 * static_cast<double>(ok) / static_cast<double>(n),
      answered ? fmt::format("{:.1f}%", 100.0 * static_cast<double>(ok) / static_cast<double>(answered))
               : std::string("-"),
      100.0 * static_cast<double>(declined) / static_cast<double>(n), eval::percentile(ms, 0.5),
      eval::percentile(ms, 0.95),
      cpu_ms.empty() ? std::string("-") : fmt::format("{:.1f}", eval::percentile(cpu_ms, 0.5)), db);
}

// One query for the calibration curve: answered (not declined), its score, and whether it is right.
struct Answer {
  bool answered = false;
  double score = 0.0;
  bool ok = false;
};

// The calibration curve of one map: at each threshold, the queries answered with a score at least
// the threshold (share of all queries), the successes among all queries, the precision among those
// answers; then the lowest threshold from which on (every threshold of a 0.01 grid at or above it
// that still answers something) the precision is at least 99%.
std::string calibrationCurve(const std::string& name, const std::vector<Answer>& answers) {
  const auto n = static_cast<double>(answers.size());
  auto at = [&](double t) {
    std::size_t a = 0, ok = 0;
    for (const Answer& q : answers)
      if (q.answered && q.score >= t - 1e-12) {
        ++a;
        ok += q.ok;
      }
    return std::pair<std::size_t, std::size_t>{a, ok};
  };
  std::string out = fmt::format("| {} |", name);
  for (const double t : {0.5, 0.6, 0.7, 0.8, 0.85, 0.9, 0.95}) {
    const auto [a, ok] = at(t);
    out +=
        fmt::format(" {:.1f} / {:.1f} / {} |", 100.0 * static_cast<double>(a) / n, 100.0 * static_cast<double>(ok) / n,
                    a ? fmt::format("{:.1f}", 100.0 * static_cast<double>(ok) / static_cast<double>(a)) : "-");
  }
  // Scan the thresholds from the top down: the lowest one before the precision first drops below 99%.
  double t99 = std::numeric_limits<double>::quiet_NaN();
  for (int c = 100; c >= 50; --c) {
    const auto [a, ok] = at(c / 100.0);
    if (a == 0) continue;
    if (static_cast<double>(ok) < 0.99 * static_cast<double>(a)) break;
    t99 = c / 100.0;
  }
  if (std::isnan(t99)) return out + " none | - |\n";
  const auto [a, ok] = at(t99);
  return out + fmt::format(" {:.2f} | {:.1f}% |\n", t99, 100.0 * static_cast<double>(ok) / n);
}

// Every `bo.stride`-th scan of `log` localized in `map` on its own: the share answered, how many
// consecutive answered pairs agree with the odometry (0.3 m, 5 deg), and, when almost none are
// answered, whether their mirror images would be (localization::MirrorCheck). Printed as one line.
void localizeWithOdometry(const std::string& name, const OccupancyImage& map, const std::string& log,
                          const io::ReaderOptions& ro, const LocalizeBenchOptions& bo) {
  const auto tb = Clock::now();
  localization::Database db = localization::Database::build(map, bo.db);
  const double build_s = sec(tb);
  localization::Localizer loc(map, std::move(db), bo.loc);
  auto src = io::openLog(log, ro);
  std::size_t n = 0, answered = 0, pairs = 0, consistent = 0;
  std::vector<double> ms;
  SE2 prev_pose, prev_odom;
  bool have_pose = false, have_odom = false;
  std::size_t idx = 0;
  localization::MirrorCheck mirror;
  while (auto f = src->next()) {
    if (idx++ % bo.stride != 0) continue;
    const auto r = loc.localize(f->scan, f->T_robot_laser);
    ++n;
    ms.push_back(r.total_ms);
    if (!r.declined) {
      ++answered;
      if (have_pose && have_odom && f->T_odom_robot) {
        const SE2 e = (prev_odom.inverse() * *f->T_odom_robot).inverse() * (prev_pose.inverse() * r.T_world_robot);
        ++pairs;
        consistent += e.translation().norm() <= 0.3 && std::abs(e.theta()) <= 5.0 * kDeg;
      }
      prev_pose = r.T_world_robot;
    } else {
      mirror.add(f->scan, f->T_robot_laser);
    }
    have_pose = !r.declined;
    have_odom = f->T_odom_robot.has_value();
    if (have_odom) prev_odom = *f->T_odom_robot;
  }
  std::string mirrored;
  if (const auto m = mirror.runIfFewPlaced(loc, n))
    mirrored = fmt::format("; mirror images of the declined placed: {} of {}", m->placed, m->tried);
  std::cout << fmt::format(
      "\n{} ({}x{} cells at {} m; database {:.2f} s, {:.1f} MB): {} scans (every {}), answered {:.1f}%, consecutive "
      "answered pairs consistent with odometry (0.3 m, 5 deg) {} of {} ({:.1f}%), median {:.1f} ms, p95 {:.1f} ms{}\n",
      name, map.width(), map.height(), map.resolution(), build_s, loc.database().memoryBytes() / 1e6, n, bo.stride,
      100.0 * static_cast<double>(answered) / static_cast<double>(n), consistent, pairs,
      pairs ? 100.0 * static_cast<double>(consistent) / static_cast<double>(pairs) : 0.0, eval::percentile(ms, 0.5),
      eval::percentile(ms, 0.95), mirrored);
}

// Each log's map (its even scans at truth poses) queried with `bo.other_buildings` scans, evenly
// spread, of every other log: a map of another building holds none of their places, so every
// answer is wrong. One table row per map.
void runOtherBuildings(const std::string& data_dir, const LocalizeBenchOptions& bo) {
  std::vector<std::pair<std::string, std::vector<Frame>>> logs;
  for (const std::string& log : bo.logs) {
    const std::string path = (std::filesystem::path(data_dir) / log).string();
    if (!std::filesystem::exists(path)) continue;
    logs.emplace_back(path, loadFrames(path));
  }
  std::cout << fmt::format(
      "\nScans of other buildings ({} of each other log, evenly spread) in each log's even-scan map; every "
      "answer is wrong\n\n| map | queries | answered | score >= 0.7 | score >= 0.8 | declined ambiguous |\n"
      "|---|---|---|---|---|---|\n",
      bo.other_buildings);
  for (const auto& [path, frames] : logs) {
    const OccupancyImage map = mapping::toOccupancyImage(*evenFramesMap(frames, path));
    const localization::Localizer loc(map, localization::Database::build(map, bo.db), bo.loc);
    std::size_t n = 0, answered = 0, over07 = 0, over08 = 0, ambiguous = 0;
    for (const auto& [other, queries] : logs) {
      if (other == path || queries.empty()) continue;
      const std::size_t k = std::min(bo.other_buildings, queries.size());
      for (std::size_t i = 0; i < k; ++i) {
        const Frame& f = queries[i * queries.size() / k];
        const auto r = loc.localize(f.scan, f.T_robot_laser);
        ++n;
        ambiguous += r.declined && r.reason == "ambiguous";
        if (r.declined) continue;
        ++answered;
        over07 += r.score >= 0.7;
        over08 += r.score >= 0.8;
      }
    }
    const auto pct = [n](std::size_t v) {
      return fmt::format("{} ({:.1f}%)", v, n ? 100.0 * static_cast<double>(v) / static_cast<double>(n) : 0.0);
    };
    std::cout << fmt::format("| {} | {} | {} | {} | {} | {} |\n", std::filesystem::path(path).stem().stem().string(), n,
                             pct(answered), pct(over07), pct(over08), pct(ambiguous));
  }
}

}  // namespace

void runLocalizeBenchmark(const std::string& data_dir, const LocalizeBenchOptions& bo) {
  if (bo.other_buildings > 0) return runOtherBuildings(data_dir, bo);
  std::cout << "| dataset | method | queries | success | precision | declined | median ms | p95 ms | median CPU ms "
               "| database |\n";
  std::cout << "|---|---|---|---|---|---|---|---|---|---|\n";
  std::string curves;
  std::ofstream queries;
  if (!bo.queries.empty()) {
    queries.open(bo.queries);
    if (!queries) throw std::runtime_error(fmt::format("{}: cannot write", bo.queries));
    queries
        << "map\tscan\tmapped\toutcome\treason\tscore\tfit\trunner_up_score\trunner_up_fit\ttruth_fit\tcandidate_near_"
           "truth\talternative_fits\tpoints\tregions\tlookup_ms\tverify_ms\twall_ms\tcandidate_scores_fits\n";
  }
  for (const std::string& log : bo.logs) {
    const std::string path = (std::filesystem::path(data_dir) / log).string();
    if (!std::filesystem::exists(path)) {
      std::cout << fmt::format("| {} | (missing: {}) |\n", log, path);
      continue;
    }
    const std::vector<Frame> frames = loadFrames(path);
    const std::string name = std::filesystem::path(log).stem().stem().string();
    const std::vector<Frame> mapped(
        frames.begin(), frames.begin() + static_cast<std::ptrdiff_t>(bo.half ? frames.size() / 2 : frames.size()));
    const OccupancyImage map = mapping::toOccupancyImage(*evenFramesMap(mapped, path));
    // A query is in a mapped place when a mapping scan was taken within 1 m of it.
    const auto inMappedPlace = [&](const SE2& T) {
      for (std::size_t i = 0; i < mapped.size(); i += 2)
        if ((mapped[i].T_world_robot->translation() - T.translation()).norm() < 1.0) return true;
      return false;
    };
    if (!bo.save_maps.empty()) {
      std::filesystem::create_directories(bo.save_maps);
      io::writeMap((std::filesystem::path(bo.save_maps) / (name + "-even.yaml")).string(), map);
    }
    const auto tb = Clock::now();
    localization::Database db = localization::Database::build(map, bo.db);
    const double build_s = sec(tb);
    const std::string db_desc = fmt::format("{:.2f} s, {:.1f} MB, {} positions, {:.0f}% coverage", build_s,
                                            db.memoryBytes() / 1e6, db.positions().size(), 100.0 * db.coverage());
    localization::Localizer loc(map, std::move(db), bo.loc);
    std::size_t n = 0, ok = 0, answered = 0, declined = 0;
    // With --half: queries in unmapped places, their answers, and the right ones among them.
    std::size_t unmapped = 0, unmapped_answered = 0, unmapped_ok = 0;
    // Failure modes: no verified candidate near the truth; one near it but not ranked first;
    // ranked first but declined (by reason).
    std::size_t f_missing = 0, f_misranked = 0;
    std::map<std::string, std::size_t> f_declined;
    double t_desc = 0, t_look = 0, t_ver = 0;
    std::size_t with_regions = 0, with_fallback = 0;
    std::vector<double> ms, cpu_ms;
    std::vector<Answer> answers;
    std::vector<std::size_t> odd;
    for (std::size_t i = 1; i < frames.size(); i += 2) odd.push_back(i);
    for (std::size_t k = 0; k < odd.size(); k += bo.stride) {
      const Frame& f = frames[odd[k]];
      const double cpu0 = processCpuSeconds();
      const auto t0 = Clock::now();
      const auto r = loc.localize(f.scan, f.T_robot_laser);
      ms.push_back(1e3 * sec(t0));
      ++n;
      // CPU time of the query, every thread: on a shared machine the wall time includes waiting for
      // a core, so both are given (a query uses up to LocalizerOptions::threads).
      cpu_ms.push_back(1e3 * (processCpuSeconds() - cpu0));
      t_desc += r.describe_ms;
      t_look += r.lookup_ms;
      t_ver += r.verify_ms;
      with_regions += r.num_regions > 0;
      with_fallback += r.used_fallback;
      // Whether the best pose is at the truth (declined or not), and the first candidate that is.
      const bool at_truth = near(*f.T_world_robot, r.T_world_robot);
      const auto truth = std::find_if(r.candidates.begin(), r.candidates.end(), [&](const localization::Candidate& c) {
        return near(*f.T_world_robot, c.T_world_robot);
      });
      const bool right = !r.declined && at_truth;
      if (r.declined) {
        ++declined;
      } else {
        ++answered;
        ok += right;
      }
      answers.push_back({!r.declined, r.score, right});
      const bool mapped_place = (bo.half || queries.is_open()) && inMappedPlace(*f.T_world_robot);
      if (bo.half && !mapped_place) {
        ++unmapped;
        unmapped_answered += !r.declined;
        unmapped_ok += right;
      }
      if (!right) {
        if (truth == r.candidates.end())
          ++f_missing;
        else if (truth != r.candidates.begin())
          ++f_misranked;
        else
          ++f_declined[r.reason];
      }
      if (queries.is_open()) {
        std::string alts;
        for (const auto& a : r.alternatives) alts += fmt::format("{}{:.4f}", alts.empty() ? "" : ",", a.fit);
        std::string cands;
        for (const auto& c : r.candidates)
          cands += fmt::format("{}{:.4f}:{:.4f}", cands.empty() ? "" : ",", c.score, c.fit);
        const bool two = r.candidates.size() > 1;
        queries << fmt::format(
            "{}\t{}\t{}\t{}\t{}\t{:.4f}\t{:.4f}\t{:.4f}\t{:.4f}\t{}\t{}\t{}\t{}\t{}\t{:.2f}\t{:.2f}\t{:.2f}\t{}\n",
            name, odd[k], int(mapped_place), r.declined ? "declined" : (at_truth ? "right" : "wrong"),
            r.reason.empty() ? "-" : r.reason, r.score, r.candidates.empty() ? 0.0 : r.candidates.front().fit,
            two ? r.candidates[1].score : 0.0, two ? r.candidates[1].fit : 0.0,
            truth == r.candidates.end() ? std::string("-") : fmt::format("{:.4f}", truth->fit),
            truth == r.candidates.end() ? -1 : truth - r.candidates.begin(), alts.empty() ? "-" : alts, r.num_points,
            r.num_regions, r.lookup_ms, r.verify_ms, ms.back(), cands.empty() ? "-" : cands);
      }
      if (bo.verbose && !right)
        std::cerr << fmt::format(
            "{} scan {}: {} {} truth score {:.3f} score {:.3f} lines {} cands {} alt {} alt0/best fit {:.3f} ({:.3f} {:.3f} "
            "{:.1f}) truth ({:.3f} {:.3f} {:.1f}) regions {}{}\n",
            name, odd[k], r.declined ? "declined" : "WRONG", r.reason,
            loc.score(f.scan.toPoints(f.T_robot_laser), *f.T_world_robot, f.T_robot_laser.translation()), r.score,
            r.num_lines, r.num_candidates, r.alternatives.size(),
            r.alternatives.empty() ? 0.0 : r.alternatives[0].fit / std::max(1e-9, r.candidates.empty() ? 1.0 : r.candidates[0].fit), r.T_world_robot.x(), r.T_world_robot.y(),
            r.T_world_robot.theta() / kDeg, f.T_world_robot->x(), f.T_world_robot->y(),
            f.T_world_robot->theta() / kDeg, r.num_regions, r.used_fallback ? " whole-map" : "");
    }
    row(name, "cascade", n, ok, answered, declined, ms, cpu_ms, db_desc);
    if (bo.half)
      std::cout << fmt::format("{}: {} queries more than 1 m from every mapping scan: {} answered, {} of them right\n",
                               name, unmapped, unmapped_answered, unmapped_ok);
    if (bo.calibration) curves += calibrationCurve(name, answers);
    {
      std::string dec;
      for (const auto& [reason, c] : f_declined) dec += fmt::format(" {}: {}", reason, c);
      std::cerr << fmt::format(
          "{} failures: no candidate near the truth {}, near but mis-ranked {}, best declined{}; region search on {}, "
          "whole-map search on {} of {} queries\n",
          name, f_missing, f_misranked, dec.empty() ? std::string(" 0") : dec, with_regions, with_fallback, n);
    }
    if (bo.verbose)
      std::cerr << fmt::format("mean ms: describe {:.2f} lookup {:.2f} verify {:.2f}\n",
                               t_desc / static_cast<double>(n), t_look / static_cast<double>(n),
                               t_ver / static_cast<double>(n));

    if (bo.baseline_stride > 0) {
      registration::CorrelativeOptions co;
      co.min_score = 0.0;
      co.refinement.resolution_m = map.resolution();
      const auto tg = Clock::now();
      const registration::CorrelativeGrid grid = registration::CorrelativeGrid::fromMap(map, co);
      const registration::LikelihoodField field = registration::LikelihoodField::fromMap(map, co.refinement);
      const double grid_s = sec(tg);
      std::size_t bn = 0, bok = 0;
      std::vector<double> bms;
      for (std::size_t k = 0; k < odd.size(); k += bo.baseline_stride) {
        const Frame& f = frames[odd[k]];
        const auto t0 = Clock::now();
        const auto r = registration::matchCorrelativeGlobal(grid, f.scan.toPoints(f.T_robot_laser), co, &field);
        bms.push_back(1e3 * sec(t0));
        ++bn;
        bok += near(*f.T_world_robot, r.T_target_source);
      }
      row(name, "branch-and-bound (whole map)", bn, bok, bn, 0, bms, {}, fmt::format("grids {:.2f} s", grid_s));
    }
  }

  if (bo.calibration) {
    std::cout << "\ncalibration: answered / success / precision [%] among all queries, answers with a score >= the "
                 "threshold\n\n| dataset | >= 0.5 | >= 0.6 | >= 0.7 | >= 0.8 | >= 0.85 | >= 0.9 | >= 0.95 | 99% "
                 "precision from | success there |\n|---|---|---|---|---|---|---|---|---|---|\n"
              << curves;
  }
  if (!bo.extras) return;
  // Symmetric world: four identical rooms, invariant under a 90 degree rotation about the origin.
  {
    const sim::Scenario sc = sim::builtinScenario("symmetric");
    const auto truth = sim::samplePath(sc.waypoints, {});
    sim::SimulatorOptions so;
    const std::vector<Frame> frames = sim::simulate(sc.world, truth, so.noiseFree());
    const OccupancyImage map = mapping::toOccupancyImage(*evenFramesMap(frames, "symmetric world"));
    localization::Localizer loc(map, bo.loc, bo.db);
    std::size_t n = 0, declined = 0, all_listed = 0, answered_one = 0;
    std::vector<double> ms;
    for (std::size_t i = 1; i < frames.size(); i += 2 * bo.stride) {
      const Frame& f = frames[i];
      const auto r = loc.localize(f.scan, f.T_robot_laser);
      ++n;
      ms.push_back(r.total_ms);
      declined += r.declined;
      std::vector<SE2> listed{r.T_world_robot};
      for (const auto& a : r.alternatives) listed.push_back(a.T_world_robot);
      std::size_t found = 0;
      for (int q = 0; q < 4; ++q) {
        const SE2 rot(0, 0, q * 90.0 * kDeg);
        const SE2 sym = rot * *f.T_world_robot;
        found += std::any_of(listed.begin(), listed.end(), [&](const SE2& p) { return near(sym, p); });
      }
      all_listed += found == 4;
      answered_one += !r.declined && found < 4;
    }
    std::cout << fmt::format(
        "\nsymmetric world: {} queries, declined {:.1f}%, all four symmetric poses listed {:.1f}%, "
        "answered with a single room (wrong by symmetry) {:.1f}%, median {:.1f} ms\n",
        n, 100.0 * static_cast<double>(declined) / static_cast<double>(n),
        100.0 * static_cast<double>(all_listed) / static_cast<double>(n),
        100.0 * static_cast<double>(answered_one) / static_cast<double>(n), eval::percentile(ms, 0.5));
  }

  // Real bags in maps from elsewhere, no truth: consistency of consecutive answers with odometry.
  const auto bag = std::filesystem::path(data_dir) / "ros2" / "macfirst_floor_take_2";
  const auto yaml = std::filesystem::path(data_dir) / "ros2" / "maps" / "mac_1st_floor_final.yaml";
  if (std::filesystem::exists(bag) && std::filesystem::exists(yaml))
    localizeWithOdometry("ros2 bag macfirst_floor_take_2 in mac_1st_floor_final", io::readMap(yaml.string()).map,
                         bag.string(), {}, bo);
  // The rplidar-flipped room's hand-made gridmap.png, read with its rows up as its course wrote it
  // (docs/file-formats.md, bare map images), the laser as config.yaml mounts it (upside down); and
  // read as map_server reads an image, where the map is the room's mirror image.
  const auto room = std::filesystem::path(data_dir) / "bags" / "rplidar-flipped";
  if (std::filesystem::exists(room / "hw2_data.bag") && std::filesystem::exists(room / "gridmap.png")) {
    io::MapYaml y;
    y.resolution = 0.05;
    y.origin = SE2(-7.5, -9.5, 0.0);
    io::ReaderOptions ro;
    ro.laser_mount = LaserMount::fromRollPitchYaw(0.2, 0.0, 0.0, 0.0, std::numbers::pi, 0.0);
    for (const bool rows_up : {true, false}) {
      y.rows_up = rows_up;
      localizeWithOdometry(rows_up ? "rplidar-flipped bag in gridmap.png (rows up)"
                                   : "rplidar-flipped bag in gridmap.png read as map_server reads it (mirrored)",
                           io::readMapImage((room / "gridmap.png").string(), y).map, (room / "hw2_data.bag").string(),
                           ro, bo);
    }
  }
}

}  // namespace lidar2d::bench
