// lidar2d perturb LOG --odom-noise SX,SY,STH --seed N -o LOG2: replaces a log's odometry by odometry
// derived from its truth with drifting noise, keeping truth, scans and laser mounting.
//
// Noise model (one implementation, shared with the simulator: sim::noisyOdometryStep with
// sim::OdometryNoise::constant(SX, SY, STH)):
//   odom_0 = truth_0
//   odom_k = odom_{k-1} * (truth_{k-1}^-1 * truth_k) * SE2(n_x, n_y, n_theta),
//   (n_x, n_y, n_theta) ~ N(0, diag(SX^2, SY^2, STH^2)) independently for every scan step,
// with SX, SY in metres (robot frame: x forward, y left) and STH in radians, per scan step (not per
// metre or second). The errors accumulate: the odometry drifts like a random walk.
//
// Exit codes: a malformed --odom-noise is a usage error (2); a log without ground truth, an
// unreadable log or an unwritable output is bad input (1), and then no output file appears.

#include <fmt/format.h>

#include <cmath>
#include <iostream>
#include <memory>
#include <numbers>
#include <sstream>

#include "commands.hpp"
#include "lidar2d/core/error.hpp"
#include "lidar2d/io/carmen_writer.hpp"
#include "lidar2d/io/frame_source.hpp"
#include "lidar2d/sim/noise.hpp"

namespace lidar2d::cli {
namespace {

bool parseSigmas(const std::string& s, double out[3]) {
  std::stringstream ss(s);
  std::string part;
  int n = 0;
  while (std::getline(ss, part, ',')) {
    if (n == 3 || part.empty()) return false;
    char* end = nullptr;
    const double v = std::strtod(part.c_str(), &end);
    if (end == part.c_str() || *end != '\0' || !std::isfinite(v) || v < 0) return false;
    out[n++] = v;
  }
  return n == 3 && s.back() != ',';
}

struct PerturbArgs {
  std::string log;
  std::string output;
  std::string odom_noise = "0.01,0.005,0.002";
  std::uint64_t seed = 1;
  io::ReaderOptions reader;
};

void run(const PerturbArgs& a) {
  double s[3];
  parseSigmas(a.odom_noise, s);  // validated by the option's check
  const sim::OdometryNoise noise = sim::OdometryNoise::constant(s[0], s[1], s[2]);
  sim::Rng rng(a.seed);
  auto source = io::openLog(a.log, a.reader);
  io::CarmenWriter writer(a.output);
  writer.comment(fmt::format(
      "lidar2d perturb: source={} odom_noise=[{},{},{}] seed={}: odom_k = odom_(k-1) * (truth_(k-1)^-1 * truth_k) * "
      "SE2(n), n ~ N(0, diag(SX^2, SY^2, STH^2)) per scan step [m, m, rad]",
      a.log, s[0], s[1], s[2], a.seed));
  std::optional<SE2> prev_truth;
  SE2 odom;
  std::size_t count = 0;
  while (auto f = source->next()) {
    if (!f->T_world_robot)
      throw badInput(fmt::format("scan {} (time {:.6f}) has no ground-truth pose; perturb needs a log with truth "
                                 "(TRUEPOS lines, or a SLAM-corrected CARMEN log)",
                                 f->index, f->time),
                     ErrorLocation(a.log));
    const SE2 truth = *f->T_world_robot;
    odom = prev_truth ? odom * sim::noisyOdometryStep(prev_truth->inverse() * truth, noise, rng) : truth;
    prev_truth = truth;
    f->T_odom_robot = odom;
    writer.write(*f);
    ++count;
  }
  if (count == 0) throw badInput("log has no scans", ErrorLocation(a.log));
  writer.commit();
  const double err = (odom.translation() - prev_truth->translation()).norm();
  std::cout << fmt::format("perturbed {} scans: final odometry error {:.3f} m, {:.2f} deg -> {}\n", count, err,
                           std::abs(angleDiff(odom.theta(), prev_truth->theta())) * 180.0 / std::numbers::pi,
                           a.output);
}

}  // namespace

void addPerturbCommand(CLI::App& app) {
  auto a = std::make_shared<PerturbArgs>();
  auto* sub = app.add_subcommand(
      "perturb",
      "Replace a log's odometry by its truth with drifting noise: odom_k = odom_(k-1) * (truth_(k-1)^-1 * truth_k) "
      "* noise_k, noise_k ~ N(0, diag(SX^2, SY^2, STH^2)) per scan step; odom_0 = truth_0. Keeps truth, scans and "
      "laser mounting; writes a CARMEN log with TRUEPOS lines. The log must have truth.");
  sub->add_option("LOG", a->log, "input log with ground truth (any format lidar2d reads)")->required();
  sub->add_option("-o,--output", a->output, "output CARMEN log")->required();
  sub->add_option("--odom-noise", a->odom_noise,
                  "SX,SY,STH: std of the per-scan-step odometry error, x forward and y left in metres, heading in "
                  "radians (per scan step, not per metre)")
      ->capture_default_str()
      ->check(CLI::Validator(
          [](std::string& v) -> std::string {
            double s[3];
            return parseSigmas(v, s) ? std::string()
                                     : fmt::format("expected SX,SY,STH: three comma-separated non-negative numbers, "
                                                   "got '{}'",
                                                   v);
          },
          "SX,SY,STH"));
  sub->add_option("--seed", a->seed, "random seed (std::mt19937_64)")->capture_default_str();
  addReaderOptions(sub, a->reader);
  sub->callback([a] { run(*a); });
}

}  // namespace lidar2d::cli
