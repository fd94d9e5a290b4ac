// lidar2d_dataset_bench: accuracy and speed of lidar2d's algorithms on the real logs, as tables.
//   lidar2d_dataset_bench map [--data DIR]
//   lidar2d_dataset_bench degeneracy [--data DIR] [--beams N] [--fov DEG] [-v]
//   lidar2d_dataset_bench localize [--data DIR] [--stride N] [--baseline-stride N]
//   lidar2d_dataset_bench match [--data DIR] [--sigma-xy M] [--sigma-theta DEG] [--seed N] [--methods p2p p2l ...]
//   lidar2d_dataset_bench match --relations [--truth-check]   (the raw bags' Kuemmerle relations as pairs)
//   lidar2d_dataset_bench match-map [--data DIR] [--methods lf corr] [--solvers gn ceres]   (scan to map)
//   lidar2d_dataset_bench track [--data DIR] [--logs ...] [--passes 10] [--maps half whole] [--no-amcl]

#include <CLI/CLI.hpp>
#include <cstdlib>
#include <iostream>

#include "dataset_bench.hpp"
#include "lidar2d/core/error.hpp"

int main(int argc, char** argv) {
  CLI::App app{"lidar2d dataset benchmark: accuracy and speed on ../shared/data"};
  std::string data = LIDAR2D_DEFAULT_DATA_DIR;
  if (const char* env = std::getenv("LIDAR2D_DATA_DIR"); env && *env) data = env;
  app.add_option("--data", data, "folder holding corrected/, raw/, ... (default ../shared/data or $LIDAR2D_DATA_DIR)");
  app.require_subcommand(1);
  auto* map = app.add_subcommand("map", "mapping: ms per scan, cell updates per second, even/odd map consistency");
  map->callback([&] { lidar2d::bench::runMapBenchmark(data); });
  lidar2d::bench::MatchBenchOptions match_options;
  auto* match = app.add_subcommand("match", "scan matching: success rate, median errors and ms per pair, per method and solver");
  match->add_option("--sigma-xy", match_options.sigma_xy_m, "RMS translation error of the perturbed guess [m]")->capture_default_str();
  match->add_option("--sigma-theta", match_options.sigma_theta_deg, "RMS rotation error of the perturbed guess [deg]")->capture_default_str();
  match->add_option("--seed", match_options.seed, "seed of the perturbation")->capture_default_str();
  match->add_option("--methods", match_options.methods, "methods to run (p2p p2l lf corr; default all)");
  match->add_option("--solvers", match_options.solvers, "solvers to run (gn ceres; default all)");
  match->add_option("--inits", match_options.inits, "initial guesses: perturbed identity truth")->capture_default_str();
  match->add_option("--logs", match_options.logs, "logs under --data")->capture_default_str();
  match->add_option("--max-dist", match_options.icp.max_correspondence_dist_m, "ICP max correspondence distance [m]")->capture_default_str();
  match->add_option("--trim", match_options.icp.trim_keep_fraction, "ICP trim keep fraction")->capture_default_str();
  match->add_option("--loss-scale", match_options.icp.loss.scale_m, "robust loss scale [m]")->capture_default_str();
  match->add_option("--point-pairs", match_options.icp.point_pair_weight,
                    "point-to-line: weight of point pairs for target points with no line (0: none)")
      ->capture_default_str();
  match->add_option("--two-point-lines", match_options.icp.two_point_lines,
                    "point-to-line: target points with no line fit pair with the line to a neighbour (1) or not (0)")
      ->capture_default_str();
  match->add_option("--source-spacing", match_options.icp.min_source_spacing_m,
                    "ICP: leave out source points closer than this to the previous one kept [m] (0: keep all)")
      ->capture_default_str();
  match->add_option("--loss", match_options.icp.loss.kind, "robust loss: 0 none, 1 huber, 2 cauchy")->capture_default_str();
  match->add_option("--normal-k", match_options.icp.normal_neighbors, "points per line fit")->capture_default_str();
  match->add_option("--flatness", match_options.icp.max_line_flatness, "max line flatness")->capture_default_str();
  match->add_option("--max-iterations", match_options.icp.max_iterations, "ICP max iterations")->capture_default_str();
  match->add_option("--gn-inner", match_options.icp.gn_inner_iterations, "Gauss-Newton steps per correspondence search")->capture_default_str();
  match->add_option("--ceres-inner", match_options.icp.ceres_max_inner_iterations,
                    "ICP: Ceres iterations per correspondence search")
      ->capture_default_str();
  match->add_option("--eps-m", match_options.icp.translation_eps_m,
                    "ICP translation convergence threshold [m] (default: 1e-3 for p2l, 1e-4 for p2p)");
  match->add_option("--eps-rad", match_options.icp.rotation_eps_rad,
                    "ICP rotation convergence threshold [rad] (default: 1e-3 for p2l, 1e-4 for p2p)");
  match->add_option("--search", match_options.icp.neighbor_search, "ICP nearest-neighbour search: 0 bearing walk, 1 k-d tree")->capture_default_str();
  match->add_flag("--truth-check", match_options.truth_check,
                  "match each pair from the truth with p2p, p2l and lf: pairs where all three fail but agree");
  match->add_option("--lf-levels", match_options.lf.levels, "likelihood field: resolutions")->capture_default_str();
  match->add_option("--lf-max-iterations", match_options.lf.max_iterations, "likelihood field: iterations per level")
      ->capture_default_str();
  match->add_option("--corr-window-m", match_options.corr.linear_window_m, "correlative linear half-window [m]")->capture_default_str();
  match->add_option("--corr-window-rad", match_options.corr.angular_window_rad, "correlative angular half-window [rad]")->capture_default_str();
  match->add_flag("--relations", match_options.relations,
                  "the scan pairs of the raw bags' Kuemmerle relations instead of consecutive corrected pairs");
  match->add_option("--relation-max-m", match_options.relation_max_m, "--relations: largest translation of a pair [m]")
      ->capture_default_str();
  match->add_option("--relation-max-deg", match_options.relation_max_deg, "--relations: largest rotation of a pair [deg]")
      ->capture_default_str();
  match->callback([&] { lidar2d::bench::runMatchBenchmark(data, match_options); });
  lidar2d::bench::MatchMapBenchOptions mm_options;
  auto* mm = app.add_subcommand("match-map", "scan to map: odd scans matched against the even scans' map (lf, corr)");
  mm->add_option("--sigma-xy", mm_options.sigma_xy_m, "RMS translation error of the perturbed guess [m]")->capture_default_str();
  mm->add_option("--sigma-theta", mm_options.sigma_theta_deg, "RMS rotation error of the perturbed guess [deg]")->capture_default_str();
  mm->add_option("--seed", mm_options.seed, "seed of the perturbation")->capture_default_str();
  mm->add_option("--resolution", mm_options.resolution_m, "map cell size [m]")->capture_default_str();
  mm->add_option("--methods", mm_options.methods, "methods to run (lf corr; default both)");
  mm->add_option("--solvers", mm_options.solvers, "solvers to run (gn ceres; default both)");
  mm->add_option("--logs", mm_options.logs, "logs under --data")->capture_default_str();
  mm->callback([&] { lidar2d::bench::runMatchMapBenchmark(data, mm_options); });
  lidar2d::bench::DegeneracyBenchOptions deg_options;
  auto* deg = app.add_subcommand(
      "degeneracy", "degeneracy detection: precision/recall on simulated worlds, flagged share of real logs, ms per scan");
  deg->add_option("--beams", deg_options.beams, "simulated laser: number of beams")->capture_default_str();
  deg->add_option("--fov", deg_options.fov_deg, "simulated laser: field of view [deg]")->capture_default_str();
  deg->add_option("--max-range", deg_options.max_range_m, "simulated laser: maximum range [m]")->capture_default_str();
  deg->add_option("--seed", deg_options.seed, "simulator seed")->capture_default_str();
  deg->add_option("--geo-threshold", deg_options.options.geometric.threshold, "geometric detector threshold")->capture_default_str();
  deg->add_option("--info-threshold", deg_options.options.information.threshold, "information detector threshold")->capture_default_str();
  deg->add_option("--eps", deg_options.options.geometric.cluster_eps_m, "DBSCAN radius near the sensor [m]")->capture_default_str();
  deg->add_option("--spacing", deg_options.spacing_m, "thinning: minimum point spacing [m] (both detectors)")->capture_default_str();
  deg->add_flag("-v,--verbose", deg_options.verbose, "list the simulated scans the combination gets wrong (stderr)");
  deg->callback([&] {
    deg_options.options.geometric.input.min_spacing_m = deg_options.options.information.input.min_spacing_m =
        deg_options.spacing_m;
    lidar2d::bench::runDegeneracyBenchmark(data, deg_options);
  });
  lidar2d::bench::LocalizeBenchOptions loc_options;
  auto* loc = app.add_subcommand("localize", "global localization: success, precision, decline rate, ms per query; B&B baseline");
  loc->add_option("--logs", loc_options.logs, "logs under --data")->capture_default_str();
  loc->add_option("--stride", loc_options.stride, "localize every n-th odd scan")->capture_default_str();
  loc->add_option("--baseline-stride", loc_options.baseline_stride, "B&B baseline on every n-th odd scan (0: skip)")->capture_default_str();
  loc->add_option("--save-maps", loc_options.save_maps, "write the even-scan maps (PREFIX-even.yaml/pgm) to this folder");
  loc->add_option("--step", loc_options.db.step_m, "database grid step [m]")->capture_default_str();
  loc->add_option("--min-score", loc_options.loc.min_score, "decline below this score")->capture_default_str();
  loc->add_option("--ambiguity", loc_options.loc.ambiguity_ratio, "ambiguity ratio")->capture_default_str();
  loc->add_option("--candidates", loc_options.loc.max_candidates, "candidates verified")->capture_default_str();
  loc->add_option("--key-radius", loc_options.loc.key_radius_m, "key search radius")->capture_default_str();
  loc->add_option("--refined", loc_options.loc.max_refined, "candidates refined")->capture_default_str();
  loc->add_option("--bin", loc_options.loc.vote_bin_m, "vote bin [m]")->capture_default_str();
  loc->add_option("--profile-bins", loc_options.db.profile_bins, "range-profile sectors per position (0: no profiles)")->capture_default_str();
  loc->add_option("--profile-candidates", loc_options.loc.profile_candidates, "candidates from the range profiles (0: off)")->capture_default_str();
  loc->add_flag("--fallback", loc_options.loc.fallback_branch_and_bound, "branch-and-bound fallback");
  loc->add_flag("-v,--verbose", loc_options.verbose, "print each failure");
  loc->add_flag("--half", loc_options.half,
                "map from the first half of each log only: the second half's queries are in unmapped places");
  loc->add_option("--queries", loc_options.queries,
                  "write one tab-separated line per query (outcome, score, fit, the alternatives' fits, the points "
                  "scored) to this file");
  loc->add_flag("--calibration", loc_options.calibration,
                "also the score-threshold curve per map (answered, success, precision)");
  loc->add_flag("!--no-extras", loc_options.extras, "only the logs (not the symmetric world and the ROS2 bag)");
  loc->add_option("--other-buildings", loc_options.other_buildings,
                  "only this: each log's even-scan map queried with N scans of every other log (all answers are "
                  "wrong); answered, and answered with a score >= 0.7 / 0.8");
  loc->add_option("--budget-ms", loc_options.loc.budget_ms, "whole-map search budget per query [ms] (0: none)")->capture_default_str();
  loc->add_option("--regions", loc_options.loc.max_regions, "candidate regions searched by branch and bound (0: none)")->capture_default_str();
  loc->add_option("--confident", loc_options.loc.confident_score, "answers scoring this skip the region search")->capture_default_str();
  loc->callback([&] { lidar2d::bench::runLocalizeBenchmark(data, loc_options); });
  lidar2d::bench::TrackBenchOptions track_options;
  auto* track = app.add_subcommand(
      "track", "tracking: one log tracked N times in a row (accuracy, RSS per pass); AMCL-style baseline");
  track->add_option("--logs", track_options.logs, "logs under --data")->capture_default_str();
  track->add_option("--maps", track_options.maps, "maps from the log's first half and/or all of it: half whole")
      ->capture_default_str();
  track->add_option("--passes", track_options.passes, "passes of one tracker over the log (0: baseline only)")
      ->capture_default_str();
  track->add_option("--seed", track_options.seed, "seed of the odometry noise")->capture_default_str();
  track->add_flag("!--no-amcl", track_options.amcl, "skip the AMCL-style baseline");
  track
      ->add_option("--amcl-particles", track_options.amcl_options.global_particles,
                   "AMCL: particles of the uniform start")
      ->capture_default_str();
  track
      ->add_option("--amcl-tracking-particles", track_options.amcl_options.tracking_particles,
                   "AMCL: particles once converged")
      ->capture_default_str();
  track->add_option("--amcl-beams", track_options.amcl_options.beams, "AMCL: scan points per update")
      ->capture_default_str();
  track->add_option("--amcl-sigma-hit", track_options.amcl_options.sigma_hit_m, "AMCL: likelihood field sigma [m]")
      ->capture_default_str();
  track->add_flag("-v,--verbose", track_options.verbose, "print the AMCL filter's state after every scan (stderr)");
  track->callback([&] { lidar2d::bench::runTrackBenchmark(data, track_options); });
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e) == 0 ? 0 : 2;
  } catch (const lidar2d::Error& e) {
    std::cerr << "lidar2d_dataset_bench: error: " << e.what() << "\n";
    return 1;
  }
  return 0;
}
