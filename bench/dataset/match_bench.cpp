// Scan matching on the corrected Radish logs (protocol of ../shared/DESIGN.md): the truth's
// relative motion of each consecutive pair is perturbed in memory by one step of the odometry noise
// model (sim::noisyOdometryStep with OdometryNoise::constant), giving an initial guess off by
// about 0.1 m and 5 degrees (RMS), and each pair is matched (source = current scan, target =
// previous scan, both in the robot frame). Also from the identity. A pair succeeds when its error is
// under 10 cm and 2 degrees (eval::evaluatePairs). Time per pair = target preparation (k-d tree,
// normals, fields) + matching, on one core, parsing excluded: the thread's CPU time (the machine
// may be shared), with the wall time of all pairs in "total wall s".
// With --relations, the pairs are instead those of the Kuemmerle relations of the raw bags (a
// second, hand-checked truth; success and errors only, no timing).

#include <fmt/format.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <iostream>
#include <cstdlib>
#include <ctime>
#include <numbers>
#include <optional>

#include "dataset_bench.hpp"
#include "lidar2d/eval/metrics.hpp"
#include "lidar2d/io/frame_source.hpp"
#include "lidar2d/io/trajectory.hpp"
#include "lidar2d/registration/correlative.hpp"
#include "lidar2d/registration/matcher.hpp"
#include "lidar2d/registration/sequence_matcher.hpp"
#include "lidar2d/sim/noise.hpp"

