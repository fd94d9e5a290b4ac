// lidar2d_dataset_bench: accuracy and speed of lidar2d's algorithms on the real logs, as tables.
//   lidar2d_dataset_bench map [--data DIR]
//   lidar2d_dataset_bench match [--data DIR] [--sigma-xy M] [--sigma-theta DEG] [--seed N] [--methods p2p p2l ...]

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
  match->callback([&] { lidar2d::bench::runMatchBenchmark(data, match_options); });
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
