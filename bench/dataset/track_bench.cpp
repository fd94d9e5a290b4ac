// Tracking (`lidar2d track`, issue 30) on BENCHMARK.md's protocol, and two of its targets:
// - lifelong: one log tracked `passes` times in a row by ONE localization::Tracker (never reset;
//   at each wrap the robot is carried from the log's end to its start, which the tracker must
//   notice and recover from), with the accuracy of every pass and the process's resident memory
//   after it: memory must stay flat, accuracy the same;
// - side by side with an AMCL-style particle filter started without an initial pose
//   (amcl_baseline.hpp), one pass over the same frames in the same map.
// Protocol: a log-odds map (5 cm) from the first half of a corrected log (or all of it) at truth
// poses; odometry re-made from the truth with `perturb --odom-model realistic --seed 1`'s noise.
// "Within" = reported as tracking (AMCL: cloud converged) and within 10 cm / 2 deg of the truth,
// share of all scans; "wrong" = tracking yet more than 0.5 m or 10 deg off.

#include <fmt/format.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <numbers>
#include <optional>

#include "amcl_baseline.hpp"
#include "dataset_bench.hpp"
#include "lidar2d/core/error.hpp"
#include "lidar2d/eval/metrics.hpp"
#include "lidar2d/localization/tracker.hpp"
#include "lidar2d/mapping/export.hpp"
#include "lidar2d/mapping/occupancy_map.hpp"
#include "lidar2d/sim/log_perturbation.hpp"

namespace lidar2d::bench {
namespace {

constexpr double kDeg = std::numbers::pi / 180.0;

// Resident set size of this process [MB] (/proc/self/statm, second field, in pages).
double rssMb() {
  std::ifstream in("/proc/self/statm");
  long size = 0, resident = 0;
  if (!(in >> size >> resident)) return std::nan("");
  return static_cast<double>(resident) * static_cast<double>(sysconf(_SC_PAGESIZE)) / (1024.0 * 1024.0);
}

// What one pass over the log gave.
struct PassStats {
  std::size_t scans = 0, tracking = 0, within = 0, wrong = 0, relocalizations = 0;
  std::optional<double> first_fix_s;   ///< log seconds from the pass's first scan to its first placed scan
  std::size_t scans_to_first_fix = 0;  ///< scans before it
  bool clock_advances = true;          ///< every stamp before the first fix later than the one before
  std::optional<double> last_time;
  std::vector<double> ms;              ///< CPU ms per scan
  std::vector<double> tracked_ms;      ///< CPU ms per tracked scan (Tracker only)
  std::vector<double> err_m, err_deg;  ///< errors of the scans reported as tracking [m], [deg]

