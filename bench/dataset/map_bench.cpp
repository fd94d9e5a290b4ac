// Mapping on the corrected Radish logs with their truth poses:
// - speed: all scans inserted, per model and thread count (InsertOptions::threads; the maps are
//   identical; 2 with and without the adaptive back-off): ms per scan, cell updates per second, share of scans split
//   between two threads;
// - OccupancyMap::prepare alone, with and without the surface guard (a table of its own);
// - consistency: a map from the even-numbered scans must explain the odd-numbered ones: the
//   fraction of their beam endpoints (ranges under 20 m) within one cell of an occupied cell.

#include <fmt/format.h>

#include <algorithm>
#include <chrono>
#include <filesystem>
#include <iostream>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "dataset_bench.hpp"
#include "lidar2d/io/frame_source.hpp"
#include "lidar2d/mapping/export.hpp"
#include "lidar2d/mapping/map_builder.hpp"
#include "lidar2d/mapping/occupancy_map.hpp"

namespace lidar2d::bench {

std::vector<Frame> loadFrames(const std::string& path) {
  std::vector<Frame> frames;
  auto src = io::openLog(path);
  while (auto f = src->next()) frames.push_back(std::move(*f));
  return frames;
}

std::unique_ptr<mapping::OccupancyMap> evenFramesMap(const std::vector<Frame>& frames, const std::string& name,
                                                     mapping::MapModel model, const mapping::MapOptions& options) {
  auto map = mapping::makeMap(model, options);
  mapping::MapBuilder builder(*map, mapping::FramePoses::fromFrames(mapping::PoseSource::kTruth), {.source_name = name});
  std::size_t next = 0;
  builder.insert([&]() -> std::optional<Frame> {
    if (next >= frames.size()) return std::nullopt;
    const std::size_t i = next;
    next += 2;
    return frames[i];
  });
  return map;
}

namespace {

struct Consistency {
  double explained = 0;      // endpoints within one cell of an occupied cell
  double free_occupied = 0;  // samples along the beams (0.3 m after the laser to 0.2 m before the
                             // return, every 0.25 m) that fall in occupied cells
};

Consistency consistency(const OccupancyImage& map, const std::vector<Frame>& frames, std::size_t first,
                        double max_range) {
  std::size_t n = 0, ok = 0, free_n = 0, free_occ = 0;
  auto occupied = [&map](int col, int row) {
    return map.contains(col, row) && map.at(col, row) == OccupancyImage::kOccupied;
  };
  for (std::size_t i = first; i < frames.size(); i += 2) {
    const Frame& f = frames[i];
    const SE2 T_world_laser = *f.T_world_robot * f.T_robot_laser;
    for (std::size_t b = 0; b < f.scan.size(); ++b) {
      if (!f.scan.isValid(b) || f.scan.ranges()[b] >= max_range) continue;
      const double r = f.scan.ranges()[b];
      const Eigen::Vector2d dir(std::cos(f.scan.angle(b)), std::sin(f.scan.angle(b)));
      ++n;
      if (const auto c = map.worldToCell(T_world_laser * (r * dir))) {
        bool hit = false;
        for (int dy = -1; dy <= 1 && !hit; ++dy)
          for (int dx = -1; dx <= 1 && !hit; ++dx) hit = occupied(c->x() + dx, c->y() + dy);
        ok += hit;
      }
      for (double s = 0.3; s < r - 0.2; s += 0.25)
        if (const auto c = map.worldToCell(T_world_laser * (s * dir))) {
          ++free_n;
          free_occ += occupied(c->x(), c->y());
        }
    }
  }
  Consistency out;
  out.explained = n ? static_cast<double>(ok) / static_cast<double>(n) : 0.0;
  out.free_occupied = free_n ? static_cast<double>(free_occ) / static_cast<double>(free_n) : 0.0;
  return out;
}

}  // namespace

void runMapBenchmark(const std::string& data_dir) {
  const std::vector<std::string> logs{"corrected/intel.log.gz", "corrected/freiburg-079.log.gz",
                                      "corrected/infinite-corridor.log.gz"};
  std::cout << "| dataset | model | threads | scans | split scans | ms/scan | M cells walked/s | M cell updates/s | "
               "map cells | odd endpoints explained | odd free space occupied |\n";
  std::cout << "|---|---|---|---|---|---|---|---|---|---|---|\n";
  std::vector<std::string> prepare_rows;
  for (const auto& rel : logs) {
    const std::string path = (std::filesystem::path(data_dir) / rel).string();
    if (!std::filesystem::exists(path)) {
      std::cout << "| " << rel << " | missing: skipped | | | | | | | | | |\n";
      continue;
    }
    const std::vector<Frame> frames = loadFrames(path);
    // OccupancyMap::prepare alone (part of "ms/scan" above), with and without the surface guard.
    for (const bool guard : {true, false}) {
      mapping::MapOptions o;
      if (!guard) o.insert.surface_guard_max_m = 0.0;
      auto map = mapping::makeMap(mapping::MapModel::kLogOdds, o);
      mapping::OccupancyMap::PreparedScan prepared;
      double best = 1e30;
      for (int rep = 0; rep < 5; ++rep) {
        const auto t0 = std::chrono::steady_clock::now();
        for (const Frame& f : frames) map->prepare(f.scan, *f.T_world_robot * f.T_robot_laser, prepared);
        best = std::min(best, std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
      }
      prepare_rows.push_back(fmt::format("| {} | {} | {:.4f} |\n", std::filesystem::path(rel).stem().stem().string(),
                                         guard ? "on" : "off", 1e3 * best / static_cast<double>(frames.size())));
    }
    // The occupancy models once more without the surface guard (InsertOptions), for comparison.
    for (const auto& [model, guard] : {std::pair{mapping::MapModel::kLogOdds, true}, std::pair{mapping::MapModel::kCount, true},
                                       std::pair{mapping::MapModel::kTsdf, true}, std::pair{mapping::MapModel::kLogOdds, false},
                                       std::pair{mapping::MapModel::kCount, false}}) {
      mapping::MapOptions o;
      if (!guard) o.insert.surface_guard_max_m = 0.0;
      // Consistency: even scans build, odd scans test (the same map for any thread count).
      const OccupancyImage image = mapping::toOccupancyImage(*evenFramesMap(frames, path, model, o));
      const Consistency c = consistency(image, frames, 1, 20.0);
      // Threads 2 twice: with the adaptive back-off (default) and splitting every scan worth it.
      for (const auto& [threads, adaptive] : {std::pair{1u, true}, std::pair{2u, true}, std::pair{2u, false}}) {
        if (!guard && threads > 1) continue;
        o.insert.threads = threads;
        o.insert.adaptive_threads = adaptive;
        // Speed: every scan; best of 5 runs to damp the noise of a shared machine. The map's own
        // insertion (prepare and insert) on this thread, without MapBuilder's read-ahead thread.
        double best = 1e30;
        std::uint64_t updates = 0, visits = 0, split = 0;
        for (int rep = 0; rep < 5; ++rep) {
          auto map = mapping::makeMap(model, o);
          const auto t0 = std::chrono::steady_clock::now();
          for (const Frame& f : frames) map->insert(f.scan, *f.T_world_robot * f.T_robot_laser);
          best = std::min(best, std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
          updates = map->cellUpdates();
          visits = map->cellVisits();
          split = map->parallelScans();
        }
        std::cout << fmt::format("| {} | {} | {} | {} | {:.0f}% | {:.3f} | {:.0f} | {:.0f} | {} x {} | {:.1f}% | {:.2f}% |\n",
                                 std::filesystem::path(rel).stem().stem().string(),
                                 std::string(mapping::toString(model)) + (guard ? "" : " (no guard)"),
                                 threads == 1 ? std::string("1") : (adaptive ? "2" : "2 (no back-off)"),
                                 frames.size(), 100.0 * static_cast<double>(split) / static_cast<double>(frames.size()),
                                 1e3 * best / static_cast<double>(frames.size()), static_cast<double>(visits) / best / 1e6,
                                 static_cast<double>(updates) / best / 1e6, image.width(), image.height(),
                                 100.0 * c.explained, 100.0 * c.free_occupied);
      }
    }
  }
  std::cout << "\nOccupancyMap::prepare alone (log-odds; best of 5):\n\n| dataset | surface guard | ms/scan "
               "|\n|---|---|---|\n";
  for (const std::string& row : prepare_rows) std::cout << row;
}

}  // namespace lidar2d::bench
