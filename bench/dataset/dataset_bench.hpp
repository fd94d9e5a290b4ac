#pragma once
// Shared pieces of the dataset benchmark.

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "amcl_baseline.hpp"
#include "lidar2d/core/frame.hpp"
#include "lidar2d/degeneracy/degeneracy.hpp"
#include "lidar2d/localization/localizer.hpp"
#include "lidar2d/localization/tracker.hpp"
#include "lidar2d/mapping/occupancy_map.hpp"
#include "lidar2d/registration/correlative.hpp"
#include "lidar2d/registration/icp.hpp"

namespace lidar2d::bench {

/// Reads every frame of a log into memory (so that timings exclude parsing).
std::vector<Frame> loadFrames(const std::string& path);

/// A map of `model` from the even-numbered frames (0, 2, 4, ...) at their truth poses, built by
/// mapping::MapBuilder. Throws `lidar2d::Error` naming `name` and the scan when one lacks a truth pose.
std::unique_ptr<mapping::OccupancyMap> evenFramesMap(const std::vector<Frame>& frames, const std::string& name,
                                                     mapping::MapModel model = mapping::MapModel::kLogOdds,
                                                     const mapping::MapOptions& options = {});

/// CPU time of the calling thread [s]: per-item times on a machine shared with other jobs (wall
/// time there includes waiting for the core).
double threadCpuSeconds();
/// CPU seconds of the whole process so far (every thread).
double processCpuSeconds();

/// True when `name` is in `list`, or `list` is empty (a `--methods` / `--solvers` filter).
bool wanted(const std::vector<std::string>& list, const std::string& name);

void runMapBenchmark(const std::string& data_dir);

/// Options of the `match` subcommand.
struct MatchBenchOptions {
  double sigma_xy_m = 0.1;          ///< RMS translation error of the perturbed initial guess [m]
  double sigma_theta_deg = 5.0;     ///< RMS rotation error of the perturbed initial guess [deg]
  std::uint64_t seed = 1;           ///< seed of the perturbation
  std::vector<std::string> methods;  ///< method names to run (p2p, p2l, lf, corr); empty = all
  std::vector<std::string> solvers;  ///< solver names to run (gn, ceres); empty = all
  std::vector<std::string> inits{"perturbed", "identity"};  ///< initial guesses: perturbed, identity, truth
  registration::IcpOptions icp;      ///< ICP options (metric and solver are set per row)
  registration::CorrelativeOptions corr;  ///< correlative options (window, grid)
  registration::LikelihoodFieldOptions lf;  ///< likelihood-field options (solver is set per row)
  /// Instead of the table: match every pair from its true relative pose with p2p, p2l and lf
  /// (Gauss-Newton) and count the pairs where all three fail the bar yet agree with each other.
  bool truth_check = false;
  std::vector<std::string> logs{"corrected/intel.log.gz", "corrected/freiburg-079.log.gz"};  ///< under data_dir
  /// Instead of consecutive pairs of the corrected logs: the scan pairs of the Kuemmerle relations
  /// of the raw bags (their hand-checked relative poses as the truth), those at most
  /// `relation_max_m` and `relation_max_deg` apart.
  bool relations = false;
  double relation_max_m = 1.0;
  double relation_max_deg = 45.0;
};
void runMatchBenchmark(const std::string& data_dir, const MatchBenchOptions& options);

/// Options of the `match-map` subcommand (scan to map: odd scans against the even scans' map).
struct MatchMapBenchOptions {
  double sigma_xy_m = 0.1;           ///< RMS translation error of the perturbed guess [m]
  double sigma_theta_deg = 5.0;      ///< RMS rotation error of the perturbed guess [deg]
  std::uint64_t seed = 1;            ///< seed of the perturbation
  double resolution_m = 0.05;        ///< cell size of the log-odds map [m]
  std::vector<std::string> methods;  ///< lf, corr; empty = both
  std::vector<std::string> solvers;  ///< gn, ceres; empty = both
  std::vector<std::string> logs{"corrected/intel.log.gz", "corrected/freiburg-079.log.gz"};  ///< under data_dir
};
void runMatchMapBenchmark(const std::string& data_dir, const MatchMapBenchOptions& options);

/// Options of the `degeneracy` subcommand.
struct DegeneracyBenchOptions {
  degeneracy::Options options;  ///< detector options (defaults of the library)
  int beams = 541;              ///< simulated laser: beams over fov_deg
  double fov_deg = 270.0;       ///< simulated laser: field of view [deg]
  double max_range_m = 30.0;    ///< simulated laser: maximum range [m]
  std::uint64_t seed = 1;       ///< simulator seed
  bool verbose = false;         ///< list the simulated scans where the combination disagrees with the label
  double spacing_m = degeneracy::InputOptions{}.min_spacing_m;  ///< thinning of both detectors [m]
};
void runDegeneracyBenchmark(const std::string& data_dir, const DegeneracyBenchOptions& options);
/// Options of the `localize` subcommand.
struct LocalizeBenchOptions {
  /// Under data_dir: the seven corrected logs.
  std::vector<std::string> logs{"corrected/intel.log.gz",        "corrected/freiburg-079.log.gz",
                                "corrected/orebro.log.gz",       "corrected/belgioioso.log.gz",
                                "corrected/edmonton.log.gz",     "corrected/freiburg-101.log.gz",
                                "corrected/infinite-corridor.log.gz"};
  std::size_t stride = 1;            ///< localize every stride-th odd scan
  std::size_t baseline_stride = 20;  ///< branch-and-bound baseline on every n-th odd scan (0: skip)
  std::string save_maps;             ///< folder to write the even-scan maps to (empty: none)
  bool verbose = false;              ///< print every failure on stderr
  /// A tab-separated file with one line per query (every map): the outcome, the best candidate's
  /// score and fit, and the fits of the distinct alternatives (empty: none).
  std::string queries;
  /// The map from the even scans of the first half of each log only; every odd scan is still
  /// queried, so the second half holds scans in unmapped places (the answer there must be "unknown").
  bool half = false;
  bool extras = true;                ///< also the symmetric world and the ROS2 bag
  /// Also the calibration curve of each map: for score thresholds, the share of queries answered
  /// with a score at least the threshold, the success rate and the precision among those answers.
  bool calibration = false;
  /// Scans from other buildings: each log's map (its even scans) queried with this many scans,
  /// evenly spread, of every other log; every answer is wrong (0: skip, and the rest runs as usual).
  std::size_t other_buildings = 0;
  localization::DatabaseOptions db;
  localization::LocalizerOptions loc;
};
void runLocalizeBenchmark(const std::string& data_dir, const LocalizeBenchOptions& options);

/// Options of the `track` subcommand (track_bench.cpp): lifelong tracking and the AMCL baseline.
struct TrackBenchOptions {
  std::vector<std::string> logs{"corrected/intel.log.gz", "corrected/freiburg-079.log.gz"};  ///< under data_dir
  std::vector<std::string> maps{"half"};  ///< maps from the first half and/or the whole log: half, whole
  std::size_t passes = 10;                ///< times the log is tracked in a row by one Tracker (0: AMCL only)
  std::uint64_t seed = 1;                 ///< seed of the odometry noise (perturb --odom-model realistic)
  bool amcl = true;                       ///< also one pass of the AMCL-style baseline
  localization::TrackerOptions tracker;
  AmclOptions amcl_options;
  bool verbose = false;  ///< the AMCL filter's state after every scan on stderr
};
void runTrackBenchmark(const std::string& data_dir, const TrackBenchOptions& options);

}  // namespace lidar2d::bench