  void add(const Frame& f, double t0, bool placed, bool tracking_now, const SE2& pose, double cpu_ms) {
    ++scans;
    ms.push_back(cpu_ms);
    if (!first_fix_s) {
      if (last_time && !(f.time > *last_time)) clock_advances = false;
      last_time = f.time;
      if (placed) {
        first_fix_s = f.time - t0;
        scans_to_first_fix = scans - 1;
      }
    }
    if (!tracking_now) return;
    ++tracking;
    const SE2 e = f.T_world_robot->inverse() * pose;
    err_m.push_back(e.translation().norm());
    err_deg.push_back(std::abs(e.theta()) / kDeg);
    within += e.translation().norm() <= 0.1 && std::abs(e.theta()) <= 2.0 * kDeg;
    wrong += e.translation().norm() > 0.5 || std::abs(e.theta()) > 10.0 * kDeg;
  }
  double share(std::size_t n) const { return 100.0 * static_cast<double>(n) / static_cast<double>(scans); }
  std::string medianError() const {
    if (err_m.empty()) return "-";
    return fmt::format("{:.1f} / {:.2f}", 100.0 * eval::percentile(err_m, 0.5), eval::percentile(err_deg, 0.5));
  }
  // As `lidar2d track` does: where the log's clock repeats or goes backwards before the fix, its time
  // says nothing (the Infinite Corridor's clock wraps), and the scan's index stands for it.
  std::string firstFix() const {
    if (!first_fix_s) return "never";
    return clock_advances ? fmt::format("{:.2f}", *first_fix_s) : fmt::format("scan {}", scans_to_first_fix);
  }
};

PassStats trackPass(localization::Tracker& tracker, const std::vector<Frame>& frames) {
  PassStats s;
  for (const Frame& f : frames) {
    const double c0 = threadCpuSeconds();
    const localization::TrackResult r = tracker.add(f);
    const double ms = 1e3 * (threadCpuSeconds() - c0);
    const bool tracking = r.status == localization::TrackStatus::kTracking;
    s.add(f, frames.front().time, r.status != localization::TrackStatus::kLost, tracking, r.T_world_robot, ms);
    s.relocalizations += r.relocalized;
    if (tracking) s.tracked_ms.push_back(ms);
  }
  return s;
}

PassStats amclPass(AmclFilter& filter, const std::vector<Frame>& frames, bool verbose) {
  PassStats s;
  for (const Frame& f : frames) {
    const double c0 = threadCpuSeconds();
    const AmclResult r = filter.add(f);
    if (verbose) {
      const SE2 e = f.T_world_robot->inverse() * r.T_world_robot;
      std::cerr << fmt::format(
          "amcl scan {}: {} particles, cluster {:.2f}, std {:.2f} m {:.1f} deg, error {:.2f} m {:.1f} deg{}{}\n",
          f.index, r.particles, r.cluster_weight, r.std_m, r.std_rad / kDeg, e.translation().norm(),
          std::abs(e.theta()) / kDeg, r.updated ? "" : " (no update)", r.converged ? " converged" : "");
    }
    s.add(f, frames.front().time, r.converged, r.converged, r.T_world_robot, 1e3 * (threadCpuSeconds() - c0));
  }
  return s;
}

std::string msCell(const std::vector<double>& ms) {
  if (ms.empty()) return "-";
  return fmt::format("{:.2f} / {:.1f}", eval::percentile(ms, 0.5), eval::percentile(ms, 0.99));
}

}  // namespace

void runTrackBenchmark(const std::string& data_dir, const TrackBenchOptions& bo) {
  struct Row {
    std::string run, method;
    PassStats s;
  };
  std::vector<Row> compare;
  std::cout << fmt::format("RSS at start: {:.1f} MB\n\n", rssMb());
  std::cout << "| log | map | pass | scans | tracking | within | wrong while tracking | relocalizations | first fix "
               "(log s) | median ms tracked | RSS after pass (MB) |\n";
  std::cout << "|---|---|---|---|---|---|---|---|---|---|---|\n";
  for (const std::string& log : bo.logs) {
    const std::string path = (std::filesystem::path(data_dir) / log).string();
    if (!std::filesystem::exists(path)) {
      std::cout << fmt::format("| {} | (missing: {}) |\n", log, path);
      continue;
    }
    const std::string name = std::filesystem::path(log).stem().stem().string();
    const std::vector<Frame> truth_frames = loadFrames(path);
    for (std::size_t i = 0; i < truth_frames.size(); ++i)
      if (!truth_frames[i].T_world_robot)
        throw badInput(fmt::format("scan {} has no truth pose; the track benchmark needs a corrected log", i),
                       ErrorLocation(path));
    sim::LogPerturbationOptions po;
    po.odometry = sim::realisticOdometryNoise();
    po.seed = bo.seed;
    const std::vector<Frame> frames = sim::perturbLog(truth_frames, po);
    for (const std::string& which : bo.maps) {
      if (which != "half" && which != "whole")
        throw invalidArgument(fmt::format("--maps: '{}' is neither 'half' nor 'whole'", which));
      const std::size_t n_map = which == "half" ? truth_frames.size() / 2 : truth_frames.size();
      auto m = mapping::makeMap(mapping::MapModel::kLogOdds, {});
      for (std::size_t i = 0; i < n_map; ++i)
        m->insert(truth_frames[i].scan, *truth_frames[i].T_world_robot * truth_frames[i].T_robot_laser);
      const OccupancyImage map = mapping::toOccupancyImage(*m);
      m.reset();
      const std::string run = fmt::format("{}, {} map", name, which);

      if (bo.passes > 0) {
        localization::Tracker tracker(map, std::nullopt, bo.tracker);
        std::cerr << fmt::format("{}: tracker built, RSS {:.1f} MB\n", run, rssMb());
        for (std::size_t pass = 1; pass <= bo.passes; ++pass) {
          const PassStats s = trackPass(tracker, frames);
          std::cout << fmt::format("| {} | {} | {} | {} | {:.1f}% | {:.1f}% | {} | {} | {} | {:.2f} | {:.1f} |\n", name,
                                   which, pass, s.scans, s.share(s.tracking), s.share(s.within), s.wrong,
                                   s.relocalizations, s.firstFix(),
                                   s.tracked_ms.empty() ? 0.0 : eval::percentile(s.tracked_ms, 0.5), rssMb());
          std::cout.flush();
          if (pass == 1) compare.push_back({run, "lidar2d track", s});
        }
      }
      if (bo.amcl) {
        AmclFilter filter(map, bo.amcl_options);
        compare.push_back({run,
                           fmt::format("AMCL-style PF ({} / {} particles)", bo.amcl_options.global_particles,
                                       bo.amcl_options.tracking_particles),
                           amclPass(filter, frames, bo.verbose)});
        std::cerr << fmt::format("{}: AMCL pass done, RSS {:.1f} MB\n", run, rssMb());
      }
    }
  }
  std::cout << "\n| run | method | scans | tracking | within | wrong while tracking | median error while tracking "
               "(cm / deg) | first fix (log s) | CPU ms per scan median / p99 |\n";
  std::cout << "|---|---|---|---|---|---|---|---|---|\n";
  for (const Row& r : compare)
    std::cout << fmt::format("| {} | {} | {} | {:.1f}% | {:.1f}% | {} | {} | {} | {} |\n", r.run, r.method, r.s.scans,
                             r.s.share(r.s.tracking), r.s.share(r.s.within), r.s.wrong, r.s.medianError(),
                             r.s.firstFix(), msCell(r.s.ms));
}

}  // namespace lidar2d::bench
