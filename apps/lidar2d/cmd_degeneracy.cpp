// lidar2d degeneracy LOG -o FILE [--snapshots DIR]: per-scan degeneracy (does the scan constrain the
// robot's translation in every direction?).
//
// Each scan's valid beams become points in the robot frame (LaserScan::toPoints(T_robot_laser)) and go
// through degeneracy::analyze (geometric + information detectors, combined). Output, one line per scan
// in file order (the log's timestamps, which may repeat), written atomically:
//   t degenerate(0/1) score direction_rad
// with the meaning of each column in the file's '#' header (see kHeader below). --snapshots DIR draws
// chosen scans as PNGs: points coloured by cluster, fitted lines, the verdict and the degenerate
// direction. Exit codes: 1 for bad input (unreadable or malformed log, no scans, unwritable output;
// no output file appears then), 2 for usage errors.

#include <fmt/format.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <iostream>
#include <memory>
#include <numbers>
#include <opencv2/imgproc.hpp>

#include "commands.hpp"
#include "progress.hpp"
#include "lidar2d/core/error.hpp"
#include "lidar2d/degeneracy/degeneracy.hpp"
#include "lidar2d/io/atomic_file.hpp"
#include "lidar2d/io/image.hpp"
#include "lidar2d/io/prefetch.hpp"

