// lidar2d perturb LOG -o LOG2: a log derived from LOG for robustness tests, written as a CARMEN log
// (scans, truth and laser mounting kept). The steps, in this order (sim::LogPerturber,
// include/lidar2d/sim/log_perturbation.hpp, is the one implementation; docs/perturb.md has examples):
//
// Clock. --synthesize-times HZ replaces the stamp of input scan i (0-based, file order) by
// t0 + i / HZ, t0 = the first scan's stamp (for logs whose stamps repeat or are missing). Gaps and
// output stamps use this clock; without the option it is the log's stamps.
//
// Gaps. --gap DURATION_S[@START_S|@turn] (repeatable) drops the scans whose time lies in
// [b, b + DURATION_S): b = t0 + START_S; without @, the window is centred on the log; @turn: the
// window in which the truth heading turns most (sum of |heading change| between consecutive scans
// both inside), placed after the fixed windows, disjoint from every window placed before it. Gaps are
// placed from a first pass over the log (times and poses only: the log is read twice). A gap must
// end at or before the last scan's time. --kidnap DURATION_S[@START_S|@turn] is a gap across which
// the robot is carried: the odometry of the first scan after it reads no motion while the truth
// jumps (with --keep-odometry the log's odometry continues from where it stopped).
// --freeze-odometry DURATION_S[@START_S|@turn] places a window the same way but keeps its scans: their
// odometry reads what it read at the last scan before the window (a stalled driver), and after it
// what the wheels counted (the motion across the window in one step).
//
// Keyframes. --keyframes D,K keeps a scan outside the gaps when it is the first kept, or when its
// truth pose moved at least D metres or turned at least K degrees (net heading change) from the last
// kept scan's; D or K = 0 turns that criterion off (not both).
//
// Odometry. odom = truth_0 at the log's first scan (kept or not); each later kept scan k gets
//   odom_k = odom_j * SE2(dx (1 + s), dy (1 + s), dth + h d) * SE2(n_x, n_y, n_th),
// (dx, dy, dth) = truth_j^-1 * truth_k, j the previously kept scan, d = |(dx, dy)|, n independent
// Gaussians of std
//   sigma_x = SX + T d,  sigma_y = SY + T d,  sigma_th = STH + R |dth| + M d
// (sim::noisyOdometryStep): the noise applies to the steps between kept scans, and the first scan
// after a gap gets one step for the whole motion across it. SX,SY,STH = --odom-noise [m, m, rad per
// step], T = --odom-trans-noise-per-m [m/m], R = --odom-rot-noise-per-rad [rad/rad],
// M = --odom-rot-noise-deg-per-m [deg/m], s = --odom-scale-error [relative, 0.02 = distances read 2 %
// long], h = --odom-drift-deg-per-m [deg/m, systematic]. --odom-model picks the defaults:
//   constant (default): SX,SY,STH = 0.01,0.005,0.002 and nothing else (perturb's model before
//     these options);
//   realistic (issue 29): SX = SY = 0.005, STH = 0, T = 0.03, R = 0.03, M = 1 deg/m, s = 0.02, h = 0;
// an option given explicitly overrides its term. --keep-odometry keeps the log's own odometry
// instead (no noise, no truth needed: keyframes and @turn then use the truth if the log has it, else
// the odometry).
//
// Odometry lag. --odom-lag MEAN_S[,SIGMA_S] reads each kept scan's odometry at its time plus
// MEAN_S + N(0, SIGMA_S^2) (sim::OdometryLag): truth_k above is the truth at that time, interpolated
// between the log's scans (dropped ones included, from a first pass over the log); in a turn the
// heading is off by the turn rate times the offset, without accumulating.
//
// Stamps. --time-jitter SIGMA_S adds N(0, SIGMA_S^2) to each kept scan's stamp (its odometry and
// truth stay with it); --time-bursts N then gives each group of N consecutive kept scans the stamp of
// its last scan (the last group may be shorter).
//
// Random numbers: --seed N seeds the odometry noise (sim::Rng(N), three Gaussians per kept step),
// the jitter (sim::Rng(N ^ sim::kJitterSeedSalt)) and the lag (sim::Rng(N ^ sim::kLagSeedSalt));
// same seed, same output. Without any of the options above besides --odom-noise and --seed, the
// output (file and summary line) is what perturb wrote before they existed.
//
// Exit codes: a malformed or out-of-range option value (negative, non-finite, --keyframes 0,0,
// --time-bursts 0, odometry options with --keep-odometry) is a usage error (2); a log without ground
// truth (unless --keep-odometry), a gap that does not fit in the log, a log whose scans all get
// dropped, an unreadable log or an unwritable output is bad input (1), and then no output file
// appears.

