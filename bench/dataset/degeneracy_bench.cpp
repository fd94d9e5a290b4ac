// Degeneracy detection (issue 5):
// - simulated worlds (corridor, office, open; default laser: 541 beams over 270 degrees, 30 m, 1 cm
//   noise, 1% dropout; default route and noise, seed 1): every scan labelled from the world geometry
//   (degeneracy::labelFromWorld: degenerate when the visible walls are all parallel), precision and
//   recall of the geometric detector, the information detector and their combination. "Cannot decide"
//   counts as not flagged.
// - real logs (corrected infinite-corridor, intel, freiburg-079): the fraction of scans flagged by each detector,
//   the longest flagged stretches (scan indices, truth positions) and cannot-decide counts.
// - time per scan: both detectors together (degeneracy::analyze), median over the scans of the thread's
//   CPU time (CLOCK_THREAD_CPUTIME_ID: the machine may be shared), one core.

#include <fmt/format.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <ctime>
#include <filesystem>
#include <iostream>
#include <numbers>

#include "dataset_bench.hpp"
#include "lidar2d/degeneracy/degeneracy.hpp"
#include "lidar2d/degeneracy/ground_truth.hpp"
#include "lidar2d/eval/metrics.hpp"
#include "lidar2d/sim/path.hpp"
#include "lidar2d/sim/simulator.hpp"
#include "lidar2d/sim/worlds.hpp"