namespace lidar2d::cli {
namespace {

constexpr double kDeg = 180.0 / std::numbers::pi;

constexpr const char* kHeader =
    "# t degenerate(0/1) score direction_rad\n"
    "# t: the scan's timestamp as stored in the log [s]; one line per scan in file order\n"
    "# degenerate: 1 when the scan leaves the translation along direction_rad (nearly) unconstrained, and\n"
    "#   also when it cannot be judged (too few points, all on one spot, no usable structure): then score\n"
    "#   and direction_rad are nan. 0 when every translation direction is constrained.\n"
    "# score: translational information along the weakest direction per point (smallest eigenvalue of the\n"
    "#   point-to-line information matrix's translation block divided by the number of points; 0 = free,\n"
    "#   0.5 = every direction equally constrained); written for every judged scan, flagged or not\n"
    "# direction_rad: that weakest direction in the robot frame, an axis in (-pi/2, pi/2] [rad]; for a\n"
    "#   degenerate scan the corridor's axis, for a well-constrained one merely the least constrained axis\n";

struct DegeneracyArgs {
  std::string log;
  std::string output;
  std::string snapshots;
  std::size_t snapshot_every = 50;
  std::size_t max_snapshots = 50;
  bool snapshot_degenerate_only = false;
  double snapshot_range_m = 15.0;
  degeneracy::Options options;
  bool quiet = false;
  io::ReaderOptions reader;
};

cv::Scalar clusterColour(int id) {
  static const cv::Scalar palette[] = {{180, 119, 31}, {14, 127, 255},  {44, 160, 44},  {189, 103, 148},
                                       {75, 86, 140},  {194, 119, 227}, {34, 189, 188}, {207, 190, 23}};
  return palette[static_cast<std::size_t>(id) % (sizeof(palette) / sizeof(palette[0]))];
}

// A picture of one scan in the robot frame (x right, y up), the robot at the centre.
void writeSnapshot(const std::string& path, const Frame& f, const Points2& pts, const degeneracy::Result& r,
                   double range_m) {
  const int size = 800, margin = 40;
  cv::Mat img(size + margin, size, CV_8UC3, cv::Scalar(255, 255, 255));
  const double scale = (size / 2.0 - 10) / range_m;
  auto px = [&](const Eigen::Vector2d& p) {
    return cv::Point(static_cast<int>(std::lround(size / 2.0 + scale * p.x())),
                     static_cast<int>(std::lround(margin + size / 2.0 - scale * p.y())));
  };
  // A 1 m grid (10 m, 100 m, ... for wide pictures: at most 50 lines each way).
  double grid = 1.0;
  while (range_m / grid > 50) grid *= 10;
  for (int k = -static_cast<int>(range_m / grid); k <= static_cast<int>(range_m / grid); ++k) {
    const cv::Scalar g(235, 235, 235);
    cv::line(img, px({k * grid, -range_m}), px({k * grid, range_m}), g, 1);
    cv::line(img, px({-range_m, k * grid}), px({range_m, k * grid}), g, 1);
  }
  for (std::size_t i = 0; i < pts.size(); ++i) {
    if (!pts[i].allFinite()) continue;
    const int c = r.geometric.cluster_of_point.empty() ? -1 : r.geometric.cluster_of_point[i];
    cv::circle(img, px(pts[i]), c < 0 ? 1 : 2, c < 0 ? cv::Scalar(160, 160, 160) : clusterColour(c), cv::FILLED);
  }
  const double dir = r.direction_rad;
  const Eigen::Vector2d d(std::cos(dir), std::sin(dir));
  for (const auto& l : r.geometric.lines) {
    const bool parallel = std::isfinite(dir) && std::abs(l.direction.dot(d)) >= std::cos(10.0 / kDeg);
    cv::line(img, px(l.a), px(l.b), parallel && r.degenerate() ? cv::Scalar(0, 0, 200) : cv::Scalar(0, 0, 0), 2,
             cv::LINE_AA);
  }
  // The degenerate direction (both ways), then the robot on top: a triangle pointing along +x.
  if (r.degenerate()) {
    const double L = range_m * 0.6;
    cv::arrowedLine(img, px({0, 0}), px(L * d), cv::Scalar(0, 0, 255), 2, cv::LINE_AA, 0, 0.05);
    cv::arrowedLine(img, px({0, 0}), px(-L * d), cv::Scalar(0, 0, 255), 2, cv::LINE_AA, 0, 0.05);
  }
  const double s = std::max(0.3, range_m / 40.0);
  std::vector<cv::Point> tri{px({s, 0}), px({-s / 2, s / 2}), px({-s / 2, -s / 2})};
  cv::fillConvexPoly(img, tri, cv::Scalar(40, 160, 40), cv::LINE_AA);
  const std::string verdict = degeneracy::toString(r.verdict);
  const std::string line1 =
      fmt::format("scan {}  t={:.3f}  {}  score {:.4f}  dir {:.1f} deg", f.index, f.time, verdict, r.score, dir * kDeg);
  const std::string line2 =
      fmt::format("geometric: {} {:.4f} ({} clusters, {} lines)   information: {} {:.4f}   1 m grid",
                  toString(r.geometric.verdict), r.geometric.score, r.geometric.num_clusters, r.geometric.lines.size(),
                  toString(r.information.verdict), r.information.score);
  const cv::Scalar text = r.degenerate() ? cv::Scalar(0, 0, 200) : cv::Scalar(0, 0, 0);
  cv::putText(img, line1, {8, 16}, cv::FONT_HERSHEY_SIMPLEX, 0.5, text, 1, cv::LINE_AA);
  cv::putText(img, line2, {8, 34}, cv::FONT_HERSHEY_SIMPLEX, 0.42, cv::Scalar(60, 60, 60), 1, cv::LINE_AA);
  const auto png = io::encodePng(img.data, img.cols, img.rows, 3, img.step, path);
  io::writeFileAtomically(path, std::string(png.begin(), png.end()));
}

void run(const DegeneracyArgs& a) {
  const CreatedFolders out_folders = prepareOutputFile(a.output);
  const auto t_start = std::chrono::steady_clock::now();
  if (const std::string bad = a.options.check(); !bad.empty())
    throw invalidArgument(fmt::format("invalid degeneracy option: {}", bad));
  auto source = io::prefetch(io::openLog(a.log, a.reader));
  io::AtomicFile out(a.output);
  out.stream() << fmt::format("# lidar2d degeneracy: geometric threshold {} (eps {} m), information threshold {}\n",
                              a.options.geometric.threshold, a.options.geometric.cluster_eps_m,
                              a.options.information.threshold);
  out.stream() << kHeader;
  if (!a.snapshots.empty()) {
    std::error_code ec;
    std::filesystem::create_directories(a.snapshots, ec);
    if (ec || !std::filesystem::is_directory(a.snapshots))
      throw ioError("cannot create the snapshot folder", ErrorLocation(a.snapshots));
  }
  std::size_t scans = 0, degenerate = 0, undecided = 0, snapshots = 0, repeats = 0;
  std::optional<std::size_t> last_snapshot;
  double analyze_s = 0.0, prev_t = std::nan("");
  RateProgress progress(a.quiet, "degeneracy", "scans", source->sizeHint());
  while (auto f = source->next()) {
    progress.update(scans);
    ++scans;
    repeats += f->time == prev_t;
    prev_t = f->time;
    const Points2 pts = f->scan.toPoints(f->T_robot_laser);
    const auto t0 = std::chrono::steady_clock::now();
    const degeneracy::Result r = degeneracy::analyze(pts, a.options);
    analyze_s += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    const bool flag = r.verdict != degeneracy::Verdict::kWellConstrained;
    degenerate += r.degenerate();
    undecided += r.verdict == degeneracy::Verdict::kCannotDecide;
    if (r.verdict == degeneracy::Verdict::kCannotDecide)
      out.stream() << fmt::format("{:.6f} 1 nan nan\n", f->time);
    else
      out.stream() << fmt::format("{:.6f} {} {:.6f} {:.6f}\n", f->time, flag ? 1 : 0, r.score, r.direction_rad);
    if (!a.snapshots.empty() && snapshots < a.max_snapshots) {
      const bool eligible = !a.snapshot_degenerate_only || r.degenerate();
      const bool due = !last_snapshot || f->index >= *last_snapshot + a.snapshot_every;
      if (eligible && due) {
        writeSnapshot((std::filesystem::path(a.snapshots) / fmt::format("scan_{:06d}.png", f->index)).string(), *f, pts,
                      r, a.snapshot_range_m);
        last_snapshot = f->index;
        ++snapshots;
      }
    }
  }
  progress.clear();
  if (scans == 0) throw badInput("log has no scans", ErrorLocation(a.log));
  out.commit();
  if (!a.quiet) {
    const double total_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t_start).count();
    std::cerr << fmt::format(
        "{} scans: {} degenerate ({:.1f}%), {} cannot decide, {} well constrained; {:.3f} ms per scan (analysis), "
        "{:.2f} "
        "s in all -> {}\n",
        scans, degenerate, 100.0 * static_cast<double>(degenerate) / static_cast<double>(scans), undecided,
        scans - degenerate - undecided, 1e3 * analyze_s / static_cast<double>(scans), total_s, a.output);
    if (repeats)
      std::cerr << fmt::format("note: {} scans repeat the previous scan's timestamp; lines are in scan order\n",
                               repeats);
    if (!a.snapshots.empty()) std::cerr << fmt::format("{} snapshots -> {}\n", snapshots, a.snapshots);
  }
}

}  // namespace

