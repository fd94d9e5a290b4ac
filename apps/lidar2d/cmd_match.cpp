// lidar2d match LOG --method p2p|p2l|lf|corr [--solver gn|ceres] [--init odom|identity] [--then p2p|p2l]
//   -o FILE [--eval]: aligns every scan to the previous one.
//
// For each consecutive pair (previous = target, current = source), both scans are turned into points
// in their robot frames (LaserScan::toPoints(T_robot_laser)), the initial guess is the odometry's
// relative motion T_prev_cur = odom_prev^-1 * odom_cur (or the identity), and the matcher estimates
// T_prev_cur. With --then, a second stage (ICP) starts from the first stage's estimate: "--method corr
// --then p2l" is the correlative search for large initial errors followed by point-to-line ICP (the
// correlative search's own likelihood-field refinement is then skipped). Output (io::readRelativePoses reads it): one line per pair,
//   t_prev t_cur dx dy dtheta converged iterations    [s, s, m, m, rad, 0/1, count]
// written atomically. --eval compares the pairs with the log's truth (eval::evaluatePairs: success =
// error < 10 cm and < 2 deg) and prints the success rate, median errors and time per pair.
// Pairs are matched on all cores (--threads); the output does not depend on the thread count.
// Exit codes: 1 for bad input (unreadable log, no odometry with --init odom, no truth with --eval,
// unwritable output; no output file appears then), 2 for usage errors.

#include <fmt/format.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <exception>
#include <iostream>
#include <map>
#include <memory>
#include <numbers>
#include <mutex>
#include <optional>
#include <thread>
#include <vector>

#include "commands.hpp"
#include "lidar2d/core/error.hpp"
#include "lidar2d/eval/metrics.hpp"
#include "lidar2d/io/atomic_file.hpp"
#include "lidar2d/io/prefetch.hpp"
#include "lidar2d/io/trajectory.hpp"
#include "lidar2d/registration/matcher.hpp"

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

// Calls f(i) for i in [0, n) on `threads` threads (the caller's included); rethrows the first
// exception after all have finished.
template <typename F>
void parallelFor(std::size_t n, unsigned threads, F&& f) {
  std::atomic<std::size_t> next{0};
  std::exception_ptr error;
  std::mutex error_mutex;
  auto work = [&] {
    try {
      for (std::size_t i; (i = next.fetch_add(1)) < n;) f(i);
    } catch (...) {
      const std::lock_guard<std::mutex> lock(error_mutex);
      if (!error) error = std::current_exception();
      next = n;
    }
  };
  std::vector<std::thread> pool;
  for (unsigned t = 1; t < threads && t < n; ++t) pool.emplace_back(work);
  work();
  for (auto& t : pool) t.join();
  if (error) std::rethrow_exception(error);
}

