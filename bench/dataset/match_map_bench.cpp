// Scan-to-map matching on the corrected Radish logs: a log-odds map (5 cm cells) from the
// even-numbered scans at their truth poses, then every odd-numbered scan matched against it
// (registration::PreparedTarget::fromMap) from its truth pose perturbed by one step of
// OdometryNoise::constant (RMS 0.1 m and 5 degrees, as the scan-to-scan protocol), by the methods
// that match maps (likelihood field, correlative) and both solvers. A scan succeeds when its pose
// is within 10 cm and 2 degrees of the truth. Time per scan: the matching thread's CPU time of the
// match alone (the map's field or grids are prepared once per row, timed separately).

#include <fmt/format.h>

#include <chrono>
#include <cmath>
#include <filesystem>
#include <iostream>
#include <numbers>

#include "dataset_bench.hpp"
#include "lidar2d/core/error.hpp"
#include "lidar2d/eval/metrics.hpp"
#include "lidar2d/mapping/export.hpp"
#include "lidar2d/mapping/occupancy_map.hpp"
#include "lidar2d/registration/matcher.hpp"
#include "lidar2d/sim/noise.hpp"

namespace lidar2d::bench {
namespace {

constexpr double kDeg = std::numbers::pi / 180.0;

}  // namespace

void runMatchMapBenchmark(const std::string& data_dir, const MatchMapBenchOptions& bo) {
  using registration::Method;
  using registration::Solver;
  std::cout << "| dataset | method | solver | scans | success | median trans err [cm] | median rot err [deg] | "
               "median CPU ms/scan | prepare ms | not converged |\n";
  std::cout << "|---|---|---|---|---|---|---|---|---|---|\n";
  const sim::OdometryNoise noise = sim::OdometryNoise::constant(bo.sigma_xy_m / std::sqrt(2.0), bo.sigma_xy_m / std::sqrt(2.0),
                                                                bo.sigma_theta_deg * kDeg);
  for (const auto& rel : bo.logs) {
    const std::string path = (std::filesystem::path(data_dir) / rel).string();
    const std::string name = std::filesystem::path(rel).stem().stem().string();
    if (!std::filesystem::exists(path)) {
      std::cout << "| " << rel << " | missing: skipped | | | | | | | | |\n";
      continue;
    }
    const std::vector<Frame> frames = loadFrames(path);
    mapping::MapOptions mo;
    mo.resolution_m = bo.resolution_m;
    const OccupancyImage image = mapping::toOccupancyImage(*evenFramesMap(frames, path, mapping::MapModel::kLogOdds, mo));
    // The odd scans (robot frame) and their perturbed guesses, the same for every row.
    std::vector<Points2> points;
    std::vector<SE2> truth, guess;
    sim::Rng rng(bo.seed);
    for (std::size_t i = 1; i < frames.size(); i += 2) {
      points.push_back(frames[i].scan.toPoints(frames[i].T_robot_laser));
      truth.push_back(*frames[i].T_world_robot);
      guess.push_back(truth.back() * sim::noisyOdometryStep(SE2(), noise, rng));
    }
    for (const Method method : {Method::kLikelihoodField, Method::kCorrelative}) {
      if (!wanted(bo.methods, registration::toString(method))) continue;
      for (const Solver solver : {Solver::kGaussNewton, Solver::kCeres}) {
        if (!wanted(bo.solvers, registration::toString(solver))) continue;
        registration::MatcherOptions o;
        o.method = method;
        o.solver = solver;
        const auto t0 = std::chrono::steady_clock::now();
        const auto target = registration::PreparedTarget::fromMap(image, o);
        const double prepare_ms = 1e3 * std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
        if (!target.error().empty()) throw invalidArgument(target.error());
        std::vector<double> ms, trans, rot;
        std::size_t ok = 0, not_converged = 0;
        for (std::size_t k = 0; k < points.size(); ++k) {
          const double c0 = threadCpuSeconds();
          const registration::Result r = registration::matchScans(target, points[k], guess[k], o);
          ms.push_back(1e3 * (threadCpuSeconds() - c0));
          const SE2 e = truth[k].inverse() * r.T_target_source;
          trans.push_back(e.translation().norm());
          rot.push_back(std::abs(e.theta()));
          ok += trans.back() < 0.1 && rot.back() < 2.0 * kDeg;
          not_converged += !r.converged;
        }
        std::cout << fmt::format("| {} | {} | {} | {} | {:.1f}% | {:.2f} | {:.3f} | {:.3f} | {:.0f} | {} |\n", name,
                                 registration::toString(method), registration::toString(solver), points.size(),
                                 100.0 * static_cast<double>(ok) / static_cast<double>(points.size()),
                                 100.0 * eval::percentile(trans, 0.5), eval::percentile(rot, 0.5) / kDeg,
                                 eval::percentile(ms, 0.5), prepare_ms, not_converged);
      }
    }
  }
}

}  // namespace lidar2d::bench