namespace lidar2d::bench {
namespace {

using Clock = std::chrono::steady_clock;

// CPU time of the calling thread [ms]: the machine may be shared, wall time would count the waits.
double threadCpuMs() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return 1e3 * static_cast<double>(ts.tv_sec) + 1e-6 * static_cast<double>(ts.tv_nsec);
}

struct Tally {
  std::size_t tp = 0, fp = 0, fn = 0, tn = 0, undecided = 0;
  void add(bool truth, degeneracy::Verdict v) {
    undecided += v == degeneracy::Verdict::kCannotDecide;
    const bool flagged = v == degeneracy::Verdict::kDegenerate;
    if (truth && flagged) ++tp;
    if (!truth && flagged) ++fp;
    if (truth && !flagged) ++fn;
    if (!truth && !flagged) ++tn;
  }
  std::string precision() const { return tp + fp ? fmt::format("{:.1f}%", 100.0 * tp / (tp + fp)) : "-"; }
  std::string recall() const { return tp + fn ? fmt::format("{:.1f}%", 100.0 * tp / (tp + fn)) : "-"; }
};

void simulated(const DegeneracyBenchOptions& bo) {
  std::cout << "### Simulated worlds (labels from the world geometry)\n\n";
  std::cout << fmt::format("Laser: {} beams over {} deg, range {} m. 'Cannot decide' counts as not flagged.\n\n",
                           bo.beams, bo.fov_deg, bo.max_range_m);
  std::cout << "| world | labelled scans | labelled degenerate | detector | TP | FP | FN | precision | recall | cannot "
               "decide | "
               "median CPU ms/scan |\n";
  std::cout << "|---|---|---|---|---|---|---|---|---|---|---|\n";
  Tally all[3];
  std::string notes;
  for (const std::string world : {"corridor", "office", "open"}) {
    sim::Scenario sc = sim::builtinScenario(world);
    sim::SimulatorOptions so;
    so.seed = bo.seed;
    so.laser.beams = bo.beams;
    so.laser.fov_rad = bo.fov_deg * std::numbers::pi / 180.0;
    so.laser.range_max_m = bo.max_range_m;
    const auto truth = sim::samplePath(sc.waypoints, sim::PathOptions{});
    sim::Simulator simulator(sc.world, truth, so);
    Tally t[3];
    std::size_t labelled = 0, scans = 0, too_few = 0, too_few_undecided = 0, too_few_flagged = 0;
    std::vector<double> ms;
    while (auto f = simulator.next()) {
      const degeneracy::TruthLabel label = degeneracy::labelFromWorld(sc.world, *f->T_world_robot, so.laser);
      const Points2 pts = f->scan.toPoints(f->T_robot_laser);
      const double c0 = threadCpuMs();
      const degeneracy::Result r = degeneracy::analyze(pts, bo.options);
      ms.push_back(threadCpuMs() - c0);
      ++scans;
      if (!label.enough_hits) {  // the label does not judge scans with fewer than 20 hits
        ++too_few;
        too_few_undecided += r.verdict == degeneracy::Verdict::kCannotDecide;
        too_few_flagged += r.degenerate();
        continue;
      }
      labelled += label.degenerate;
      t[0].add(label.degenerate, r.geometric.verdict);
      t[1].add(label.degenerate, r.information.verdict);
      t[2].add(label.degenerate, r.verdict);
      if (bo.verbose && (label.degenerate != (r.verdict == degeneracy::Verdict::kDegenerate)))
        std::cerr << fmt::format(
            "{} scan {} at ({:.2f}, {:.2f}, {:.0f} deg): label {} (hits {}, visible {}) -> {} geo {} {:.4f} info {} "
            "{:.4f} "
            "({})\n",
            world, f->index, f->T_world_robot->x(), f->T_world_robot->y(),
            f->T_world_robot->theta() * 180 / std::numbers::pi, label.degenerate, label.hits, label.visible,
            degeneracy::toString(r.verdict), degeneracy::toString(r.geometric.verdict), r.geometric.score,
            degeneracy::toString(r.information.verdict), r.information.score, r.reason + r.geometric.reason);
    }
    const char* names[3] = {"geometric", "information", "combined"};
    for (int k = 0; k < 3; ++k) {
      std::cout << fmt::format("| {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} |\n", world, scans - too_few,
                               labelled, names[k], t[k].tp, t[k].fp, t[k].fn, t[k].precision(), t[k].recall(),
                               t[k].undecided, k == 2 ? fmt::format("{:.3f}", eval::percentile(ms, 0.5)) : "");
      all[k].tp += t[k].tp;
      all[k].fp += t[k].fp;
      all[k].fn += t[k].fn;
      all[k].undecided += t[k].undecided;
    }
    if (too_few)
      notes += fmt::format(
          "- {}: {} scans with fewer than 20 beam hits are not labelled (excluded above); the combination "
          "says 'cannot decide' for {} of them and 'degenerate' for {}.\n",
          world, too_few, too_few_undecided, too_few_flagged);
  }
  const char* names[3] = {"geometric", "information", "combined"};
  for (int k = 0; k < 3; ++k)
    std::cout << fmt::format("| all three | | | {} | {} | {} | {} | **{}** | **{}** | {} | |\n", names[k], all[k].tp,
                             all[k].fp, all[k].fn, all[k].precision(), all[k].recall(), all[k].undecided);
  std::cout << "\n" << notes << (notes.empty() ? "" : "\n");
}

void real(const std::string& data_dir, const DegeneracyBenchOptions& bo) {
  std::cout << "### Real logs (corrected Radish logs; positions are the corrected poses)\n\n";
  std::cout << "| log | scans | beams | geometric flagged | information flagged | combined flagged | cannot decide | "
               "median CPU ms/scan | longest flagged stretches (scans: first-last, x y of the first) |\n";
  std::cout << "|---|---|---|---|---|---|---|---|---|\n";
  for (const std::string rel :
       {"corrected/infinite-corridor.log.gz", "corrected/intel.log.gz", "corrected/freiburg-079.log.gz"}) {
    const std::string path = (std::filesystem::path(data_dir) / rel).string();
    if (!std::filesystem::exists(path)) {
      std::cout << "| " << rel << " | missing: skipped | | | | | | | |\n";
      continue;
    }
    const std::vector<Frame> frames = loadFrames(path);
    std::size_t flagged[3] = {0, 0, 0}, undecided = 0;
    std::vector<double> ms;
    std::vector<bool> deg(frames.size());
    for (std::size_t i = 0; i < frames.size(); ++i) {
      const Points2 pts = frames[i].scan.toPoints(frames[i].T_robot_laser);
      const double c0 = threadCpuMs();
      const degeneracy::Result r = degeneracy::analyze(pts, bo.options);
      ms.push_back(threadCpuMs() - c0);
      flagged[0] += r.geometric.verdict == degeneracy::Verdict::kDegenerate;
      flagged[1] += r.information.verdict == degeneracy::Verdict::kDegenerate;
      flagged[2] += r.degenerate();
      undecided += r.verdict == degeneracy::Verdict::kCannotDecide;
      deg[i] = r.degenerate();
    }
    // Stretches of consecutive flagged scans, longest first.
    std::vector<std::pair<std::size_t, std::size_t>> runs;
    for (std::size_t i = 0; i < deg.size();) {
      if (!deg[i]) {
        ++i;
        continue;
      }
      std::size_t j = i;
      while (j < deg.size() && deg[j]) ++j;
      runs.push_back({i, j - 1});
      i = j;
    }
    std::sort(runs.begin(), runs.end(),
              [](const auto& a, const auto& b) { return a.second - a.first > b.second - b.first; });
    std::string where;
    for (std::size_t k = 0; k < std::min<std::size_t>(runs.size(), 4); ++k) {
      const Frame& f = frames[runs[k].first];
      where += fmt::format("{}{}-{}", k ? "; " : "", runs[k].first, runs[k].second);
      if (f.T_world_robot) where += fmt::format(" ({:.1f} {:.1f})", f.T_world_robot->x(), f.T_world_robot->y());
    }
    const double n = static_cast<double>(frames.size());
    std::cout << fmt::format("| {} | {} | {} | {:.1f}% | {:.1f}% | {:.1f}% | {} | {:.3f} | {} |\n",
                             std::filesystem::path(rel).stem().stem().string(), frames.size(),
                             frames.empty() ? 0 : frames[0].scan.size(), 100.0 * flagged[0] / n, 100.0 * flagged[1] / n,
                             100.0 * flagged[2] / n, undecided, eval::percentile(ms, 0.5), where);
  }
  std::cout << "\n";
}

}  // namespace

void runDegeneracyBenchmark(const std::string& data_dir, const DegeneracyBenchOptions& options) {
  simulated(options);
  real(data_dir, options);
}

}  // namespace lidar2d::bench