void run(const MatchArgs& a) {
  using Clock = std::chrono::steady_clock;
  const auto t_start = Clock::now();
  if (const std::string bad = a.options.icp.check(); !bad.empty())
    throw invalidArgument(fmt::format("invalid matcher option: {}", bad));
  registration::MatcherOptions then_options = a.options;
  if (a.then) {
    if (*a.then != registration::Method::kP2P && *a.then != registration::Method::kP2L)
      throw invalidArgument("--then must be an ICP method (p2p or p2l)");
    then_options.method = *a.then;
    if (a.options.method == registration::Method::kCorrelative) then_options.corr.refine = false;
  }
  registration::MatcherOptions first_options = a.options;
  if (a.then && a.options.method == registration::Method::kCorrelative) first_options.corr.refine = false;
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

  // Pairs are independent, so they are matched in chunks of frames, each chunk's targets prepared
  // and its pairs matched by all cores (the log reader runs on its own thread); results are
  // written in log order and equal a sequential run's.
  const unsigned threads = std::max(1u, std::min(a.threads, 64u));
  constexpr std::size_t kChunk = 128;
  std::optional<registration::PreparedTarget> prev, prev_then;  // the last frame of the previous chunk
  std::optional<Frame> prev_frame;
  std::vector<RelativePose> pairs;
  Trajectory truth;
  double match_s = 0.0;  // preparation and matching, summed over the threads
  std::size_t scans = 0, converged = 0;
  std::vector<Frame> chunk;
  bool more = true;
  while (more) {
    chunk.clear();
    while (chunk.size() < kChunk) {
      auto f = source->next();
      if (!f) {
        more = false;
        break;
      }
      ++scans;
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
      chunk.push_back(std::move(*f));
    }
    const std::size_t n = chunk.size();
    if (n == 0) break;
    std::vector<std::optional<registration::PreparedTarget>> targets(n), targets_then(n);
    std::vector<std::optional<registration::Result>> results(n);
    std::vector<double> seconds(n, 0.0);
    std::vector<char> second_stage(n, 0);  // the result is the --then stage's
    parallelFor(n, threads, [&](std::size_t i) {
      const auto t0 = Clock::now();
      targets[i].emplace(chunk[i].scan.toPoints(chunk[i].T_robot_laser), first_options);
      if (a.then) targets_then[i].emplace(targets[i]->points(), then_options);
      seconds[i] += std::chrono::duration<double>(Clock::now() - t0).count();
    });
    parallelFor(n, threads, [&](std::size_t i) {
      const Frame* before = i > 0 ? &chunk[i - 1] : (prev_frame ? &*prev_frame : nullptr);
      if (!before) return;  // the log's first scan
      const registration::PreparedTarget& target = i > 0 ? *targets[i - 1] : *prev;
      const auto t0 = Clock::now();
      const SE2 init = a.init == Init::kOdom ? before->T_odom_robot->inverse() * *chunk[i].T_odom_robot : SE2();
      registration::Result r = registration::matchScans(target, targets[i]->points(), init, first_options);
      if (a.then && r.status != registration::Status::kInvalidInput) {
        const registration::PreparedTarget& target_then = i > 0 ? *targets_then[i - 1] : *prev_then;
        r = registration::matchScans(target_then, targets[i]->points(), r.T_target_source, then_options);
        second_stage[i] = 1;
      }
      seconds[i] += std::chrono::duration<double>(Clock::now() - t0).count();
      results[i] = std::move(r);
    });
    for (std::size_t i = 0; i < n; ++i) {
      match_s += seconds[i];
      if (!results[i]) continue;
      const registration::Result& r = *results[i];
      if (r.status == registration::Status::kInvalidInput)
        throw invalidArgument(fmt::format("method {}: {}",
                                          registration::toString(second_stage[i] ? *a.then : a.options.method),
                                          r.message));
      const double t_before = i > 0 ? chunk[i - 1].time : prev_frame->time;
      const SE2& T = r.T_target_source;
      out.stream() << fmt::format("{:.9f} {:.9f} {:.9f} {:.9f} {:.9f} {} {}\n", t_before, chunk[i].time, T.x(), T.y(),
                                  T.theta(), r.converged ? 1 : 0, r.iterations);
      pairs.push_back({t_before, chunk[i].time, T, r.converged, r.iterations});
      converged += r.converged;
    }
    prev = std::move(targets[n - 1]);
    if (a.then) prev_then = std::move(targets_then[n - 1]);
    chunk[n - 1].scan = LaserScan();  // only the times and poses of the previous frame are needed
    prev_frame = std::move(chunk[n - 1]);
  }
  if (scans < 2) throw badInput(fmt::format("log has {} scan(s); matching needs at least 2", scans), ErrorLocation(a.log));
  out.commit();
  const double total_s = std::chrono::duration<double>(Clock::now() - t_start).count();
  const double per_pair_ms = 1e3 * match_s / static_cast<double>(pairs.size());  // CPU time per pair
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
                             pairs.size(), converged, registration::toString(a.options.method),
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
  const std::map<std::string, registration::Method> methods{{"p2p", registration::Method::kP2P},
                                                            {"p2l", registration::Method::kP2L},
                                                            {"lf", registration::Method::kLikelihoodField},
                                                            {"corr", registration::Method::kCorrelative}};
  sub->add_option("--method", a->options.method, "p2p (point-to-point ICP), p2l (point-to-line ICP), lf, corr")
      ->transform(CLI::CheckedTransformer(methods, CLI::ignore_case))
      ->default_str("p2l");
  const std::map<std::string, registration::Method> icp_methods{{"p2p", registration::Method::kP2P},
                                                                {"p2l", registration::Method::kP2L}};
  sub->add_option("--then", a->then,
                  "second stage from the first one's estimate: p2p or p2l ICP (e.g. --method corr --then p2l for large "
                  "initial errors; skips the correlative search's own refinement)")
      ->transform(CLI::CheckedTransformer(icp_methods, CLI::ignore_case));
  const std::map<std::string, registration::Solver> solvers{{"gn", registration::Solver::kGaussNewton},
                                                            {"ceres", registration::Solver::kCeres}};
  sub->add_option("--solver", a->options.solver, "gn (Gauss-Newton) or ceres (robust loss)")
      ->transform(CLI::CheckedTransformer(solvers, CLI::ignore_case))
      ->default_str("gn");
  const std::map<std::string, Init> inits{{"odom", Init::kOdom}, {"identity", Init::kIdentity}};
  sub->add_option("--init", a->init, "initial guess: odom (odometry's relative motion) or identity")
      ->transform(CLI::CheckedTransformer(inits, CLI::ignore_case))
      ->default_str("odom");
  sub->add_option("--max-dist", a->options.icp.max_correspondence_dist_m, "ICP: max correspondence distance [m]")
      ->capture_default_str();
  sub->add_option("--max-iterations", a->options.icp.max_iterations, "ICP: max iterations")->capture_default_str();
  sub->add_option("--point-pairs", a->options.icp.point_pair_weight,
                  "p2l: pair target points with no line (with two-point lines: only those without a neighbour) point "
                  "to point, with this weight; pins corridors, costs time (BENCHMARK.md); 0: none")
      ->capture_default_str();
  sub->add_flag_callback("--no-two-point-lines", [a] { a->options.icp.two_point_lines = false; },
                "p2l: drop the pairs whose target point fits no line (corners, clutter, short noisy walls) instead of "
                "pairing them with the line through it and a neighbour (Censi's two nearest points; BENCHMARK.md)");
  sub->add_option("--source-spacing", a->options.icp.min_source_spacing_m,
                  "ICP: leave out source points closer than this to the previous one kept [m]; 0 keeps all "
                  "(BENCHMARK.md)")
      ->capture_default_str();
  sub->add_flag("--eval", a->eval,
                "compare with the log's truth: success rate (< 10 cm and < 2 deg), median errors, ms per pair");
  sub->add_option("--threads", a->threads, "threads matching pairs (default: all cores)")->capture_default_str();
  sub->add_flag("-q,--quiet", a->quiet, "no summary on stderr");
  addReaderOptions(sub, a->reader);
  sub->callback([a] { run(*a); });
}

}  // namespace lidar2d::cli
