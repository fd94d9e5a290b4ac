// The localization database: the virtual scans of a map's free space, their lines and range
// profiles (Database::build), and the k-d tree over line pairs the query looks up (buildIndex).

#include <fmt/format.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <memory>
#include <thread>

#include "lidar2d/core/error.hpp"
#include "lidar2d/geometry/ray_cast.hpp"
#include "lidar2d/localization/localizer.hpp"
#include "src/localization/internal/database_index.hpp"

namespace lidar2d::localization {

using internal::badOption;
using internal::kPi;
using internal::kTwoPi;
using internal::sectorOf;
using internal::wrapTwoPi;

namespace {

// Grid positions (before the clearance test) a database may be built over: 10^7 is a 630 m square
// at the default 0.2 m step, hours of virtual scans and gigabytes of memory.
constexpr double kMaxGridPositions = 1e7;
// The clearance in cells a database build tests around each position, at most.
constexpr double kMaxClearanceCells = 500;
// Coarsest map resolution a database is built for: beyond it a wall is one blurred cell, the
// query's 0.1 m hit distance and 0.3 m success tolerance are below a cell, and corridors are one
// or two cells wide (no position keeps its clearance).
constexpr double kMaxResolution = 0.2;

}  // namespace

void DatabaseOptions::validate() const {
  if (!(step_m > 0) || !std::isfinite(step_m)) throw badOption("step_m", step_m);
  if (beams < 8 || beams > 100000) throw badOption("beams", beams);
  if (!(fov_rad > 0) || !(fov_rad <= kTwoPi + 1e-9)) throw badOption("fov_rad", fov_rad);
  if (!(max_range_m > 0) || !std::isfinite(max_range_m)) throw badOption("max_range_m", max_range_m);
  if (!(clearance_m >= 0) || !(clearance_m <= 100)) throw badOption("clearance_m", clearance_m);
  if (occupied_min < 1 || occupied_min > 100) throw badOption("occupied_min", occupied_min);
  if (free_max < 0 || free_max > 99 || free_max >= occupied_min) throw badOption("free_max", free_max);
  if (max_lines < 2 || max_lines > 64) throw badOption("max_lines", static_cast<double>(max_lines));
  if (!(min_pair_angle_rad >= 0) || !(min_pair_angle_rad <= kPi / 2))
    throw badOption("min_pair_angle_rad", min_pair_angle_rad);
  if (!(key_angle_scale_m_per_rad > 0) || !std::isfinite(key_angle_scale_m_per_rad))
    throw badOption("key_angle_scale_m_per_rad", key_angle_scale_m_per_rad);
  if (profile_bins != 0 && (profile_bins < 8 || profile_bins > 720)) throw badOption("profile_bins", profile_bins);
  lines.validate();
}

void Database::Impl::buildIndex() {
  pairs.clear();
  const double min_sin = std::sin(options.min_pair_angle_rad);
  const double k = options.key_angle_scale_m_per_rad;
  line_position.assign(lines.size(), 0);
  float max_distance = 0.0f;
  for (std::uint32_t p = 0; p < positions.size(); ++p)
    for (std::uint32_t a = 0; a < positions[p].num_lines; ++a) {
      line_position[positions[p].first_line + a] = p;
      max_distance = std::max(max_distance, lines[positions[p].first_line + a].distance);
    }
  key_scale.unit[0] = key_scale.unit[1] = std::max(max_distance, 1e-3f) / 65535.0f;
  key_scale.unit[2] = static_cast<float>(k * kTwoPi / 65535.0);
  // Two passes (count, then fill) so that the largest array of the database is allocated once.
  auto for_each_pair = [&](auto&& emit) {
    for (const Position& pos : positions)
      for (std::uint32_t a = 0; a < pos.num_lines; ++a)
        for (std::uint32_t b = a + 1; b < pos.num_lines; ++b) {
          const LineFeature& la = lines[pos.first_line + a];
          const LineFeature& lb = lines[pos.first_line + b];
          const double rel = wrapTwoPi(static_cast<double>(lb.normal_angle) - la.normal_angle);
          if (std::abs(std::sin(rel)) < min_sin) continue;
          emit(pos.first_line + a, b - a, la.distance, lb.distance, k * rel);
        }
  };
  std::size_t n_pairs = 0;
  for_each_pair([&](std::uint32_t, std::uint32_t, float, float, double) { ++n_pairs; });
  pairs.reserve(n_pairs);
  for_each_pair([&](std::uint32_t ref, std::uint32_t delta, float da, float db, double ka) {
    internal::Pair pr;
    pr.key[0] = key_scale.quantize(0, da);
    pr.key[1] = key_scale.quantize(1, db);
    pr.key[2] = key_scale.quantize(2, ka);
    pr.other_delta = static_cast<std::uint16_t>(delta);
    pr.ref = ref;
    pairs.push_back(pr);
  });
  coarse.clear();
  if (!profiles.empty()) {
    const auto B = static_cast<std::size_t>(options.profile_bins);
    coarse_factor = B % 3 == 0 ? 3 : (B % 2 == 0 ? 2 : 1);
    const std::size_t C = B / coarse_factor;
    coarse.resize(C * positions.size());
    for (std::size_t p = 0; p < positions.size(); ++p) {
      const float* prof = profiles.data() + p * B;
      for (std::size_t c = 0; c < C; ++c)
        coarse[p * C + c] = *std::min_element(prof + c * coarse_factor, prof + (c + 1) * coarse_factor);
    }
  }
  tree.build(pairs, key_scale);
}

Database::Database() : impl_(std::make_unique<Impl>()) {}
Database::~Database() = default;
Database::Database(Database&& o) noexcept : impl_(std::move(o.impl_)) {}
Database& Database::operator=(Database&& o) noexcept {
  impl_ = std::move(o.impl_);
  return *this;
}

const DatabaseOptions& Database::options() const { return impl_->options; }
std::uint64_t Database::mapChecksum() const { return impl_->map_checksum; }
const std::vector<Database::Position>& Database::positions() const { return impl_->positions; }
const std::vector<Database::LineFeature>& Database::lines() const { return impl_->lines; }
const std::vector<float>& Database::profiles() const { return impl_->profiles; }
std::size_t Database::numPairs() const { return impl_->pairs.size(); }
double Database::coverage() const { return impl_->coverage; }
bool Database::empty() const { return impl_->pairs.empty(); }
std::size_t Database::memoryBytes() const {
  const Impl& d = *impl_;
  return d.positions.capacity() * sizeof(Position) + d.lines.capacity() * sizeof(LineFeature) +
         d.line_position.capacity() * sizeof(std::uint32_t) + d.pairs.capacity() * sizeof(internal::Pair) +
         d.tree.memoryBytes() + (d.profiles.capacity() + d.coarse.capacity()) * sizeof(float);
}

std::uint64_t mapChecksum(const OccupancyImage& map) {
  std::uint64_t h = 1469598103934665603ULL;
  auto mix = [&h](const void* data, std::size_t n) {
    const auto* b = static_cast<const unsigned char*>(data);
    for (std::size_t i = 0; i < n; ++i) {
      h ^= b[i];
      h *= 1099511628211ULL;
    }
  };
  const std::int32_t w = map.width(), hh = map.height();
  const double v[4] = {map.resolution(), map.origin().x(), map.origin().y(), map.origin().theta()};
  mix(&w, sizeof w);
  mix(&hh, sizeof hh);
  mix(v, sizeof v);
  mix(map.cells().data(), map.cells().size());
  return h;
}

Database Database::build(const OccupancyImage& map, const DatabaseOptions& options, unsigned threads,
                         ProgressCallback progress, void* progress_user) {
  options.validate();
  const int W = map.width(), H = map.height();
  const double res = map.resolution();
  if (W <= 0 || H <= 0 || !(res > 0)) throw badInput("the map is empty", ErrorLocation({}, 0, "map"));
  const std::size_t n_cells = static_cast<std::size_t>(W) * static_cast<std::size_t>(H);
  std::vector<std::uint8_t> obstacle(n_cells), free(n_cells);
  for (std::size_t i = 0; i < n_cells; ++i) {
    const int v = map.cells()[i];
    obstacle[i] = v >= options.occupied_min;
    free[i] = v >= 0 && v <= options.free_max;
  }

  // Positions: a grid over the map (map frame) keeping the clearance from every non-free cell.
  // An absurd grid (a huge map, a tiny step) is an error up front rather than hours of work and
  // then an out-of-memory crash.
  const double grid_positions = std::ceil(W * res / options.step_m) * std::ceil(H * res / options.step_m);
  if (grid_positions > kMaxGridPositions)
    throw badInput(
        fmt::format("the map spans {:.0f} m x {:.0f} m, which at a step of {} m is {:.3g} database positions, "
                    "more than the limit of {:.0f}: use a step of at least {:.2f} m",
                    W * res, H * res, options.step_m, grid_positions, kMaxGridPositions,
                    std::sqrt(W * res * H * res / kMaxGridPositions) * 1.01),
        ErrorLocation({}, 0, "step"));
  if (res > kMaxResolution + 1e-9)
    throw badInput(fmt::format("the map's cells are {} m, coarser than {} m: too coarse to match a scan against "
                               "(rasterise the map at {} m or finer)",
                               res, kMaxResolution, kMaxResolution),
                   ErrorLocation({}, 0, "resolution"));
  // (Each candidate tests the disc of cells within the clearance: bounded, as a clearance of many
  // cells at a fine resolution would test millions per position.)
  if (options.clearance_m / res > kMaxClearanceCells)
    throw badInput(fmt::format("a clearance of {} m is {:.0f} cells of this map's {} m, more than the limit of {:.0f}",
                               options.clearance_m, std::ceil(options.clearance_m / res), res, kMaxClearanceCells),
                   ErrorLocation({}, 0, "clearance"));
  const int clear = static_cast<int>(std::ceil(options.clearance_m / res));
  std::vector<Eigen::Vector2i> offsets;
  for (int dy = -clear; dy <= clear; ++dy)
    for (int dx = -clear; dx <= clear; ++dx)
      if ((dx * dx + dy * dy) * res * res <= options.clearance_m * options.clearance_m + 1e-12)
        offsets.emplace_back(dx, dy);
  std::vector<Eigen::Vector2d> cand;  // map frame [m]
  std::vector<std::size_t> cand_square;  // index of its square of the grid of positions
  const auto GW = static_cast<std::size_t>(std::ceil(W * res / options.step_m));
  const auto GH = static_cast<std::size_t>(std::ceil(H * res / options.step_m));
  for (double y = 0.5 * options.step_m; y < H * res; y += options.step_m)
    for (double x = 0.5 * options.step_m; x < W * res; x += options.step_m) {
      const int cx = static_cast<int>(x / res), cy = static_cast<int>(y / res);
      bool ok = true;
      for (const auto& o : offsets) {
        const int qx = cx + o.x(), qy = cy + o.y();
        if (qx < 0 || qy < 0 || qx >= W || qy >= H ||
            !free[static_cast<std::size_t>(qy) * static_cast<std::size_t>(W) + static_cast<std::size_t>(qx)]) {
          ok = false;
          break;
        }
      }
      if (ok) {
        cand.emplace_back(x, y);
        cand_square.push_back(std::min(GH - 1, static_cast<std::size_t>(y / options.step_m)) * GW +
                              std::min(GW - 1, static_cast<std::size_t>(x / options.step_m)));
      }
    }
  if (cand.empty())
    throw badInput(fmt::format("the map has no free cell {:.2f} m away from obstacles and unknown space "
                               "(nothing to localize in)",
                               options.clearance_m),
                   ErrorLocation({}, 0, "free space"));

  // Virtual scans, line extraction: in parallel over positions. Rays leap over open space
  // (geometry::castRayInClearance: castRay's answer in a fraction of the cell visits).
  // (The per-cell arrays are released as soon as they have served: on a large map each is tens of
  // megabytes, and the index built last is the peak of the build's memory.)
  if (threads == 0) threads = std::max(1u, std::thread::hardware_concurrency());
  auto clearance_grid = std::make_unique<geometry::ClearanceGrid>(obstacle, W, H, threads);
  const geometry::ClearanceGrid& clearance = *clearance_grid;
  std::vector<std::uint8_t>().swap(obstacle);
  const int n_orient = std::max(1, static_cast<int>(std::ceil(kTwoPi / options.fov_rad - 1e-9)));
  const double inc = options.fov_rad >= kTwoPi - 1e-9 ? kTwoPi / options.beams : options.fov_rad / (options.beams - 1);
  const double a0 = options.fov_rad >= kTwoPi - 1e-9 ? -kPi : -0.5 * options.fov_rad;
  const double max_cells = options.max_range_m / res;
  const double yaw = map.origin().theta();
  const auto B = static_cast<std::size_t>(options.profile_bins);
  // Every beam's direction in the map frame (ray casting) and the world frame (its point), and its
  // profile sector: the same for every position.
  std::vector<Eigen::Vector2d> dir_map, dir_world;
  std::vector<std::size_t> sector;
  for (int o = 0; o < n_orient; ++o)
    for (int b = 0; b < options.beams; ++b) {
      const double a_world = o * kTwoPi / n_orient + a0 + b * inc;  // beam angle in the world frame
      const double a_map = a_world - yaw;
      dir_map.emplace_back(std::cos(a_map), std::sin(a_map));
      dir_world.emplace_back(std::cos(a_world), std::sin(a_world));
      sector.push_back(B > 0 ? sectorOf(a_world, B) : 0);
    }
  // Lines of each candidate, compact (the Line of the extraction holds its points' fit as well).
  std::vector<std::vector<LineFeature>> per_pos(cand.size());
  std::vector<float> cand_profiles(cand.size() * B, static_cast<float>(options.max_range_m));
  std::atomic<std::size_t> next{0}, done{0};
  threads = static_cast<unsigned>(std::min<std::size_t>(threads, cand.size()));
  auto worker = [&](bool report) {
    Points2 pts;
    std::vector<Line> all;
    std::vector<double> range(dir_map.size());
    for (std::size_t i; (i = next.fetch_add(1)) < cand.size();) {
      // Range to the first obstacle cell [cells], +inf when nothing is hit within max_cells.
      geometry::castRaysInClearance(cand[i] / res, dir_map.data(), dir_map.size(), max_cells, clearance, range.data());
      all.clear();
      for (int o = 0; o < n_orient; ++o) {
        pts.clear();
        for (int b = 0; b < options.beams; ++b) {
          const std::size_t k =
              static_cast<std::size_t>(o) * static_cast<std::size_t>(options.beams) + static_cast<std::size_t>(b);
          // Plus half a cell: a real return lies inside the cell, on average at its middle.
          const double r = range[k] + 0.5;
          if (std::isfinite(r))
            pts.emplace_back(r * res * dir_world[k]);
          else
            pts.emplace_back(std::numeric_limits<double>::quiet_NaN(), 0.0);
          if (B > 0 && std::isfinite(r)) {
            float& v = cand_profiles[i * B + sector[k]];
            v = std::min(v, static_cast<float>(r * res));
          }
        }
        // A NaN between two runs separates them like a gap: split the point list at invalid beams.
        Points2 run;
        auto flush = [&] {
          if (run.size() >= options.lines.min_points) {
            auto ls = extractLines(run, options.lines);
            all.insert(all.end(), ls.begin(), ls.end());
          }
          run.clear();
        };
        for (const auto& p : pts) {
          if (p.allFinite())
            run.push_back(p);
          else
            flush();
        }
        flush();
      }
      // Merge duplicates (same infinite line from two orientations or runs), longest first.
      std::sort(all.begin(), all.end(), [](const Line& x, const Line& y) { return x.length > y.length; });
      std::vector<Line> kept;
      for (const Line& l : all) {
        bool dup = false;
        for (Line& k : kept)
          if (std::abs(angleDiff(l.normal_angle, k.normal_angle)) <= options.lines.merge_angle_rad &&
              std::abs(l.distance - k.distance) <= options.lines.merge_distance_m) {
            k.length += l.length;
            dup = true;
            break;
          }
        if (!dup) kept.push_back(l);
      }
      if (kept.size() > options.max_lines) kept.resize(options.max_lines);
      std::vector<LineFeature>& out = per_pos[i];
      out.reserve(kept.size());
      for (const Line& l : kept)
        out.push_back(
            {static_cast<float>(l.normal_angle), static_cast<float>(l.distance), static_cast<float>(l.length)});
      const std::size_t d = done.fetch_add(1) + 1;
      if (report && progress && (d % 256 == 0 || d == cand.size())) progress(d, cand.size(), progress_user);
    }
  };
  std::vector<std::thread> pool;
  for (unsigned t = 1; t < threads; ++t) pool.emplace_back(worker, false);
  worker(true);
  for (auto& t : pool) t.join();
  if (progress) progress(cand.size(), cand.size(), progress_user);
  clearance_grid.reset();

  std::vector<Position> positions;
  std::vector<LineFeature> lines;
  std::vector<float> profiles;
  std::vector<std::uint8_t> indexed_square(GW * GH, 0);
  std::size_t n_lines = 0;
  for (const auto& l : per_pos) n_lines += l.size();
  lines.reserve(n_lines);
  profiles.reserve(cand_profiles.size());
  for (std::size_t i = 0; i < cand.size(); ++i) {
    // A position with fewer than two lines gives no pair but may still be found by its profile.
    if (per_pos[i].size() < 2 && B == 0) continue;
    indexed_square[cand_square[i]] = 1;
    // Whole centimetres, as the database file stores them (a loaded database answers alike).
    for (std::size_t k = 0; k < B; ++k)
      profiles.push_back(static_cast<float>(std::round(cand_profiles[i * B + k] * 100.0) / 100.0));
    const Eigen::Vector2d w = map.origin() * (cand[i]);
    Position p;
    p.x = static_cast<float>(w.x());
    p.y = static_cast<float>(w.y());
    p.first_line = static_cast<std::uint32_t>(lines.size());
    p.num_lines = static_cast<std::uint32_t>(per_pos[i].size());
    lines.insert(lines.end(), per_pos[i].begin(), per_pos[i].end());
    std::vector<LineFeature>().swap(per_pos[i]);
    positions.push_back(p);
  }
  std::vector<float>().swap(cand_profiles);
  // Coverage: the share of free cells whose square of the grid of positions holds an indexed
  // position (a scan taken there is near a virtual scan of the database).
  std::size_t n_free = 0, n_covered = 0;
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      if (!free[static_cast<std::size_t>(y) * static_cast<std::size_t>(W) + static_cast<std::size_t>(x)]) continue;
      ++n_free;
      const auto gx = std::min(GW - 1, static_cast<std::size_t>((x + 0.5) * res / options.step_m));
      const auto gy = std::min(GH - 1, static_cast<std::size_t>((y + 0.5) * res / options.step_m));
      n_covered += indexed_square[gy * GW + gx];
    }
  std::vector<std::uint8_t>().swap(free);
  std::vector<std::uint8_t>().swap(indexed_square);
  Database db = fromParts(options, localization::mapChecksum(map), std::move(positions), std::move(lines),
                          std::move(profiles));
  db.impl_->coverage = n_free ? static_cast<double>(n_covered) / static_cast<double>(n_free) : 0.0;
  return db;
}

