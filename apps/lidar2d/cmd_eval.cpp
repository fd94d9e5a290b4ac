// lidar2d eval EST --truth LOG|TRAJ|RELATIONS: accuracy of an estimated trajectory (and optionally of
// scan matching pairs) against ground truth, printed as JSON.

#include <fmt/format.h>

#include <algorithm>
#include <iostream>
#include <map>
#include <memory>
#include <nlohmann/json.hpp>
#include <numbers>
#include <optional>
#include <string>

#include "commands.hpp"
#include "lidar2d/core/error.hpp"
#include "lidar2d/eval/metrics.hpp"
#include "lidar2d/io/atomic_file.hpp"
#include "lidar2d/io/frame_source.hpp"
#include "lidar2d/io/trajectory.hpp"

namespace lidar2d::cli {
namespace {

using Json = nlohmann::ordered_json;

enum class PoseSource { kOdometry, kTruth };

struct EvalArgs {
  std::string est;
  std::string truth;
  std::string output;
  std::string pairs;
  PoseSource estimate_from = PoseSource::kOdometry;
  eval::Options options;
  bool no_align = false;
  io::ReaderOptions reader;
};

double deg(double rad) { return rad * 180.0 / std::numbers::pi; }

const char* toString(io::PoseFileKind k) {
  switch (k) {
    case io::PoseFileKind::kTrajectory:
      return "trajectory";
    case io::PoseFileKind::kRelations:
      return "relations";
    case io::PoseFileKind::kLog:
      return "log";
  }
  return "unknown";
}

/// The poses of a log's frames, keyed by the frames' times. `required`: a frame lacking the pose is
/// an error naming it; otherwise such frames are left out (and counted in `missing`).
Trajectory logPoses(const std::string& path, const io::ReaderOptions& reader, PoseSource from, bool required,
                        std::size_t& missing) {
  auto source = io::openLog(path, reader);
  Trajectory out;
  missing = 0;
  const char* what = from == PoseSource::kOdometry ? "odometry" : "ground-truth";
  while (auto f = source->next()) {
    const std::optional<SE2>& pose = from == PoseSource::kOdometry ? f->T_odom_robot : f->T_world_robot;
    if (!pose) {
      if (required)
        throw badInput(fmt::format("has no {} pose{}", what,
                                   from == PoseSource::kOdometry ? " (try --estimate-from truth)" : ""),
                       {path, 0, fmt::format("frame {} (t={:.6f})", f->index, f->time)});
      ++missing;
      continue;
    }
    out.push_back({f->time, *pose});
  }
  if (out.empty()) throw badInput(fmt::format("the log has no {} poses", what), {path});
  return out;
}

double minTime(const Trajectory& t) {
  double v = t.front().time;
  for (const auto& p : t) v = std::min(v, p.time);
  return v;
}
double maxTime(const Trajectory& t) {
  double v = t.front().time;
  for (const auto& p : t) v = std::max(v, p.time);
  return v;
}

void run(const EvalArgs& args) {
  std::optional<CreatedFolders> out_folders;
  if (!args.output.empty()) out_folders.emplace(prepareOutputFile(args.output));
  // Open the output first so that an unwritable -o fails before the work, and never half-written.
  std::unique_ptr<io::AtomicFile> out_file;
  if (!args.output.empty()) out_file = std::make_unique<io::AtomicFile>(args.output);

  Json j;
  Json warnings = Json::array();

  const io::PoseFileKind est_kind = io::detectPoseFile(args.est);
  const io::PoseFileKind truth_kind = io::detectPoseFile(args.truth);
  if (!args.pairs.empty() && truth_kind == io::PoseFileKind::kRelations)
    throw CLI::ValidationError("--pairs", "needs truth poses (a trajectory or a log), not a relations file");

  // ---- estimate ----
  Trajectory est;
  Json je{{"file", args.est}, {"kind", toString(est_kind)}};
  switch (est_kind) {
    case io::PoseFileKind::kRelations:
      throw badInput("is a relations file; relations are ground truth: pass them with --truth", {args.est});
    case io::PoseFileKind::kTrajectory:
      est = io::readTrajectory(args.est);
      break;
    case io::PoseFileKind::kLog: {
      std::size_t missing = 0;
      est = logPoses(args.est, args.reader, args.estimate_from, true, missing);
      je["poses_from"] = args.estimate_from == PoseSource::kOdometry ? "odometry" : "truth";
      break;
    }
  }
  je["poses"] = est.size();
  j["estimate"] = je;

  // ---- truth ----
  Json jt{{"file", args.truth}, {"kind", toString(truth_kind)}};
  Trajectory ref;
  Relations relations;
  switch (truth_kind) {
    case io::PoseFileKind::kRelations:
      relations = io::readRelations(args.truth);
      jt["relations"] = relations.size();
      break;
    case io::PoseFileKind::kTrajectory:
      ref = io::readTrajectory(args.truth);
      jt["poses"] = ref.size();
      break;
    case io::PoseFileKind::kLog: {
      std::size_t missing = 0;
      ref = logPoses(args.truth, args.reader, PoseSource::kTruth, false, missing);
      jt["poses"] = ref.size();
      if (missing) warnings.push_back(fmt::format("{} frames of the truth log have no truth pose and are left out", missing));
      break;
    }
  }
  j["truth"] = jt;
  j["max_dt_s"] = args.options.max_dt_s;

  eval::Options options = args.options;
  options.align = !args.no_align;

  if (truth_kind == io::PoseFileKind::kRelations) {
    const eval::RelationsResult r = eval::evaluateRelations(est, relations, options);
    if (r.ambiguous_times)
      warnings.push_back("the estimate repeats timestamps: each relation uses the first pose of a repeated time");
    if (r.count == 0)
      throw badInput(fmt::format("none of the {} relations of {} has estimated poses within {} s of both its times "
                                 "(estimated times span {:.6f} .. {:.6f})",
                                 relations.size(), args.truth, options.max_dt_s, minTime(est), maxTime(est)),
                     {args.est});
    j["relations"] = Json{{"trans_mean_m", r.trans_m.mean},      {"trans_std_m", r.trans_m.stddev},
                          {"rot_mean_deg", deg(r.rot_rad.mean)}, {"rot_std_deg", deg(r.rot_rad.stddev)},
                          {"count", r.count},                    {"skipped", r.skipped},
                          {"trans_rmse_m", r.trans_m.rmse},      {"trans_median_m", r.trans_m.median},
                          {"trans_max_m", r.trans_m.max},        {"rot_rmse_deg", deg(r.rot_rad.rmse)},
                          {"rot_median_deg", deg(r.rot_rad.median)}, {"rot_max_deg", deg(r.rot_rad.max)},
                          {"std", "sample (n-1)"}};
  } else {
    eval::TrajectoryResult r;
    try {
      r = eval::evaluateTrajectory(est, ref, options);
    } catch (const Error& e) {
      if (e.where().file.empty()) throw Error(e.kind(), e.message(), {args.est});
      throw;
    }
    const auto& a = r.association;
    if (a.ambiguous_times)
      warnings.push_back("the estimate repeats timestamps and is associated by time: the first pose of a repeated time is used");
    // Figures over a few stray matches of two trajectories whose clocks differ (an estimate of a
    // log with its times rewritten, say) would read as a perfect score.
    if (a.matches.size() < a.unmatched_estimate || a.matches.size() < a.unmatched_reference) {
      const std::string w = fmt::format(
          "only {} of the {} estimated and {} truth poses are within {} s of each other: the figures cover "
          "those only (estimated times span {:.6f} .. {:.6f}, truth times {:.6f} .. {:.6f})",
          a.matches.size(), est.size(), ref.size(), options.max_dt_s, minTime(est), maxTime(est), minTime(ref),
          maxTime(ref));
      warnings.push_back(w);
      fmt::print(stderr, "lidar2d eval: warning: {}\n", w);
    }
    j["association"] = eval::toString(a.mode);
    j["matched"] = a.matches.size();
    j["unmatched"] = a.unmatched_reference;
    j["unmatched_estimate"] = a.unmatched_estimate;
    j["max_abs_dt_s"] = a.max_abs_dt_s;
    const auto& ate = r.ate;
    j["ate_rmse_m"] = ate.trans_m.rmse;
    j["ate_mean_m"] = ate.trans_m.mean;
    j["ate_median_m"] = ate.trans_m.median;
    j["ate_std_m"] = ate.trans_m.stddev;
    j["ate_max_m"] = ate.trans_m.max;
    j["ate_rot_rmse_deg"] = deg(ate.rot_rad.rmse);
    j["ate_rot_mean_deg"] = deg(ate.rot_rad.mean);
    j["ate_rot_max_deg"] = deg(ate.rot_rad.max);
    j["ate_unaligned_rmse_m"] = ate.unaligned_trans_m.rmse;
    j["alignment"] = Json{{"applied", options.align},
                          {"x_m", ate.T_ref_est.x()},
                          {"y_m", ate.T_ref_est.y()},
                          {"theta_deg", deg(ate.T_ref_est.theta())}};
    const auto& rpe = r.rpe;
    j["rpe_pairs"] = rpe.trans_m.count;
    j["rpe_trans_rmse_m"] = rpe.trans_m.rmse;
    j["rpe_trans_mean_m"] = rpe.trans_m.mean;
    j["rpe_rot_rmse_deg"] = deg(rpe.rot_rad.rmse);
    j["rpe_rot_mean_deg"] = deg(rpe.rot_rad.mean);
    j["rpe_per_m_distance_m"] = rpe.distance_m;
    j["rpe_per_m_segments"] = rpe.trans_per_m.count;
    j["rpe_per_m_trans_mean"] = rpe.trans_per_m.mean;  // [m/m]
    j["rpe_per_m_trans_rmse"] = rpe.trans_per_m.rmse;  // [m/m]
    j["rpe_per_m_rot_mean_deg"] = deg(rpe.rot_rad_per_m.mean);  // [deg/m]
    j["rpe_per_m_rot_rmse_deg"] = deg(rpe.rot_rad_per_m.rmse);  // [deg/m]
  }

  if (!args.pairs.empty()) {
    const auto pairs = io::readRelativePoses(args.pairs);
    const eval::PairsResult p = eval::evaluatePairs(pairs, ref, options);
    j["pairs"] = Json{{"file", args.pairs},
                      {"association", eval::toString(p.mode)},
                      {"count", p.count},
                      {"skipped", p.skipped},
                      {"successes", p.successes},
                      {"success_rate", p.success_rate},
                      {"converged", p.converged},
                      {"max_trans_m", options.pair_max_trans_m},
                      {"max_rot_deg", options.pair_max_rot_deg},
                      {"median_trans_m", p.trans_m.median},
                      {"median_rot_deg", deg(p.rot_rad.median)},
                      {"mean_trans_m", p.trans_m.mean},
                      {"mean_rot_deg", deg(p.rot_rad.mean)},
                      {"rmse_trans_m", p.trans_m.rmse},
                      {"rmse_rot_deg", deg(p.rot_rad.rmse)},
                      {"worst_trans_m", p.trans_m.max},
                      {"worst_rot_deg", deg(p.rot_rad.max)}};
  }
  j["warnings"] = warnings;

  const std::string text = j.dump(2) + "\n";
  if (out_file) {
    out_file->stream() << text;
    out_file->commit();
  }
  std::cout << text;
}

}  // namespace

void addEvalCommand(CLI::App& app) {
  auto args = std::make_shared<EvalArgs>();
  auto* sub = app.add_subcommand(
      "eval", "Accuracy of an estimated trajectory against ground truth: ATE, RPE, relation errors, pair errors (JSON)");
  sub->add_option("EST", args->est,
                  "estimated trajectory ('t x y theta' or TUM), or a log whose odometry/truth poses are the estimate")
      ->required();
  sub->add_option("--truth", args->truth,
                  "ground truth: a .relations file (Kuemmerle et al. 2009), a trajectory file, or a log with truth poses")
      ->required();
  sub->add_option("-o,--output", args->output, "also write the JSON to this file (atomically)");
  addChoice<PoseSource>(sub, "--estimate-from", args->estimate_from,
                        {{"odometry", PoseSource::kOdometry}, {"truth", PoseSource::kTruth}},
                        "when EST is a log: use its odometry or its truth poses")
      ->default_str("odometry");
  sub->add_option("--max-dt", args->options.max_dt_s, "time tolerance of nearest-timestamp lookups [s]")
      ->check(positiveNumber())
      ->default_val(0.1);
  sub->add_option("--pairs", args->pairs,
                  "also score relative poses written by 'match' (t_prev t_cur dx dy dtheta converged iterations)");
  addChoice<eval::AssociationMode>(sub, "--association", args->options.association,
                                   {{"auto", eval::AssociationMode::kAuto},
                                    {"index", eval::AssociationMode::kIndex},
                                    {"time", eval::AssociationMode::kTime}},
                                   "pair poses by index, by nearest time, or auto (index when the times are identical)")
      ->default_str("auto");
  sub->add_flag("--no-align", args->no_align, "ATE in the given frames, without the least-squares SE(2) alignment");
  sub->add_option("--rpe-distance", args->options.rpe_distance_m, "segment length of the per-distance RPE [m]")
      ->check(positiveNumber())
      ->default_val(1.0);
  sub->add_option("--pair-max-trans", args->options.pair_max_trans_m, "pair success threshold, translation [m]")
      ->check(positiveNumber())
      ->default_val(0.10);
  sub->add_option("--pair-max-rot", args->options.pair_max_rot_deg, "pair success threshold, rotation [deg]")
      ->check(positiveNumber())
      ->default_val(2.0);
  addReaderOptions(sub, args->reader);
  sub->callback([args] { run(*args); });
}

}  // namespace lidar2d::cli