void addDegeneracyCommand(CLI::App& app) {
  auto a = std::make_shared<DegeneracyArgs>();
  auto* sub = app.add_subcommand(
      "degeneracy",
      "Per-scan degeneracy: writes 't degenerate(0/1) score direction_rad' per scan (is translation along some "
      "direction unconstrained, as in a corridor?)");
  sub->add_option("LOG", a->log, "log file (any format lidar2d reads)")->required();
  sub->add_option("-o,--output", a->output, "output file")->required();
  sub->add_option("--snapshots", a->snapshots, "folder for PNG pictures of chosen scans (clusters, lines, verdict)");
  sub->add_option("--snapshot-every", a->snapshot_every, "at most one snapshot per this many scans")
      ->check(positiveNumber())
      ->capture_default_str();
  sub->add_option("--max-snapshots", a->max_snapshots, "stop drawing after this many snapshots")->capture_default_str();
  sub->add_flag("--snapshot-degenerate", a->snapshot_degenerate_only, "draw only scans flagged degenerate");
  sub->add_option("--snapshot-range", a->snapshot_range_m, "half-width of the snapshot pictures [m]")
      ->check(CLI::Range(0.1, 1e5))
      ->capture_default_str();
  sub->add_option("--geo-threshold", a->options.geometric.threshold, "geometric detector: degenerate below this score")
      ->capture_default_str();
  sub->add_option("--info-threshold", a->options.information.threshold,
                  "information detector: degenerate below this score")
      ->capture_default_str();
  sub->add_option("--eps", a->options.geometric.cluster_eps_m, "DBSCAN neighbourhood radius [m]")
      ->capture_default_str();
  sub->add_flag("-q,--quiet", a->quiet, "no summary on stderr");
  addReaderOptions(sub, a->reader);
  sub->callback([a] { run(*a); });
}

}  // namespace lidar2d::cli