namespace lidar2d::bench {
namespace {

constexpr double kDeg = std::numbers::pi / 180.0;

struct Row {
  eval::PairsResult eval;
  double median_ms = 0.0;
  double total_s = 0.0;
  std::size_t not_converged = 0;
};

// The success bar of the protocol: under 10 cm and 2 degrees.
bool withinBar(const SE2& error) { return error.translation().norm() < 0.1 && std::abs(error.theta()) < 2.0 * kDeg; }

// Matches every frame to the previous one (registration::SequenceMatcher on one thread) from
// inits[k], frame k's guess. `then`: an ICP refine stage from the first stage's estimate (for example
// correlative search, then point-to-line ICP); its target preparation is timed too.
Row runPairs(const std::vector<Frame>& frames, const std::vector<Points2>& points, const std::vector<SE2>& inits,
             const Trajectory& truth, const registration::MatcherOptions& options,
             std::optional<registration::Method> then = std::nullopt) {
  Row row;
  std::vector<RelativePose> pairs;
  std::vector<double> ms;
  pairs.reserve(frames.size());
  ms.reserve(frames.size());
  registration::SequenceOptions so;
  so.matcher = options;
  so.then = then;
  // Frame::index is the position in `frames`, which hold the whole log.
  so.init = [&inits](const Frame&, const Frame& cur) { return inits[cur.index]; };
  so.threads = 1;  // per-pair CPU times on one core
  const registration::SequenceSummary summary =
      registration::SequenceMatcher(so).run(frames, [&](const registration::SequencePair& p) {
        const registration::Result& r = p.result;
        row.not_converged += !r.converged;
        pairs.push_back({p.t_prev, p.t_cur, r.T_target_source, r.converged, r.iterations});
        ms.push_back(1e3 * p.cpu_s);
      });
  row.total_s = summary.wall_s;
  row.median_ms = eval::percentile(ms, 0.5);
  row.eval = eval::evaluatePairs(pairs, truth);
  if (std::getenv("LIDAR2D_BENCH_DUMP")) {
    // For the correlative search, also: its best score and how far its pose is from the truth,
    // against the best score of a search around the truth (5 cm, 1 deg, inside the success bar): a
    // wrong pose scoring at least that is ambiguity of the score (or a truth the scans disagree
    // with), not a search that missed.
    std::size_t search_ok = 0, outscored = 0, missed = 0;
    for (const auto& e : row.eval.errors)
      if (!e.success) {
        const SE2 rel = truth[e.pair].pose.inverse() * truth[e.pair + 1].pose;
        std::string corr;
        if (options.method == registration::Method::kCorrelative) {
          registration::CorrelativeOptions co = options.corr;
          co.refine = false;
          const auto grid = registration::CorrelativeGrid::fromPoints(points[e.pair], co);
          const auto found = registration::matchCorrelative(grid, points[e.pair + 1], inits[e.pair + 1], co);
          co.linear_window_m = 0.05;
          co.angular_window_rad = 1.0 * kDeg;
          const auto near = registration::matchCorrelative(grid, points[e.pair + 1], rel, co);
          const SE2 d = rel.inverse() * found.T_search;
          const bool ok = withinBar(d);
          search_ok += ok;
          outscored += !ok && found.score >= near.score;
          missed += !ok && found.score < near.score;
          corr = fmt::format("; corr score {:.3f} at {:.3f} m {:.2f} deg from the truth, best near the truth {:.3f}",
                             found.score, d.translation().norm(), d.theta() / kDeg, near.score);
        }
        std::cerr << fmt::format("fail pair {}: err {:.3f} m {:.2f} deg; motion {:.3f} m {:.2f} deg; conv {} it {} pts {} {}{}\n",
                                 e.pair, e.trans_m, e.rot_rad / kDeg, rel.translation().norm(), rel.theta() / kDeg,
                                 pairs[e.pair].converged, pairs[e.pair].iterations, points[e.pair].size(),
                                 points[e.pair + 1].size(), corr);
      }
    if (options.method == registration::Method::kCorrelative)
      std::cerr << fmt::format("failures: correlative search within the bar {}; outside it and scoring at least the "
                               "best near the truth {}; outside it and scoring less {}\n",
                               search_ok, outscored, missed);
  }
  return row;
}

// One pair matched from its true relative pose by three matchers with different costs (p2p, p2l,
// lf): how many miss the bar, whether they land within 3 cm and 0.5 deg of each other, and p2l's
// error.
struct FromTruth {
  std::size_t fails = 0;
  bool agree = false;
  SE2 p2l_error;
};
FromTruth matchFromTruth(const Points2& target, const Points2& source, const SE2& truth) {
  FromTruth out;
  std::vector<SE2> est;
  for (auto m : {registration::Method::kP2P, registration::Method::kP2L, registration::Method::kLikelihoodField}) {
    registration::MatcherOptions o;
    o.method = m;
    est.push_back(registration::matchScans(target, source, truth, o).T_target_source);
    out.fails += !withinBar(truth.inverse() * est.back());
  }
  double spread_m = 0.0, spread_rad = 0.0;
  for (std::size_t i = 0; i < est.size(); ++i)
    for (std::size_t j = i + 1; j < est.size(); ++j) {
      const SE2 d = est[i].inverse() * est[j];
      spread_m = std::max(spread_m, d.translation().norm());
      spread_rad = std::max(spread_rad, std::abs(d.theta()));
    }
  out.agree = spread_m < 0.03 && spread_rad < 0.5 * kDeg;
  out.p2l_error = truth.inverse() * est[1];
  return out;
}

// Checks the truth itself: each pair matched from its true relative pose by three matchers with
// different costs (p2p, p2l, lf). Where all three miss the bar (10 cm, 2 deg) yet agree with each
// other (within 3 cm and 0.5 deg), the scans themselves support a relative pose the corrected poses
// do not: those pairs bound the success rate any scan matcher can reach against this truth.
void runTruthCheck(const std::string& name, const std::vector<Points2>& points, const Trajectory& truth) {
  std::size_t any_fail = 0, all_fail = 0, all_fail_agree = 0;
  std::vector<std::string> listed;
  for (std::size_t k = 1; k < points.size(); ++k) {
    const FromTruth r = matchFromTruth(points[k - 1], points[k], truth[k - 1].pose.inverse() * truth[k].pose);
    any_fail += r.fails > 0;
    if (r.fails < 3) continue;
    ++all_fail;
    if (r.agree) {
      ++all_fail_agree;
      listed.push_back(fmt::format("{} ({:.3f} m, {:+.2f} deg)", k - 1, r.p2l_error.translation().norm(),
                                   r.p2l_error.theta() / kDeg));
    }
  }
  std::cout << fmt::format("| {} | {} | {} | {} | {} ({:.1f}%) |\n", name, points.size() - 1, any_fail, all_fail,
                           all_fail_agree, 100.0 * static_cast<double>(all_fail_agree) / static_cast<double>(points.size() - 1));
  std::cerr << name << ": pairs where p2p, p2l and lf all fail from the truth and agree (p2l's error):";
  for (const auto& l : listed) std::cerr << " " << l;
  std::cerr << "\n";
}

// The relations mode: pairs of scans of a raw bag with a Kuemmerle relation between them (the
// relation as the truth). Success and median errors per method (Gauss-Newton), from the perturbed
// guess and from the identity.
struct RelationLog {
  std::string bag, relations;
  std::optional<SE2> laser_mount;  // the relations' robot frame, where the bag's tf disagrees
};

void runRelations(const std::string& data_dir, const MatchBenchOptions& bo, const sim::OdometryNoise& noise) {
  // fr079: the relations measure the original CARMEN log's robot centre, the laser 4 cm behind it;
  // the bag's tf puts it 4 cm ahead (BENCHMARK.md, SLAM).
  const std::vector<RelationLog> logs{{"raw/intel.orig.bag", "raw/intel.relations", std::nullopt},
                                      {"raw/fr079.orig.bag", "raw/fr079.relations", SE2(-0.04, 0.0, 0.0)},
                                      {"raw/mit-csail.orig.bag", "raw/mit-csail.relations", std::nullopt}};
  std::cout << "| method | dataset | init | pairs | success | median trans err [cm] | median rot err [deg] | "
               "not converged |\n|---|---|---|---|---|---|---|---|\n";
  for (const RelationLog& log : logs) {
    const std::string bag = (std::filesystem::path(data_dir) / log.bag).string();
    const std::string rel_path = (std::filesystem::path(data_dir) / log.relations).string();
    const std::string name = std::filesystem::path(log.bag).stem().stem().string();
    if (!std::filesystem::exists(bag) || !std::filesystem::exists(rel_path)) {
      std::cout << "| | " << log.bag << " | missing: skipped | | | | | |\n";
      continue;
    }
    io::ReaderOptions ro;
    if (log.laser_mount) ro.laser_mount = LaserMount::planar(*log.laser_mount);
    auto source = io::openLog(bag, ro);
    std::vector<double> times;
    std::vector<Points2> points;
    while (auto f = source->next()) {
      times.push_back(f->time);
      points.push_back(f->scan.toPoints(f->T_robot_laser));
    }
    // The scan nearest in time, within 1 ms. (The intel bag has bursts of scans logged under 1 ms
    // apart while the robot turns about 5 deg per scan: the first scan within the tolerance would
    // often be the wrong one.)
    const TimeIndex time_index(times);
    auto frameAt = [&](double t) { return time_index.nearest(t, 1e-3); };
    struct Case {
      std::size_t target, source;
      SE2 truth;
    };
    std::vector<Case> cases;
    std::size_t far = 0, unmatched = 0;
    for (const Relation& r : io::readRelations(rel_path)) {
      if (r.T_1_2.translation().norm() > bo.relation_max_m || std::abs(r.T_1_2.theta()) > bo.relation_max_deg * kDeg) {
        ++far;
        continue;
      }
      const auto a = frameAt(r.t1), b = frameAt(r.t2);
      if (!a || !b) {
        ++unmatched;
        continue;
      }
      cases.push_back({*a, *b, r.T_1_2});
    }
    std::cerr << fmt::format("{}: {} relations used, {} farther apart, {} without a scan at their times\n", name,
                             cases.size(), far, unmatched);
    if (bo.truth_check) {  // as runTruthCheck, on the relations' pairs
      std::size_t any_fail = 0, all_fail = 0, all_fail_agree = 0;
      for (const Case& c : cases) {
        const FromTruth r = matchFromTruth(points[c.target], points[c.source], c.truth);
        any_fail += r.fails > 0;
        all_fail += r.fails == 3;
        all_fail_agree += r.fails == 3 && r.agree;
      }
      std::cout << fmt::format("| truth check | {} | from the relation | {} | some of p2p/p2l/lf fail: {}, all three: {}, "
                               "all three and agree (3 cm, 0.5 deg): {} ({:.1f}%) | | | |\n",
                               name, cases.size(), any_fail, all_fail, all_fail_agree,
                               100.0 * static_cast<double>(all_fail_agree) / static_cast<double>(std::max<std::size_t>(1, cases.size())));
      continue;
    }
    sim::Rng rng(bo.seed);
    std::vector<SE2> perturbed;
    for (const Case& c : cases) perturbed.push_back(sim::noisyOdometryStep(c.truth, noise, rng));
    for (const std::string init_name : {"perturbed", "identity"}) {
      if (std::find(bo.inits.begin(), bo.inits.end(), init_name) == bo.inits.end()) continue;
      for (const std::string method_name : {"p2p", "p2l", "lf", "corr", "corr+p2l"}) {
        if (!wanted(bo.methods, method_name))
          continue;
        const bool two_stage = method_name == "corr+p2l";
        registration::MatcherOptions o;
        o.icp = bo.icp;
        o.corr = bo.corr;
        o.lf = bo.lf;
        o.method = two_stage ? registration::Method::kCorrelative : *registration::parseMethod(method_name);
        registration::SequenceOptions so;
        so.matcher = o;
        if (two_stage) so.then = registration::Method::kP2L;
        const registration::SequenceMatcher matcher(so);
        std::vector<double> et, er;
        std::size_t ok = 0, not_converged = 0;
        for (std::size_t k = 0; k < cases.size(); ++k) {
          const Case& c = cases[k];
          const SE2 init = init_name == "perturbed" ? perturbed[k] : SE2();
          const registration::Result r = matcher.matchPair(points[c.target], points[c.source], init);
          not_converged += !r.converged;
          const SE2 e = c.truth.inverse() * r.T_target_source;
          et.push_back(e.translation().norm());
          er.push_back(std::abs(e.theta()));
          ok += withinBar(e);
          if (std::getenv("LIDAR2D_BENCH_DUMP") && !withinBar(e))
            std::cerr << fmt::format("{} {} fail: scans {} {} err {:.3f} m {:.2f} deg\n", name, method_name, c.target,
                                     c.source, et.back(), e.theta() / kDeg);
        }
        if (cases.empty()) continue;
        std::cout << fmt::format("| {} | {} | {} | {} | {:.1f}% | {:.2f} | {:.3f} | {} |\n", method_name, name, init_name,
                                 cases.size(), 100.0 * static_cast<double>(ok) / static_cast<double>(cases.size()),
                                 100.0 * eval::percentile(et, 0.5), eval::percentile(er, 0.5) / kDeg, not_converged);
        std::cout.flush();
      }
    }
  }
}

}  // namespace

double threadCpuSeconds() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
}