Database Database::fromParts(const DatabaseOptions& options, std::uint64_t map_checksum,
                             std::vector<Position> positions, std::vector<LineFeature> lines,
                             std::vector<float> profiles) {
  options.validate();
  if (!profiles.empty() && profiles.size() != positions.size() * static_cast<std::size_t>(options.profile_bins))
    throw badInput(fmt::format("database profiles hold {} values, {} positions x {} bins expected", profiles.size(),
                               positions.size(), options.profile_bins),
                   ErrorLocation({}, 0, "profiles"));
  for (std::size_t i = 0; i < profiles.size(); ++i)
    if (!std::isfinite(profiles[i]) || !(profiles[i] >= 0))
      throw badInput(fmt::format("database profile value {} is invalid", i), ErrorLocation({}, 0, "profiles"));
  for (std::size_t i = 0; i < positions.size(); ++i) {
    const Position& p = positions[i];
    if (!std::isfinite(p.x) || !std::isfinite(p.y) ||
        static_cast<std::uint64_t>(p.first_line) + p.num_lines > lines.size() || p.num_lines > 65535)
      throw badInput(fmt::format("database position {} is invalid (non-finite, lines out of range or more than "
                                 "65535 lines)",
                                 i),
                     ErrorLocation({}, 0, "positions"));
  }
  for (std::size_t i = 0; i < lines.size(); ++i)
    if (!std::isfinite(lines[i].normal_angle) || !std::isfinite(lines[i].distance) || !(lines[i].distance >= 0))
      throw badInput(fmt::format("database line {} is invalid", i), ErrorLocation({}, 0, "lines"));
  Database db;
  db.impl_->options = options;
  db.impl_->map_checksum = map_checksum;
  db.impl_->positions = std::move(positions);
  db.impl_->lines = std::move(lines);
  db.impl_->profiles = std::move(profiles);
  db.impl_->buildIndex();
  return db;
}

}  // namespace lidar2d::localization
