// lidar2d map LOG --model logodds|count|tsdf -o PREFIX: an occupancy map from known poses.

#include <fmt/format.h>

#include <chrono>
#include <filesystem>
#include <iostream>
#include <map>
#include <memory>
#include <optional>
#include <vector>

#include "commands.hpp"
#include "lidar2d/core/error.hpp"
#include "lidar2d/io/atomic_file.hpp"
#include "lidar2d/io/image.hpp"
#include "lidar2d/io/map_file.hpp"
#include "lidar2d/io/trajectory.hpp"
#include "lidar2d/mapping/export.hpp"
#include "lidar2d/mapping/map_builder.hpp"
#include "lidar2d/mapping/occupancy_map.hpp"
#include "map_input.hpp"
#include "map_output.hpp"
#include "progress.hpp"

namespace lidar2d::cli {
namespace {

struct MapArgs {
  std::string log;
  std::string prefix;
  std::string poses_file;
  std::string prior;
  BareMapOptions prior_bare{.resolution_flag = "--prior-resolution",
                            .origin_flag = "--prior-origin",
                            .rows_up_flag = "--prior-image-rows-up",
                            .resolution = {},
                            .origin = {}};
  mapping::MapModel model = mapping::MapModel::kLogOdds;
  mapping::PoseSource pose_source = mapping::PoseSource::kAuto;
  mapping::MapOptions options;
  double max_dt = 0.001;
  bool quiet = false;
  io::ReaderOptions reader;
};

// The prior layer, read before any mapping so that a bad mask fails before the work: a map aligned
// by world coordinates (a map_server YAML, or a bare image with --prior-resolution), or the cells of
// a bare image of exactly the output map's size (black = occupied, white = free, any other grey = no
// override: the PNG/PGM that `lidar2d map` wrote, painted over, works directly).
struct Prior {
  std::optional<OccupancyImage> aligned;
  std::vector<std::int8_t> cells;
  int width = 0, height = 0;
};

Prior readPrior(const std::string& path, const BareMapOptions& bare) {
  Prior p;
  try {
    if (!io::isMapImage(path) || bare.given()) {
      p.aligned = readMapChecked(path, bare).map;
      return p;
    }
    const io::GreyImage img = io::readGreyImage(path, "prior");
    p.cells.resize(img.value.size());
    p.width = img.width;
    p.height = img.height;
    const auto w = static_cast<std::size_t>(img.width);
    for (int r = 0; r < img.height; ++r)
      for (int c = 0; c < img.width; ++c) {
        const std::uint8_t v = img.value[static_cast<std::size_t>(img.height - 1 - r) * w + static_cast<std::size_t>(c)];
        p.cells[static_cast<std::size_t>(r) * w + static_cast<std::size_t>(c)] =
            v < 50 ? OccupancyImage::kOccupied : (v > 250 ? OccupancyImage::kFree : OccupancyImage::kUnknown);
      }
    return p;
  } catch (const Error& e) {
    if (!e.where().file.empty()) throw;
    throw Error(e.kind(), e.message(), ErrorLocation(path, 0, e.where().field));
  }
}

OccupancyImage overrideWithPrior(const Prior& prior, const std::string& path, const OccupancyImage& map,
                          std::size_t& overridden) {
  OccupancyImage out = map;
  try {
    overridden = prior.aligned ? mapping::applyPrior(out, *prior.aligned)
                               : mapping::applyPriorSameSize(out, prior.cells, prior.width, prior.height);
    return out;
  } catch (const Error& e) {
    if (!e.where().file.empty()) throw;
    throw Error(e.kind(), e.message(), ErrorLocation(path, 0, e.where().field));
  }
}

void run(const MapArgs& a) {
  const CreatedFolders out_folders = prepareOutputFile(a.prefix + ".yaml");
  const auto t0 = std::chrono::steady_clock::now();
  std::optional<Prior> prior;
  if (!a.prior.empty()) {
    prior = readPrior(a.prior, a.prior_bare);
  } else if (a.prior_bare.given()) {
    throw CLI::ValidationError("--prior-resolution/--prior-origin", "apply to a bare --prior image; no --prior given");
  }
  auto map = mapping::makeMap(a.model, a.options);
  // With a range table given file by file, --poses is the table's poses file (its truth), read by
  // the log reader, not a trajectory.
  const std::string poses_file = a.reader.range_table ? std::string() : a.poses_file;
  mapping::FramePoses poses = poses_file.empty()
                                  ? mapping::FramePoses::fromFrames(a.pose_source, "use --poses TRAJ or --pose-source")
                                  : mapping::FramePoses::fromTrajectory(io::readTrajectory(poses_file), a.max_dt, poses_file);
  auto source = io::openLog(a.log, a.reader);
  RateProgress progress(a.quiet, "mapping", "scans", source->sizeHint());
  mapping::MapBuilder builder(*map, std::move(poses), {.source_name = a.log});
  const std::size_t scans =
      builder.insert([&] { return source->next(); }, [&progress](std::size_t done) { progress.update(done); });
  progress.clear();
  if (scans == 0) throw badInput("log has no scans", ErrorLocation(a.log));
  warnAboutLog(a.log, *source);
  OccupancyImage image = mapping::toOccupancyImage(*map);
  std::size_t overridden = 0;
  if (prior) image = overrideWithPrior(*prior, a.prior, image, overridden);
  std::string comment = fmt::format("lidar2d map: {} model, {} scans of {}", mapping::toString(a.model), scans,
                                    std::filesystem::path(a.log).filename().string());
  if (!a.prior.empty())
    comment += fmt::format(
        "\nprior layer {} overrides the sensor in {} cells of the image: black mask cells are occupied, white ones\n"
        "free, grey ones keep the sensor's verdict (lidar2d map --prior; docs/mapping.md)",
        std::filesystem::path(a.prior).filename().string(), overridden);
  // The files are staged and appear together: a failed write leaves the folder as it was.
  const std::filesystem::path prefix(a.prefix);
  io::OutputSet outputs(prefix.parent_path().string());
  const std::string name = prefix.filename().string();
  writeMapFiles(outputs, name, image, comment);
  if (a.model == mapping::MapModel::kTsdf) {
    const auto surface = mapping::tsdfSurface(*map);
    io::AtomicFile f(outputs.stage(name + ".surface.txt"));
    f.stream() << "# lidar2d TSDF surface: sub-cell zero crossings, one per line: x y weight [m, m, observations]\n";
    for (const auto& s : surface) f.stream() << fmt::format("{:.4f} {:.4f} {:.0f}\n", s.p_world.x(), s.p_world.y(), s.weight);
    f.commit();
  }
  const std::vector<std::string> written = outputs.commit();
  const double secs = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  if (!a.quiet) {
    std::cerr << fmt::format("mapped {} scans ({} model, {} m cells) in {:.3f} s: {} x {} cells, {:.1f} M cell updates",
                             scans, mapping::toString(a.model), a.options.resolution_m, secs, image.width(),
                             image.height(), static_cast<double>(map->cellUpdates()) / 1e6);
    if (!a.prior.empty()) std::cerr << fmt::format(", prior overrode {} cells", overridden);
    std::cerr << "\n";
    for (const auto& w : written) std::cout << w << "\n";
  }
}

}  // namespace

void addMapCommand(CLI::App& app) {
  auto a = std::make_shared<MapArgs>();
  auto* sub = app.add_subcommand("map", "Occupancy map from the log's poses (or --poses) as a map_server PGM + YAML and a PNG");
  sub->add_option("LOG", a->log, "log file (any format lidar2d reads)")->required();
  sub->add_option("-o,--output", a->prefix, "output prefix: writes PREFIX.pgm, PREFIX.yaml, PREFIX.png (+ PREFIX.surface.txt for tsdf)")
      ->required();
  addChoice<mapping::MapModel>(sub, "--model", a->model,
                               {{"logodds", mapping::MapModel::kLogOdds},
                                {"count", mapping::MapModel::kCount},
                                {"tsdf", mapping::MapModel::kTsdf}},
                               "map model: logodds, count or tsdf")
      ->default_str("logodds");
  sub->add_option("--resolution", a->options.resolution_m, "cell size [m]")->default_val(0.05);
  sub->add_option("--max-range", a->options.insert.max_range_m, "returns beyond this are treated as no return [m]")
      ->default_val(30.0);
  sub->add_option("--no-return-clear", a->options.insert.no_return_clear_m,
                  "beams without a return clear free space up to this distance [m] (0: ignore them)")
      ->default_val(5.0);
  sub->add_option("--surface-guard", a->options.insert.surface_guard_max_m,
                  "logodds/count: a scan does not clear the cells of the surfaces it saw (grazing beams, edges of "
                  "obstacles); longest surface segment between two returns kept [m] (0: off)")
      ->default_val(1.0);
  sub->add_option("--threads", a->options.insert.threads,
                  "insertion threads: 1, or 2 (larger values too) to split each scan between two")
      ->default_val(a->options.insert.threads);
  sub->add_option("--cell-budget", a->options.insert.cell_budget, "largest map extent allowed [cells]")->default_val(1000000000);
  sub->add_flag("--classic", a->options.logodds.classic_integer,
                "logodds: the classic integer scheme (+2 per hit, -1 per pass, 1..100 around 50)");
  sub->add_option("--truncation", a->options.tsdf.truncation_m, "tsdf: truncation distance [m]")->default_val(0.3);
  sub->add_option("--poses", a->poses_file, "trajectory file (t x y theta or TUM) giving the pose of every scan");
  sub->add_option("--max-dt", a->max_dt, "--poses: largest timestamp difference to accept [s]")->default_val(0.001);
  addChoice<mapping::PoseSource>(sub, "--pose-source", a->pose_source,
                                 {{"auto", mapping::PoseSource::kAuto},
                                  {"truth", mapping::PoseSource::kTruth},
                                  {"odometry", mapping::PoseSource::kOdometry}},
                                 "without --poses: auto (truth if present, else odometry), truth or odometry")
      ->default_str("auto");
  sub->add_option("--prior", a->prior,
                  "prior layer overriding the sensor: a map_server YAML or a bare PGM/PNG image with --prior-resolution "
                  "(aligned by world coordinates), or an image of the output's size; black = occupied, white = free, "
                  "grey = no override");
  addBareMapOptions(sub, a->prior_bare, "--prior");
  sub->add_flag("-q,--quiet", a->quiet, "print nothing on success");
  addReaderOptions(sub, a->reader);
  sub->callback([a] { run(*a); });
}

}  // namespace lidar2d::cli
