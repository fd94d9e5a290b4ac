// lidar2d match LOG --method p2p|p2l|lf|corr [--solver gn|ceres] [--init odom|identity] [--then p2p|p2l]
//   -o FILE [--eval]: aligns every scan to the previous one (registration::SequenceMatcher).
//
// For each consecutive pair (previous = target, current = source) the matcher estimates T_prev_cur,
// from the odometry's relative motion or the identity; with --then, ICP refines it ("--method corr
// --then p2l": the correlative search for large initial errors, then point-to-line ICP). Output
// (io::readRelativePoses reads it): one line per pair,
//   t_prev t_cur dx dy dtheta converged iterations    [s, s, m, m, rad, 0/1, count]
// written atomically. --eval compares the pairs with the log's truth (eval::evaluatePairs: success =
// error < 10 cm and < 2 deg) and prints the success rate, median errors and time per pair.
// Pairs are matched on all cores (--threads); the output does not depend on the thread count.
// Exit codes: 1 for bad input (unreadable log, no odometry with --init odom, no truth with --eval,
// unwritable output; no output file appears then), 2 for usage errors.

#include <fmt/format.h>

#include <algorithm>
#include <chrono>
#include <iostream>
#include <map>
#include <memory>
#include <numbers>
#include <optional>
#include <thread>
#include <vector>

#include "commands.hpp"
#include "progress.hpp"
#include "lidar2d/core/error.hpp"
#include "lidar2d/core/frame.hpp"
#include "lidar2d/core/trajectory.hpp"
#include "lidar2d/eval/metrics.hpp"
#include "lidar2d/io/atomic_file.hpp"
#include "lidar2d/io/prefetch.hpp"
#include "lidar2d/registration/matcher.hpp"
#include "lidar2d/registration/sequence_matcher.hpp"