#include <fmt/format.h>

#include <cmath>
#include <functional>
#include <iostream>
#include <memory>
#include <numbers>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

#include "commands.hpp"
#include "lidar2d/core/error.hpp"
#include "lidar2d/io/carmen_writer.hpp"
#include "lidar2d/io/frame_source.hpp"
#include "lidar2d/sim/log_perturbation.hpp"
#include "lidar2d/sim/noise.hpp"

namespace lidar2d::cli {
namespace {

constexpr double kDeg = std::numbers::pi / 180.0;

// One finite number filling the whole string.
std::optional<double> parseNumber(const std::string& s) {
  if (s.empty()) return std::nullopt;
  char* end = nullptr;
  const double v = std::strtod(s.c_str(), &end);
  if (end == s.c_str() || *end != '\0' || !std::isfinite(v)) return std::nullopt;
  return v;
}

// `count` comma-separated finite non-negative numbers.
bool parseNonNegatives(const std::string& s, double* out, int count) {
  std::stringstream ss(s);
  std::string part;
  int n = 0;
  while (std::getline(ss, part, ',')) {
    if (n == count) return false;
    const auto v = parseNumber(part);
    if (!v || *v < 0) return false;
    out[n++] = *v;
  }
  return n == count && s.back() != ',';
}

bool parseSigmas(const std::string& s, double out[3]) { return parseNonNegatives(s, out, 3); }

// --keyframes D,K: D >= 0 m, K in [0, 180] deg, not both 0.
std::string keyframesError(const std::string& s) {
  double v[2];
  if (!parseNonNegatives(s, v, 2))
    return fmt::format("expected D,K: two comma-separated non-negative numbers, got '{}'", s);
  if (v[1] > 180) return fmt::format("the turn K must be at most 180 degrees, got {}", v[1]);
  if (v[0] == 0 && v[1] == 0) return "D and K are both 0: give a distance, a turn or both";
  return {};
}

// --gap DURATION_S[@START_S|@turn].
std::optional<sim::GapRequest> parseGap(const std::string& s) {
  sim::GapRequest r;
  const auto at = s.find('@');
  const auto duration = parseNumber(s.substr(0, at));
  if (!duration || *duration <= 0) return std::nullopt;
  r.duration_s = *duration;
  if (at == std::string::npos) {
    r.placement = sim::GapPlacement::kMiddle;
    return r;
  }
  const std::string where = s.substr(at + 1);
  if (where == "turn") {
    r.placement = sim::GapPlacement::kLargestTurn;
    return r;
  }
  const auto start = parseNumber(where);
  if (!start || *start < 0) return std::nullopt;
  r.placement = sim::GapPlacement::kAtOffset;
  r.offset_s = *start;
  return r;
}

// --odom-slip DURATION_S[@START_S|@turn],METRES[,DEG].
std::optional<sim::GapRequest> parseSlip(const std::string& s) {
  const auto comma = s.find(',');
  if (comma == std::string::npos) return std::nullopt;
  auto r = parseGap(s.substr(0, comma));
  if (!r) return std::nullopt;
  const std::string motion = s.substr(comma + 1);
  const auto second = motion.find(',');
  const auto metres = parseNumber(motion.substr(0, second));
  if (!metres) return std::nullopt;
  double degrees = 0.0;
  if (second != std::string::npos) {
    const auto d = parseNumber(motion.substr(second + 1));
    if (!d) return std::nullopt;
    degrees = *d;
  }
  r->odometry_slip = true;
  r->slip_m = *metres;
  r->slip_rad = degrees * kDeg;
  return r;
}

std::string slipError(const std::string& v) {
  return parseSlip(v) ? std::string()
                      : fmt::format(
                            "expected DURATION_S[@START_S|@turn],METRES[,DEG], DURATION_S > 0, START_S >= 0 and "
                            "finite METRES and DEG, got '{}'",
                            v);
}

// What a placed window does, for the summary line ("kidnapping ", ...) or the output's first comment
// ("kidnap", ...); empty for a plain gap.
std::string windowKind(const sim::GapRequest& r, bool in_comment) {
  if (r.carried) return in_comment ? "kidnap" : "kidnapping ";
  if (r.frozen_odometry) return in_comment ? "frozen-odometry" : "odometry frozen ";
  if (r.odometry_slip) {
    const double deg = r.slip_rad / kDeg;
    return in_comment ? fmt::format("odometry-slip({:g}m,{:g}deg)", r.slip_m, deg)
                      : fmt::format("odometry slip {:g} m, {:g} deg ", r.slip_m, deg);
  }
  return {};
}

std::string gapError(const std::string& v) {
  return parseGap(v) ? std::string()
                     : fmt::format("expected DURATION_S[@START_S|@turn], DURATION_S > 0 and START_S >= 0, got '{}'", v);
}

CLI::Validator check(const std::string& name, std::function<std::string(const std::string&)> error) {
  return CLI::Validator([error](std::string& v) { return error(v); }, name);
}

struct PerturbArgs {
  std::string log;
  std::string output;
  std::string odom_noise = "0.01,0.005,0.002";
  std::uint64_t seed = 1;
  io::ReaderOptions reader;
  // Options added for issue 29; `legacy()` is true when none is given.
  std::string odom_model = "constant";
  double trans_noise_per_m = 0.0;
  double rot_noise_per_rad = 0.0;
  double rot_noise_deg_per_m = 0.0;
  double scale_error = 0.0;
  double drift_deg_per_m = 0.0;
  bool keep_odometry = false;
  std::string keyframes;
  std::vector<std::string> gaps;
  std::vector<std::string> kidnaps;
  std::vector<std::string> freezes;
  std::vector<std::string> slips;
  double time_jitter_s = 0.0;
  std::string odom_lag;  // MEAN_S[,SIGMA_S]
  std::size_t time_bursts = 1;
  double synthesize_hz = 0.0;
  // What was given on the command line.
  bool odom_noise_given = false, trans_given = false, rot_rad_given = false, rot_m_given = false, scale_given = false,
       drift_given = false, bursts_given = false, jitter_given = false, synth_given = false;
  bool legacy() const {
    return odom_model == "constant" && !trans_given && !rot_rad_given && !rot_m_given && !scale_given && !drift_given &&
           !keep_odometry && keyframes.empty() && gaps.empty() && kidnaps.empty() && freezes.empty() && slips.empty() &&
           !jitter_given && !bursts_given && !synth_given && odom_lag.empty();
  }
};

// MEAN_S[,SIGMA_S] of --odom-lag: a finite mean of either sign, a finite sigma >= 0 (0 when absent).
std::optional<sim::OdometryLag> parseLag(const std::string& v) {
  const std::size_t comma = v.find(',');
  sim::OdometryLag lag;
  const auto mean = parseNumber(v.substr(0, comma));
  if (!mean) return std::nullopt;
  lag.mean_s = *mean;
  if (comma != std::string::npos) {
    const auto sigma = parseNumber(v.substr(comma + 1));
    if (!sigma || *sigma < 0) return std::nullopt;
    lag.sigma_s = *sigma;
  }
  return lag;
}

sim::OdometryNoise odometryModel(const PerturbArgs& a) {
  sim::OdometryNoise n = a.odom_model == "realistic" ? sim::realisticOdometryNoise() : [&] {
    double s[3];
    parseSigmas(PerturbArgs{}.odom_noise, s);
    return sim::OdometryNoise::constant(s[0], s[1], s[2]);
  }();
  if (a.odom_noise_given) {
    double s[3];
    parseSigmas(a.odom_noise, s);  // validated by the option's check
    n.sigma_x_m = s[0];
    n.sigma_y_m = s[1];
    n.sigma_theta_rad = s[2];
  }
  if (a.trans_given) n.trans_sigma_per_m = a.trans_noise_per_m;
  if (a.rot_rad_given) n.rot_sigma_per_rad = a.rot_noise_per_rad;
  if (a.rot_m_given) n.rot_sigma_per_m = a.rot_noise_deg_per_m * kDeg;
  if (a.scale_given) n.scale_bias = a.scale_error;
  if (a.drift_given) n.heading_bias_per_m = a.drift_deg_per_m * kDeg;
  return n;
}

// Library errors name no file: the log is the input they are about.
template <typename F>
auto aboutLog(const std::string& log, F&& f) {
  try {
    return f();
  } catch (const Error& e) {
    if (!e.where().file.empty()) throw;
    throw Error(e.kind() == ErrorKind::kInvalidArgument ? ErrorKind::kBadInput : e.kind(), e.message(),
                ErrorLocation(log));
  }
}

// Odometry made from the truth needs it in every frame; the library says so too, the CLI adds the
// way out.
void requireTruth(const Frame& f, const std::string& log) {
  if (!f.T_world_robot)
    throw badInput(fmt::format("scan {} (time {:.6f}) has no ground-truth pose; perturb needs a log with truth "
                               "(TRUEPOS lines, or a SLAM-corrected CARMEN log), or --keep-odometry to keep the "
                               "log's own odometry",
                               f.index, f.time),
                   ErrorLocation(log));
}

// The output of perturb before issue 29's options, kept byte for byte.
void runLegacy(const PerturbArgs& a) {
  double s[3];
  parseSigmas(a.odom_noise, s);  // validated by the option's check
  sim::LogPerturbationOptions o;
  o.odometry = sim::OdometryNoise::constant(s[0], s[1], s[2]);
  o.seed = a.seed;
  sim::LogPerturber perturber(o);
  auto source = io::openLog(a.log, a.reader);
  io::CarmenWriter writer(a.output);
  writer.comment(fmt::format(
      "lidar2d perturb: source={} odom_noise=[{},{},{}] seed={}: odom_k = odom_(k-1) * (truth_(k-1)^-1 * truth_k) * "
      "SE2(n), n ~ N(0, diag(SX^2, SY^2, STH^2)) per scan step [m, m, rad]",
      a.log, s[0], s[1], s[2], a.seed));
  while (auto f = source->next()) {
    requireTruth(*f, a.log);
    for (const Frame& out : aboutLog(a.log, [&] { return perturber.push(std::move(*f)); })) writer.write(out);
  }
  for (const Frame& out : perturber.finish()) writer.write(out);
  const sim::PerturbationStats& st = perturber.stats();
  if (st.scans_read == 0) throw badInput("log has no scans", ErrorLocation(a.log));
  writer.commit();
  const SE2 odom = *st.last_T_odom_robot, truth = *st.last_T_world_robot;
  const double err = (odom.translation() - truth.translation()).norm();
  std::cout << fmt::format("perturbed {} scans: final odometry error {:.3f} m, {:.2f} deg -> {}\n", st.scans_read, err,
                           std::abs(angleDiff(odom.theta(), truth.theta())) * 180.0 / std::numbers::pi, a.output);
}

std::string describeNoise(const sim::OdometryNoise& n) {
  return fmt::format(
      "sigma_step=[{},{},{}] [m,m,rad] trans_per_m={} rot_per_rad={} rot_deg_per_m={} scale_error={} "
      "drift_deg_per_m={}",
      n.sigma_x_m, n.sigma_y_m, n.sigma_theta_rad, n.trans_sigma_per_m, n.rot_sigma_per_rad, n.rot_sigma_per_m / kDeg,
      n.scale_bias, n.heading_bias_per_m / kDeg);
}

void run(const PerturbArgs& a) {
  const CreatedFolders out_folders = prepareOutputFile(a.output);
  if (a.legacy()) return runLegacy(a);

  sim::LogPerturbationOptions o;
  o.seed = a.seed;
  o.odometry_source = a.keep_odometry ? sim::OdometrySource::kKeepLog : sim::OdometrySource::kNoisyFromTruth;
  if (!a.keep_odometry) o.odometry = odometryModel(a);
  if (!a.keyframes.empty()) {
    double v[2];
    parseNonNegatives(a.keyframes, v, 2);  // validated by the option's check
    o.keyframes.min_distance_m = v[0];
    o.keyframes.min_turn_rad = v[1] * kDeg;
  }
  o.time.synthesize_rate_hz = a.synthesize_hz;
  o.time.jitter_sigma_s = a.time_jitter_s;
  o.time.burst_size = a.time_bursts;
  if (!a.odom_lag.empty()) o.odometry_lag = *parseLag(a.odom_lag);  // validated by the option's check
  std::vector<sim::GapRequest> requests;
  for (const std::string& g : a.gaps) requests.push_back(*parseGap(g));  // validated by the option's check
  for (const std::string& g : a.kidnaps) {
    requests.push_back(*parseGap(g));
    requests.back().carried = true;
  }
  for (const std::string& g : a.freezes) {
    requests.push_back(*parseGap(g));
    requests.back().frozen_odometry = true;
  }
  for (const std::string& g : a.slips) requests.push_back(*parseSlip(g));  // validated by the option's check

  // First pass: place the gaps on the log's times and poses; keep the truth for the odometry lag.
  double t_first = 0.0;
  if (!requests.empty() || o.odometry_lag.enabled()) {
    sim::GapPlanner planner(requests, o.odometry_source, o.time);
    auto source = io::openLog(a.log, a.reader);
    aboutLog(a.log, [&] {
      while (auto f = source->next()) {
        if (!a.keep_odometry) requireTruth(*f, a.log);
        planner.add(*f);
      }
      return 0;
    });
    if (planner.samples().empty()) throw badInput("log has no scans", ErrorLocation(a.log));
    t_first = planner.samples().front().time_s;
    o.gaps = aboutLog(a.log, [&] { return planner.plan(); });
    if (o.odometry_lag.enabled()) o.truth_timeline = planner.samples();
  }

  // Second pass: the derived log.
  sim::LogPerturber perturber(o);
  auto source = io::openLog(a.log, a.reader);
  io::CarmenWriter writer(a.output);
  std::string gaps_desc;
  for (const sim::GapWindow& g : o.gaps)
    gaps_desc += fmt::format(" {}[{:.3f},{:.3f})", windowKind(g.request, true), g.begin_s, g.end_s);
  writer.comment(fmt::format(
      "lidar2d perturb: source={} seed={} odometry={} keyframes={} gaps={} synthesize_hz={} time_jitter_s={} "
      "time_bursts={} (model: docs/perturb.md)",
      a.log, a.seed,
      a.keep_odometry ? "kept from the log"
                      : fmt::format("{} {}{}", a.odom_model, describeNoise(o.odometry),
                                    o.odometry_lag.enabled()
                                        ? fmt::format(" lag_s={},{}", o.odometry_lag.mean_s, o.odometry_lag.sigma_s)
                                        : std::string()),
      a.keyframes.empty() ? "none"
                          : fmt::format("{} m,{} deg", o.keyframes.min_distance_m, o.keyframes.min_turn_rad / kDeg),
      gaps_desc.empty() ? "none" : gaps_desc.substr(1), a.synthesize_hz, a.time_jitter_s, a.time_bursts));
  while (auto f = source->next()) {
    if (!a.keep_odometry) requireTruth(*f, a.log);
    for (const Frame& out : aboutLog(a.log, [&] { return perturber.push(std::move(*f)); })) writer.write(out);
  }
  for (const Frame& out : perturber.finish()) writer.write(out);
  const sim::PerturbationStats& st = perturber.stats();
  if (st.scans_read == 0) throw badInput("log has no scans", ErrorLocation(a.log));
  if (st.scans_kept == 0)
    throw badInput(fmt::format("all {} scans were dropped ({} by gaps, {} by keyframes)", st.scans_read,
                               st.dropped_by_gaps, st.dropped_by_keyframes),
                   ErrorLocation(a.log));
  writer.commit();

  std::string gaps_summary;
  for (std::size_t k = 0; k < o.gaps.size(); ++k) {
    const sim::GapWindow& g = o.gaps[k];
    gaps_summary += fmt::format("{}{}{:.1f}-{:.1f} s{}: {} scans", k == 0 ? " (" : "; ", windowKind(g.request, false),
                                g.begin_s - t_first, g.end_s - t_first,
                                std::isnan(g.turn_rad) ? "" : fmt::format(", turn {:.0f} deg", g.turn_rad / kDeg),
                                st.dropped_per_gap[k]);
  }
  if (!gaps_summary.empty()) gaps_summary += ")";
  std::string odometry = "odometry kept from the log";
  if (!a.keep_odometry) {
    const SE2 odom = *st.last_T_odom_robot, truth = *st.last_T_world_robot;
    odometry =
        fmt::format("final odometry error {:.3f} m, {:.2f} deg", (odom.translation() - truth.translation()).norm(),
                    std::abs(angleDiff(odom.theta(), truth.theta())) / kDeg);
  }
  std::cout << fmt::format("perturbed {} scans: kept {}, dropped {} by keyframes, {} by gaps{}; {} -> {}\n",
                           st.scans_read, st.scans_kept, st.dropped_by_keyframes, st.dropped_by_gaps, gaps_summary,
                           odometry, a.output);
}

}  // namespace

void addPerturbCommand(CLI::App& app) {
  auto a = std::make_shared<PerturbArgs>();
  auto* sub = app.add_subcommand(
      "perturb",
      "Derive a log for robustness tests from a log with truth; writes a CARMEN log with TRUEPOS lines (scans, "
      "truth and laser mounting kept). Steps: --synthesize-times (clock), --gap (drop time windows; --freeze-odometry "
      "keeps them, odometry frozen; --odom-slip keeps them, odometry slipping), --keyframes "
      "(drop scans too close to the last kept one), odometry (replaced, read --odom-lag off each scan's time, or "
      "kept with --keep-odometry), "
      "--time-jitter and --time-bursts (stamps). Odometry: odom_0 = truth_0; each kept scan k after the previously "
      "kept j: odom_k = odom_j * SE2(dx(1+s), dy(1+s), dth + h d) * SE2(n), (dx,dy,dth) = truth_j^-1 * truth_k, "
      "d = |(dx,dy)|, n ~ N(0, diag(sx^2, sy^2, sth^2)), sx = SX + T d, sy = SY + T d, sth = STH + R |dth| + M d: "
      "the noise applies per step between kept scans; the first scan after a gap gets the whole motion across it "
      "in one step. Without new options the output is the same as before them.");
  sub->add_option("LOG", a->log, "input log (any format lidar2d reads); needs truth unless --keep-odometry")
      ->required();
  sub->add_option("-o,--output", a->output, "output CARMEN log")->required();
  std::vector<CLI::Option*> odom_opts;
  odom_opts.push_back(
      sub->add_option("--odom-noise", a->odom_noise,
                      "SX,SY,STH: constant std of the odometry error per kept step, x forward and y left in metres, "
                      "heading in radians (per step, not per metre); default 0.01,0.005,0.002 (--odom-model "
                      "constant), 0.005,0.005,0 (realistic)")
          ->check(check("SX,SY,STH", [](const std::string& v) -> std::string {
            double s[3];
            return parseSigmas(v, s) ? std::string()
                                     : fmt::format(
                                           "expected SX,SY,STH: three comma-separated non-negative numbers, "
                                           "got '{}'",
                                           v);
          })));
  odom_opts.push_back(sub->add_option("--odom-model", a->odom_model,
                                      "defaults of the odometry terms: 'constant' (--odom-noise only, the default) or "
                                      "'realistic' (issue 29: 3 % of distance + 5 mm per step translation noise, 1 "
                                      "degree per metre + 3 % of the turn heading noise, 2 % scale error)")
                          ->check(CLI::IsMember({"constant", "realistic"}).description(""))
                          ->type_name("constant|realistic")
                          ->capture_default_str());
  odom_opts.push_back(sub->add_option("--odom-trans-noise-per-m", a->trans_noise_per_m,
                                      "T: extra std of the x and y error per metre of the step [m/m] (default: constant 0, realistic 0.03)")
                          ->check(nonNegativeNumber()));
  odom_opts.push_back(sub->add_option("--odom-rot-noise-per-rad", a->rot_noise_per_rad,
                                      "R: extra heading std per radian the step turns [rad/rad] (default: constant 0, realistic 0.03)")
                          ->check(nonNegativeNumber()));
  odom_opts.push_back(sub->add_option("--odom-rot-noise-deg-per-m", a->rot_noise_deg_per_m,
                                      "M: extra heading std per metre of the step [deg/m] (default: constant 0, realistic 1)")
                          ->check(nonNegativeNumber()));
  odom_opts.push_back(sub->add_option("--odom-scale-error", a->scale_error,
                                      "s: systematic relative distance error, > -1 (0.02: distances read 2 % long; default: constant 0, "
                                      "realistic 0.02)")
                          ->check(check("SCALE", [](const std::string& v) -> std::string {
                            const auto x = parseNumber(v);
                            return !x || *x > -1 ? std::string()
                                                 : fmt::format("must be a finite number > -1, got {}", v);
                          })));
  odom_opts.push_back(
      sub->add_option("--odom-lag", a->odom_lag,
                      "MEAN_S[,SIGMA_S]: read each kept scan's odometry at its time plus MEAN_S + N(0, SIGMA_S^2) [s] "
                      "(a laser and odometry on clocks out of step: in a turn the heading is off by the turn rate "
                      "times the offset; interpolated in the log's truth, seeded; default: at the scan's time)")
          ->check(check("MEAN_S[,SIGMA_S]", [](const std::string& v) -> std::string {
            return parseLag(v) ? std::string()
                               : fmt::format(
                                     "expected MEAN_S[,SIGMA_S]: a finite number, optionally a comma and a "
                                     "non-negative number, got '{}'",
                                     v);
          })));
  odom_opts.push_back(sub->add_option("--odom-drift-deg-per-m", a->drift_deg_per_m,
                                      "h: systematic heading drift per metre of the step [deg/m], either sign (default 0)"));
  auto* keep = sub->add_flag("--keep-odometry", a->keep_odometry,
                             "keep the log's own odometry (no noise; the log needs no truth): only drop and retime "
                             "scans");
  for (CLI::Option* o : odom_opts) keep->excludes(o);
  sub->add_option("--keyframes", a->keyframes,
                  "D,K: keep a scan when its truth pose moved at least D metres or turned at least K degrees since the "
                  "last kept scan (the first scan is kept); 0 turns a criterion off, not both; K <= 180")
      ->check(check("D,K", keyframesError));
  sub->add_option("--gap", a->gaps,
                  "DURATION_S[@START_S|@turn]: drop the scans in [t0 + START_S, t0 + START_S + DURATION_S) (t0 = the "
                  "first scan's time); without @, a window centred on the log; @turn, the window in which the truth "
                  "heading turns most. Repeatable; the gap must end by the last scan")
      ->allow_extra_args(false)  // one value per --gap, so that a following LOG is not taken as a gap
      ->check(check("DURATION_S[@START_S|@turn]", gapError));
  sub->add_option("--kidnap", a->kidnaps,
                  "DURATION_S[@START_S|@turn]: a gap (as --gap) across which the robot is carried: the odometry "
                  "reads no motion across it while the truth jumps. Repeatable")
      ->allow_extra_args(false)
      ->check(check("DURATION_S[@START_S|@turn]", gapError));
  sub->add_option("--freeze-odometry", a->freezes,
                  "DURATION_S[@START_S|@turn]: a window (placed as --gap) whose scans are kept but whose odometry "
                  "reads what it read at the last scan before it (a stalled driver); after it, what the wheels "
                  "counted. Repeatable")
      ->allow_extra_args(false)
      ->check(check("DURATION_S[@START_S|@turn]", gapError));
  sub->add_option("--odom-slip", a->slips,
                  "DURATION_S[@START_S|@turn],METRES[,DEG]: a window (placed as --gap) whose scans are kept but whose "
                  "odometry counts METRES of forward motion (negative: backward) and DEG of turn (counter-clockwise "
                  "positive) the robot did not make, spread evenly over it (wheels spinning, a robot pushed); after "
                  "it the odometry reads on, offset by the slip. Repeatable")
      ->allow_extra_args(false)
      ->check(check("DURATION_S[@START_S|@turn],METRES[,DEG]", slipError));
  sub->add_option("--time-jitter", a->time_jitter_s,
                  "SIGMA_S: add Gaussian noise of this std to every kept scan's stamp [s] (seeded)")
      ->check(nonNegativeNumber())
      ->capture_default_str();
  sub->add_option("--time-bursts", a->time_bursts,
                  "N: each group of N consecutive kept scans carries the stamp of the group's last scan")
      ->check(CLI::Range(std::size_t{1}, std::size_t{1} << 40))
      ->capture_default_str();
  sub->add_option("--synthesize-times", a->synthesize_hz,
                  "HZ: replace the stamp of input scan i by t0 + i / HZ (logs whose stamps repeat or are missing; default: "
                  "the log's stamps)")
      ->check(positiveNumber());
  sub->add_option("--seed", a->seed,
                  "random seed of the odometry noise, the time jitter and the odometry lag (std::mt19937_64)")
      ->capture_default_str();
  addReaderOptions(sub, a->reader);
  sub->callback([a, sub] {
    a->odom_noise_given = sub->count("--odom-noise") > 0;
    a->trans_given = sub->count("--odom-trans-noise-per-m") > 0;
    a->rot_rad_given = sub->count("--odom-rot-noise-per-rad") > 0;
    a->rot_m_given = sub->count("--odom-rot-noise-deg-per-m") > 0;
    a->scale_given = sub->count("--odom-scale-error") > 0;
    a->drift_given = sub->count("--odom-drift-deg-per-m") > 0;
    a->jitter_given = sub->count("--time-jitter") > 0;
    a->bursts_given = sub->count("--time-bursts") > 0;
    a->synth_given = sub->count("--synthesize-times") > 0;
    run(*a);
  });
}

}  // namespace lidar2d::cli