double processCpuSeconds() {
  timespec ts{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
}

bool wanted(const std::vector<std::string>& list, const std::string& name) {
  return list.empty() || std::find(list.begin(), list.end(), name) != list.end();
}

void runMatchBenchmark(const std::string& data_dir, const MatchBenchOptions& bo) {
  const sim::OdometryNoise noise =
      sim::OdometryNoise::constant(bo.sigma_xy_m / std::sqrt(2.0), bo.sigma_xy_m / std::sqrt(2.0), bo.sigma_theta_deg * kDeg);
  std::cout << fmt::format(
      "Initial guess: truth * SE2(n), n ~ N(0, diag({0:.4f}^2, {0:.4f}^2, ({1:.2f} deg)^2)) per pair (RMS {2} m, {3} "
      "deg), seed {4}; or identity. Success: error < 10 cm and < 2 deg.\n\n",
      bo.sigma_xy_m / std::sqrt(2.0), bo.sigma_theta_deg, bo.sigma_xy_m, bo.sigma_theta_deg, bo.seed);
  if (bo.relations) {
    runRelations(data_dir, bo, noise);
    return;
  }
  if (bo.truth_check) {
    std::cout << "| dataset | pairs | some of p2p/p2l/lf fail from the truth | all three fail | all three fail and agree "
                 "(3 cm, 0.5 deg) |\n|---|---|---|---|---|\n";
  } else {
    std::cout << "| method | solver | dataset | init | pairs | success | median trans err [cm] | median rot err [deg] | "
                 "median CPU ms/pair | total wall s | not converged |\n";
    std::cout << "|---|---|---|---|---|---|---|---|---|---|---|\n";
  }
  for (const auto& rel : bo.logs) {
    const std::string path = (std::filesystem::path(data_dir) / rel).string();
    const std::string name = std::filesystem::path(rel).stem().stem().string();
    if (!std::filesystem::exists(path)) {
      std::cout << "| | | " << rel << " | missing: skipped | | | | | | | |\n";
      continue;
    }
    const std::vector<Frame> frames = loadFrames(path);
    std::vector<Points2> points;
    Trajectory truth;
    for (const Frame& f : frames) {
      points.push_back(f.scan.toPoints(f.T_robot_laser));
      truth.push_back({f.time, *f.T_world_robot});
    }
    std::vector<SE2> perturbed(frames.size()), identity(frames.size()), exact(frames.size());
    for (std::size_t k = 1; k < frames.size(); ++k) exact[k] = truth[k - 1].pose.inverse() * truth[k].pose;
    sim::Rng rng(bo.seed);
    std::vector<double> init_t, init_r;
    for (std::size_t k = 1; k < frames.size(); ++k) {
      const SE2 rel_true = truth[k - 1].pose.inverse() * truth[k].pose;
      perturbed[k] = sim::noisyOdometryStep(rel_true, noise, rng);
      init_t.push_back((perturbed[k].translation() - rel_true.translation()).norm());
      init_r.push_back(std::abs(angleDiff(perturbed[k].theta(), rel_true.theta())) / kDeg);
    }
    std::cerr << fmt::format("{}: {} scans, perturbed guess median error {:.3f} m, {:.2f} deg\n", name, frames.size(),
                             eval::percentile(init_t, 0.5), eval::percentile(init_r, 0.5));
    if (bo.truth_check) {
      runTruthCheck(name, points, truth);
      continue;
    }
    for (const auto& [init_name, inits] :
         {std::pair<std::string, const std::vector<SE2>*>{"perturbed", &perturbed}, {"identity", &identity},
          {"truth", &exact}}) {
      if (std::find(bo.inits.begin(), bo.inits.end(), init_name) == bo.inits.end()) continue;
      for (const std::string method_name : {"p2p", "p2l", "lf", "corr", "corr+p2l"}) {
        if (!wanted(bo.methods, method_name))
          continue;
        const bool two_stage = method_name == "corr+p2l";
        const registration::Method method =
            two_stage ? registration::Method::kCorrelative : *registration::parseMethod(method_name);
        for (auto solver : {registration::Solver::kGaussNewton, registration::Solver::kCeres}) {
          if (!wanted(bo.solvers, registration::toString(solver)))
            continue;
          registration::MatcherOptions o;
          o.icp = bo.icp;
          o.corr = bo.corr;
          o.lf = bo.lf;
          o.method = method;
          o.solver = solver;
          std::optional<registration::Method> then;  // (the ICP stage replaces the correlative refinement)
          if (two_stage) then = registration::Method::kP2L;
          const Row row = runPairs(frames, points, *inits, truth, o, then);
          std::cout << fmt::format("| {} | {} | {} | {} | {} | {:.1f}% | {:.2f} | {:.3f} | {:.3f} | {:.2f} | {} |\n",
                                   method_name, registration::toString(solver), name, init_name,
                                   row.eval.count, 100.0 * row.eval.success_rate, 100.0 * row.eval.trans_m.median,
                                   row.eval.rot_rad.median / kDeg, row.median_ms, row.total_s, row.not_converged);
          std::cout.flush();
        }
      }
    }
  }
}

}  // namespace lidar2d::bench