namespace lidar2d::cli {
namespace {

enum class Init { kOdom, kIdentity };

struct MatchArgs {
  std::string log;
  std::string output;
  registration::MatcherOptions options;
  std::optional<registration::Method> then;  // second stage (ICP) from the first stage's estimate
  Init init = Init::kOdom;
  bool eval = false;
  bool quiet = false;
  unsigned threads = std::max(1u, std::thread::hardware_concurrency());
  io::ReaderOptions reader;
};

void run(const MatchArgs& a) {
  const CreatedFolders out_folders = prepareOutputFile(a.output);
  using Clock = std::chrono::steady_clock;
  const auto t_start = Clock::now();
  registration::SequenceOptions so;
  so.matcher = a.options;
  so.then = a.then;
  so.init = a.init == Init::kOdom ? registration::odometryGuess : registration::identityGuess;
  so.threads = a.threads;
  const registration::SequenceMatcher matcher(so);  // checks the options
  auto source = io::prefetch(io::openLog(a.log, a.reader));
  io::AtomicFile out(a.output);
  out.stream() << fmt::format(
      "# lidar2d match: method={}{} solver={} init={}{}{}{}\n", registration::toString(a.options.method),
      a.then ? std::string(" then ") + registration::toString(*a.then) : std::string(),
      registration::toString(a.options.solver), a.init == Init::kOdom ? "odom" : "identity",
      a.options.icp.point_pair_weight > 0 ? fmt::format(" point_pairs={}", a.options.icp.point_pair_weight)
                                          : std::string(),
      a.options.icp.two_point_lines ? "" : " two_point_lines=0",
      a.options.icp.min_source_spacing_m != registration::IcpOptions{}.min_source_spacing_m
          ? fmt::format(" source_spacing={}", a.options.icp.min_source_spacing_m)
          : std::string());
  out.stream() << "# t_prev t_cur dx dy dtheta converged iterations\n";

  // Frames are checked as they are read, so that the error names the log.
  Trajectory truth;
  const auto next_frame = [&]() -> std::optional<Frame> {
    std::optional<Frame> f = source->next();
    if (!f) return f;
    if (a.init == Init::kOdom && !f->T_odom_robot)
      throw badInput(fmt::format("scan {} (time {:.6f}) has no odometry (use --init identity)", f->index, f->time),
                     ErrorLocation(a.log));
    if (a.eval) {
      if (!f->T_world_robot)
        throw badInput(fmt::format("scan {} (time {:.6f}) has no ground-truth pose; --eval needs a log with truth",
                                   f->index, f->time),
                       ErrorLocation(a.log));
      truth.push_back({f->time, *f->T_world_robot});
    }
    return f;
  };
  std::vector<RelativePose> pairs;
  const auto write_pair = [&](const registration::SequencePair& p) {
    const registration::Result& r = p.result;
    if (r.status == registration::Status::kInvalidInput)
      throw invalidArgument(
          fmt::format("method {}: {}", registration::toString(p.refined ? *a.then : a.options.method), r.message));
    const SE2& T = r.T_target_source;
    out.stream() << fmt::format("{:.9f} {:.9f} {:.9f} {:.9f} {:.9f} {} {}\n", p.t_prev, p.t_cur, T.x(), T.y(),
                                T.theta(), r.converged ? 1 : 0, r.iterations);
    pairs.push_back({p.t_prev, p.t_cur, T, r.converged, r.iterations});
  };
  std::optional<std::size_t> total_pairs;
  if (const auto n = source->sizeHint(); n && *n > 0) total_pairs = *n - 1;
  RateProgress progress(a.quiet, "matching", "pairs", total_pairs);
  const registration::SequenceSummary summary =
      matcher.run(next_frame, write_pair, [&progress](std::size_t done) { progress.update(done); });
  progress.clear();
  if (summary.frames < 2)
    throw badInput(fmt::format("log has {} scan(s); matching needs at least 2", summary.frames), ErrorLocation(a.log));
  out.commit();
  warnAboutLog(a.log, *source);
  const double total_s = std::chrono::duration<double>(Clock::now() - t_start).count();
  const double per_pair_ms = 1e3 * summary.wall_s / static_cast<double>(pairs.size());  // on one core
  if (a.eval) {
    const eval::PairsResult e = eval::evaluatePairs(pairs, truth);
    constexpr double kDeg = 180.0 / std::numbers::pi;
    std::cout << fmt::format("pairs: {}\n", e.count);
    std::cout << fmt::format("converged: {}\n", e.converged);
    std::cout << fmt::format("success rate: {:.1f}% (error < 10 cm and < 2 deg)\n", 100.0 * e.success_rate);
    std::cout << fmt::format("median translation error: {:.2f} cm\n", 100.0 * e.trans_m.median);
    std::cout << fmt::format("median rotation error: {:.3f} deg\n", e.rot_rad.median * kDeg);
    std::cout << fmt::format("ms per pair: {:.3f} (preparation and matching on one core, parsing excluded)\n",
                             per_pair_ms);
  }
  if (!a.quiet)
    std::cerr << fmt::format("matched {} pairs ({} converged) with {}{}/{} in {:.3f} s ({:.3f} ms per pair) -> {}\n",
                             pairs.size(), summary.converged, registration::toString(a.options.method),
                             a.then ? std::string(" then ") + registration::toString(*a.then) : std::string(),
                             registration::toString(a.options.solver), total_s, per_pair_ms, a.output);
}

}  // namespace

void addMatchCommand(CLI::App& app) {
  auto a = std::make_shared<MatchArgs>();
  auto* sub = app.add_subcommand(
      "match",
      "Align each scan to the previous one; writes 't_prev t_cur dx dy dtheta converged iterations' per pair (the pose "
      "of the current scan's robot in the previous one's frame [s, s, m, m, rad])");
  sub->add_option("LOG", a->log, "log file (any format lidar2d reads)")->required();
  sub->add_option("-o,--output", a->output, "output file of relative poses")->required();
  addChoice<registration::Method>(sub, "--method", a->options.method,
                                  {{"p2p", registration::Method::kP2P},
                                   {"p2l", registration::Method::kP2L},
                                   {"lf", registration::Method::kLikelihoodField},
                                   {"corr", registration::Method::kCorrelative}},
                                  "p2p (point-to-point ICP), p2l (point-to-line ICP), lf, corr")
      ->default_str("p2l");
  addChoice<registration::Method>(
      sub, "--then", a->then, {{"p2p", registration::Method::kP2P}, {"p2l", registration::Method::kP2L}},
      "second stage from the first one's estimate: p2p or p2l ICP (e.g. --method corr --then p2l for large "
      "initial errors; skips the correlative search's own refinement)")
      ->default_str("none");
  addChoice<registration::Solver>(sub, "--solver", a->options.solver,
                                  {{"gn", registration::Solver::kGaussNewton}, {"ceres", registration::Solver::kCeres}},
                                  "gn (Gauss-Newton) or ceres (robust loss)")
      ->default_str("gn");
  addChoice<Init>(sub, "--init", a->init, {{"odom", Init::kOdom}, {"identity", Init::kIdentity}},
                  "initial guess: odom (odometry's relative motion) or identity")
      ->default_str("odom");
  sub->add_option("--max-dist", a->options.icp.max_correspondence_dist_m, "ICP: max correspondence distance [m]")
      ->capture_default_str();
  sub->add_option("--max-iterations", a->options.icp.max_iterations, "ICP: max iterations")->capture_default_str();
  sub->add_option("--point-pairs", a->options.icp.point_pair_weight,
                  "p2l: pair target points with no line (with two-point lines: only those without a neighbour) point "
                  "to point, with this weight; pins corridors, costs time (docs/matching.md); 0: none")
      ->capture_default_str();
  sub->add_flag_callback("--no-two-point-lines", [a] { a->options.icp.two_point_lines = false; },
                "p2l: drop the pairs whose target point fits no line (corners, clutter, short noisy walls) instead of "
                "pairing them with the line through it and a neighbour (Censi's two nearest points; docs/matching.md)");
  sub->add_option("--source-spacing", a->options.icp.min_source_spacing_m,
                  "ICP: leave out source points closer than this to the previous one kept [m]; 0 keeps all "
                  "(docs/matching.md)")
      ->capture_default_str();
  sub->add_flag("--eval", a->eval,
                "compare with the log's truth: success rate (< 10 cm and < 2 deg), median errors, ms per pair");
  sub->add_option("--threads", a->threads, "threads matching pairs (default: all cores)")->capture_default_str();
  sub->add_flag("-q,--quiet", a->quiet, "no summary on stderr");
  addReaderOptions(sub, a->reader);
  sub->callback([a] { run(*a); });
}

}  // namespace lidar2d::cli
