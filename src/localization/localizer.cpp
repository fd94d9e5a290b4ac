#include "lidar2d/localization/localizer.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstring>
#include <nanoflann.hpp>
#include <optional>
#include <thread>
#include <unordered_map>

#include "lidar2d/core/error.hpp"
#include "lidar2d/geometry/ray_cast.hpp"
#include "lidar2d/registration/correlative.hpp"
#include "lidar2d/registration/likelihood_field.hpp"

namespace lidar2d::localization {

namespace {

constexpr double kPi = std::numbers::pi;
constexpr double kTwoPi = 2.0 * std::numbers::pi;
// Grid positions (before the clearance test) a database may be built over: 10^7 is a 630 m square
// at the default 0.2 m step, hours of virtual scans and gigabytes of memory.
constexpr double kMaxGridPositions = 1e7;
// The clearance in cells a database build tests around each position, at most.
constexpr double kMaxClearanceCells = 500;

Error badOption(const char* field, double v) {
  return invalidArgument(fmt::format("localization option {} = {} is out of its domain", field, v),
                         ErrorLocation({}, 0, field));
}

// Angle in [0, 2 pi).
double wrapTwoPi(double a) {
  a = std::fmod(a, kTwoPi);
  if (a < 0) a += kTwoPi;
  if (a >= kTwoPi) a -= kTwoPi;
  return a;
}

// Range-profile sector of direction `angle`: sector k covers [-pi + k w, -pi + (k + 1) w), w = 2 pi / bins.
std::size_t sectorOf(double angle, std::size_t bins) {
  return std::min(bins - 1, static_cast<std::size_t>(wrapTwoPi(angle + kPi) / kTwoPi * static_cast<double>(bins)));
}

// One indexed pair: reference line `ref` and second line `other` of position `pos`.
struct Pair {
  float key[3];
  std::uint32_t ref = 0, other = 0, pos = 0;
};

struct PairAdaptor {
  const std::vector<Pair>* pairs = nullptr;
  std::size_t kdtree_get_point_count() const { return pairs->size(); }
  float kdtree_get_pt(std::size_t i, std::size_t dim) const { return (*pairs)[i].key[dim]; }
  template <class BBox>
  bool kdtree_get_bbox(BBox&) const {
    return false;
  }
};

using PairTree = nanoflann::KDTreeSingleIndexAdaptor<nanoflann::L2_Simple_Adaptor<float, PairAdaptor>, PairAdaptor, 3,
                                                     std::uint32_t>;

}  // namespace

// ------------------------------------------------------------------------------------------------
// Options

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

void LocalizerOptions::validate() const {
  lines.validate();
  if (max_query_lines < 2) throw badOption("max_query_lines", static_cast<double>(max_query_lines));
  if (!(key_radius_m > 0) || !std::isfinite(key_radius_m)) throw badOption("key_radius_m", key_radius_m);
  if (!(vote_bin_m > 0) || !std::isfinite(vote_bin_m)) throw badOption("vote_bin_m", vote_bin_m);
  if (!(vote_bin_rad > 0) || !std::isfinite(vote_bin_rad)) throw badOption("vote_bin_rad", vote_bin_rad);
  if (max_candidates < 1) throw badOption("max_candidates", static_cast<double>(max_candidates));
  if (max_refined < 1) throw badOption("max_refined", static_cast<double>(max_refined));
  if (max_verify_points < 10) throw badOption("max_verify_points", static_cast<double>(max_verify_points));
  if (prescore_points < 10) throw badOption("prescore_points", static_cast<double>(prescore_points));
  if (max_free_space_checked < 1)
    throw badOption("max_free_space_checked", static_cast<double>(max_free_space_checked));
  if (!(hit_distance_m > 0) || !std::isfinite(hit_distance_m)) throw badOption("hit_distance_m", hit_distance_m);
  if (!(free_margin_m >= 0) || !std::isfinite(free_margin_m)) throw badOption("free_margin_m", free_margin_m);
  if (!(max_range_m > 0)) throw badOption("max_range_m", max_range_m);
  if (!(min_score >= 0 && min_score <= 1)) throw badOption("min_score", min_score);
  if (!(ambiguity_ratio >= 0 && ambiguity_ratio <= 1)) throw badOption("ambiguity_ratio", ambiguity_ratio);
  if (!(distinct_distance_m >= 0) || !std::isfinite(distinct_distance_m))
    throw badOption("distinct_distance_m", distinct_distance_m);
  if (!(distinct_angle_rad >= 0) || !std::isfinite(distinct_angle_rad))
    throw badOption("distinct_angle_rad", distinct_angle_rad);
}

// ------------------------------------------------------------------------------------------------
// Database

struct Database::Impl {
  DatabaseOptions options;
  std::uint64_t map_checksum = 0;
  std::vector<Position> positions;
  std::vector<LineFeature> lines;
  std::vector<Pair> pairs;
  PairAdaptor adaptor;
  std::unique_ptr<PairTree> tree;
  std::vector<float> profiles;  // profile_bins per position, or empty
  std::vector<float> doubled;   // each profile twice in a row: turning it is then a contiguous slice
  std::size_t coarse_factor = 1;      // sectors merged per coarse sector (the prefilter of the query)
  std::vector<float> coarse_doubled;  // the same at profile_bins / coarse_factor sectors (nearest of each group)

  // Indexes every non-parallel pair of lines of every position (both orders are not needed: the
  // query tries both orders of its own pairs).
  void buildIndex() {
    pairs.clear();
    const double min_sin = std::sin(options.min_pair_angle_rad);
    const double k = options.key_angle_scale_m_per_rad;
    for (std::uint32_t p = 0; p < positions.size(); ++p) {
      const Position& pos = positions[p];
      for (std::uint32_t a = 0; a < pos.num_lines; ++a)
        for (std::uint32_t b = a + 1; b < pos.num_lines; ++b) {
          const LineFeature& la = lines[pos.first_line + a];
          const LineFeature& lb = lines[pos.first_line + b];
          const double rel = wrapTwoPi(static_cast<double>(lb.normal_angle) - la.normal_angle);
          if (std::abs(std::sin(rel)) < min_sin) continue;
          Pair pr;
          pr.key[0] = la.distance;
          pr.key[1] = lb.distance;
          pr.key[2] = static_cast<float>(k * rel);
          pr.ref = pos.first_line + a;
          pr.other = pos.first_line + b;
          pr.pos = p;
          pairs.push_back(pr);
        }
    }
    pairs.shrink_to_fit();
    doubled.clear();
    coarse_doubled.clear();
    if (!profiles.empty()) {
      const auto B = static_cast<std::size_t>(options.profile_bins);
      coarse_factor = B % 3 == 0 ? 3 : (B % 2 == 0 ? 2 : 1);
      const std::size_t C = B / coarse_factor;
      doubled.resize(2 * profiles.size());
      coarse_doubled.resize(2 * C * positions.size());
      for (std::size_t p = 0; p < positions.size(); ++p) {
        const float* prof = profiles.data() + p * B;
        std::copy_n(prof, B, doubled.begin() + static_cast<std::ptrdiff_t>(2 * p * B));
        std::copy_n(prof, B, doubled.begin() + static_cast<std::ptrdiff_t>((2 * p + 1) * B));
        for (std::size_t c = 0; c < C; ++c) {
          const float v = *std::min_element(prof + c * coarse_factor, prof + (c + 1) * coarse_factor);
          coarse_doubled[2 * p * C + c] = coarse_doubled[2 * p * C + C + c] = v;
        }
      }
    }
    adaptor.pairs = &pairs;
    tree = std::make_unique<PairTree>(3, adaptor, nanoflann::KDTreeSingleIndexAdaptorParams(16));
    if (!pairs.empty()) tree->buildIndex();
  }
};

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
bool Database::empty() const { return impl_->pairs.empty(); }
std::size_t Database::memoryBytes() const {
  const Impl& d = *impl_;
  // Tree: one index per pair plus about one node (~48 bytes) per leaf of 16.
  return d.positions.capacity() * sizeof(Position) + d.lines.capacity() * sizeof(LineFeature) +
         d.pairs.capacity() * sizeof(Pair) + d.pairs.size() * (sizeof(std::uint32_t) + 48 / 8) +
         (d.profiles.capacity() + d.doubled.capacity() + d.coarse_doubled.capacity()) * sizeof(float);
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
    throw badInput(fmt::format("the map spans {:.0f} m x {:.0f} m, which at a step of {} m is {:.3g} database positions, "
                               "more than the limit of {:.0f}: use a step of at least {:.2f} m",
                               W * res, H * res, options.step_m, grid_positions, kMaxGridPositions,
                               std::sqrt(W * res * H * res / kMaxGridPositions) * 1.01),
                   ErrorLocation({}, 0, "step"));
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
      if (ok) cand.emplace_back(x, y);
    }
  if (cand.empty())
    throw badInput(fmt::format("the map has no free cell {:.2f} m away from obstacles and unknown space "
                               "(nothing to localize in)",
                               options.clearance_m),
                   ErrorLocation({}, 0, "free space"));

  // Virtual scans, line extraction: in parallel over positions.
  const auto is_obstacle = [&](std::int32_t x, std::int32_t y) {
    return obstacle[static_cast<std::size_t>(y) * static_cast<std::size_t>(W) + static_cast<std::size_t>(x)] != 0;
  };
  const int n_orient = std::max(1, static_cast<int>(std::ceil(kTwoPi / options.fov_rad - 1e-9)));
  const double inc = options.fov_rad >= kTwoPi - 1e-9 ? kTwoPi / options.beams : options.fov_rad / (options.beams - 1);
  const double a0 = options.fov_rad >= kTwoPi - 1e-9 ? -kPi : -0.5 * options.fov_rad;
  const double max_cells = options.max_range_m / res;
  const double yaw = map.origin().theta();
  std::vector<std::vector<Line>> per_pos(cand.size());
  const auto B = static_cast<std::size_t>(options.profile_bins);
  std::vector<float> cand_profiles(cand.size() * B, static_cast<float>(options.max_range_m));
  std::atomic<std::size_t> next{0}, done{0};
  if (threads == 0) threads = std::max(1u, std::thread::hardware_concurrency());
  threads = static_cast<unsigned>(std::min<std::size_t>(threads, cand.size()));
  auto worker = [&](bool report) {
    Points2 pts;
    std::vector<Line> all;
    for (std::size_t i; (i = next.fetch_add(1)) < cand.size();) {
      const Eigen::Vector2d start = cand[i] / res;
      all.clear();
      for (int o = 0; o < n_orient; ++o) {
        pts.clear();
        for (int b = 0; b < options.beams; ++b) {
          const double a_world = o * kTwoPi / n_orient + a0 + b * inc;  // beam angle in the world frame
          const double a_map = a_world - yaw;
          // Range to the first obstacle cell plus half a cell (a real return lies inside the cell,
          // on average at its middle) [cells]; +inf when nothing is hit within max_cells.
          const Eigen::Vector2d dir(std::cos(a_map), std::sin(a_map));
          const double r = geometry::castRay(start, dir, max_cells, W, H, is_obstacle) + 0.5;
          if (std::isfinite(r))
            pts.emplace_back(r * res * std::cos(a_world), r * res * std::sin(a_world));
          else
            pts.emplace_back(std::numeric_limits<double>::quiet_NaN(), 0.0);
          if (B > 0 && std::isfinite(r)) {
            float& v = cand_profiles[i * B + sectorOf(a_world, B)];
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
      per_pos[i] = std::move(kept);
      const std::size_t d = done.fetch_add(1) + 1;
      if (report && progress && (d % 256 == 0 || d == cand.size())) progress(d, cand.size(), progress_user);
    }
  };
  std::vector<std::thread> pool;
  for (unsigned t = 1; t < threads; ++t) pool.emplace_back(worker, false);
  worker(true);
  for (auto& t : pool) t.join();
  if (progress) progress(cand.size(), cand.size(), progress_user);

  std::vector<Position> positions;
  std::vector<LineFeature> lines;
  std::vector<float> profiles;
  for (std::size_t i = 0; i < cand.size(); ++i) {
    // A position with fewer than two lines gives no pair but may still be found by its profile.
    if (per_pos[i].size() < 2 && B == 0) continue;
    // Whole centimetres, as the database file stores them (a loaded database answers alike).
    for (std::size_t k = 0; k < B; ++k)
      profiles.push_back(static_cast<float>(std::round(cand_profiles[i * B + k] * 100.0) / 100.0));
    const Eigen::Vector2d w = map.origin() * (cand[i]);
    Position p;
    p.x = static_cast<float>(w.x());
    p.y = static_cast<float>(w.y());
    p.first_line = static_cast<std::uint32_t>(lines.size());
    p.num_lines = static_cast<std::uint32_t>(per_pos[i].size());
    for (const Line& l : per_pos[i])
      lines.push_back(
          {static_cast<float>(l.normal_angle), static_cast<float>(l.distance), static_cast<float>(l.length)});
    positions.push_back(p);
  }
  return fromParts(options, localization::mapChecksum(map), std::move(positions), std::move(lines),
                   std::move(profiles));
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
        static_cast<std::uint64_t>(p.first_line) + p.num_lines > lines.size())
      throw badInput(fmt::format("database position {} is invalid (non-finite or lines out of range)", i),
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

// ------------------------------------------------------------------------------------------------
// Localizer

struct Localizer::State {
  LocalizerOptions options;
  Database db;
  registration::LikelihoodFieldOptions lf_options;
  registration::LikelihoodField field;
  std::optional<registration::CorrelativeGrid> grid;
  OccupancyImage map;  // for the free-space check
  SE2 T_map_world;
  registration::CorrelativeOptions corr_options;
};

namespace {

std::unique_ptr<Localizer::State> makeState(const OccupancyImage& map, Database db,
                                            const LocalizerOptions& options) {
  options.validate();
  auto s = std::make_unique<Localizer::State>();
  s->options = options;
  s->db = std::move(db);
  s->map = map;
  s->T_map_world = map.origin().inverse();
  s->lf_options.resolution_m = map.resolution();
  s->lf_options.levels = 2;
  s->lf_options.truncation_m = std::max(0.3, 2.0 * map.resolution());
  s->lf_options.occupied_min = s->db.options().occupied_min;
  s->lf_options.max_iterations = 15;
  s->lf_options.line_search = true;  // stops at the minimum of the map's field (BENCHMARK.md, "Global localization")
  s->field = registration::LikelihoodField::fromMap(map, s->lf_options);
  if (options.fallback_branch_and_bound) {
    s->corr_options.resolution_m = std::max(map.resolution(), 0.05);
    s->corr_options.occupied_min = s->db.options().occupied_min;
    s->corr_options.min_score = 0.0;
    s->corr_options.refine = true;
    s->corr_options.refinement = s->lf_options;
    s->grid = registration::CorrelativeGrid::fromMap(map, s->corr_options);
  }
  return s;
}

}  // namespace

Localizer::Localizer(const OccupancyImage& map, const LocalizerOptions& options, const DatabaseOptions& db_options)
    : s_(makeState(map, Database::build(map, db_options), options)) {}

Localizer::Localizer(const OccupancyImage& map, Database database, const LocalizerOptions& options) {
  const std::uint64_t sum = mapChecksum(map);
  if (database.mapChecksum() != sum)
    throw badInput(fmt::format("the localization database was built from another map (map checksum {:016x}, this map "
                               "{:016x}); rebuild it with 'lidar2d localize-index'",
                               database.mapChecksum(), sum),
                   ErrorLocation({}, 0, "map checksum"));
  s_ = makeState(map, std::move(database), options);
}

Localizer::~Localizer() = default;
const Database& Localizer::database() const { return s_->db; }
const LocalizerOptions& Localizer::options() const { return s_->options; }

double Localizer::score(const Points2& points_robot, const SE2& T_world_robot,
                        const Eigen::Vector2d& sensor_robot) const {
  const OccupancyImage& map = s_->map;
  const double res = map.resolution();
  const int occ = s_->db.options().occupied_min;
  const SE2 T_map_robot = s_->T_map_world * T_world_robot;
  const Eigen::Vector2d o = (T_map_robot * sensor_robot) / res;  // cell units
  std::size_t n = 0, hit = 0, through = 0;
  for (const auto& p : points_robot) {
    if (!p.allFinite()) continue;
    ++n;
    const auto smp = s_->field.sample(T_world_robot * p, 0);
    hit += smp.value < s_->options.hit_distance_m;
    // Free-space check: walk the beam cell by cell up to free_margin before the endpoint.
    const Eigen::Vector2d e = (T_map_robot * p) / res;
    const double len = (e - o).norm() - s_->options.free_margin_m / res;
    if (len <= 0) continue;
    const Eigen::Vector2d dir = (e - o).normalized();
    // Steps of one cell, or 5 cm on finer maps (walls there are several cells thick).
    const double step = std::max(1.0, 0.05 / res);
    for (double t = 0.5; t < len; t += step) {
      const Eigen::Vector2d q = o + t * dir;
      const int cx = static_cast<int>(std::floor(q.x())), cy = static_cast<int>(std::floor(q.y()));
      if (map.contains(cx, cy) && map.at(cx, cy) >= occ) {
        ++through;
        break;
      }
    }
  }
  if (n == 0) return 0.0;
  return std::clamp((static_cast<double>(hit) - static_cast<double>(through)) / static_cast<double>(n), 0.0, 1.0);
}

std::vector<PoseVote> voteLinePairs(const Database& database, const std::vector<Line>& lines,
                                    const LocalizerOptions& o, std::size_t max_bins, std::size_t* num_hits) {
  const DatabaseOptions& dbo = database.options();
  const Database::Impl& db = database.impl();
  struct Bin {
    double votes = 0;
    std::uint32_t stamp = 0xffffffffu;
    double sx = 0, sy = 0, sc = 0, ss = 0;
    int n = 0;
  };
  std::unordered_map<std::uint64_t, Bin> bins;
  bins.reserve(4096);
  const double k = dbo.key_angle_scale_m_per_rad;
  const double min_sin = std::sin(std::max(0.0, dbo.min_pair_angle_rad - o.key_radius_m / k));
  const float r2 = static_cast<float>(o.key_radius_m * o.key_radius_m);
  std::vector<std::pair<std::uint32_t, float>> hits;
  std::uint32_t stamp = 0;
  if (!db.pairs.empty()) {
    for (std::size_t i = 0; i < lines.size(); ++i)
      for (std::size_t j = 0; j < lines.size(); ++j) {
        if (i == j) continue;
        const Line& li = lines[i];
        const Line& lj = lines[j];
        const double rel = wrapTwoPi(lj.normal_angle - li.normal_angle);
        if (std::abs(std::sin(rel)) < min_sin) continue;
        ++stamp;
        for (const double shift : {0.0, -kTwoPi, kTwoPi}) {
          const double ka = k * (rel + shift);
          if (shift != 0.0 && (ka < -o.key_radius_m || ka > k * kTwoPi + o.key_radius_m)) continue;
          const float q[3] = {static_cast<float>(li.distance), static_cast<float>(lj.distance), static_cast<float>(ka)};
          hits.clear();
          db.tree->radiusSearch(q, r2, hits, nanoflann::SearchParams(32, 0.0f, false));
          if (num_hits) *num_hits += hits.size();
          for (const auto& h : hits) {
            const Pair& pr = db.pairs[h.first];
            const Database::LineFeature& ma = db.lines[pr.ref];
            const Database::LineFeature& mb = db.lines[pr.other];
            const Database::Position& pos = db.positions[pr.pos];
            // theta: map normal = scan normal + theta, averaged over the two lines.
            const double th_a = angleDiff(ma.normal_angle, li.normal_angle);
            const double th_b = angleDiff(mb.normal_angle, lj.normal_angle);
            const double theta = wrapAngle(th_a + 0.5 * angleDiff(th_b, th_a));
            // Translation: n_a . t = c_a - d_i and n_b . t = c_b - d_j (c = n . p + d, the map line).
            const Eigen::Vector2d na(std::cos(ma.normal_angle), std::sin(ma.normal_angle));
            const Eigen::Vector2d nb(std::cos(mb.normal_angle), std::sin(mb.normal_angle));
            const Eigen::Vector2d p(pos.x, pos.y);
            const double ra = na.dot(p) + ma.distance - li.distance;
            const double rb = nb.dot(p) + mb.distance - lj.distance;
            const double det = na.x() * nb.y() - na.y() * nb.x();
            if (std::abs(det) < 1e-3) continue;
            const double tx = (ra * nb.y() - na.y() * rb) / det;
            const double ty = (na.x() * rb - ra * nb.x()) / det;
            const auto bx = static_cast<std::int64_t>(std::floor(tx / o.vote_bin_m));
            const auto by = static_cast<std::int64_t>(std::floor(ty / o.vote_bin_m));
            const auto bt = static_cast<std::int64_t>(std::floor((theta + kPi) / o.vote_bin_rad));
            const std::uint64_t key = (static_cast<std::uint64_t>(bx + (1 << 20)) & 0x1fffff) |
                                      ((static_cast<std::uint64_t>(by + (1 << 20)) & 0x1fffff) << 21) |
                                      ((static_cast<std::uint64_t>(bt) & 0x3fffff) << 42);
            Bin& b = bins[key];
            b.sx += tx;
            b.sy += ty;
            b.sc += std::cos(theta);
            b.ss += std::sin(theta);
            ++b.n;
            if (b.stamp != stamp) {  // one vote per scan pair and bin
              b.stamp = stamp;
              b.votes += 1.0;
            }
          }
        }
      }
  }
  std::vector<std::pair<double, const Bin*>> ranked;
  ranked.reserve(bins.size());
  for (const auto& [key, b] : bins) ranked.push_back({b.votes, &b});
  const std::size_t n_cand = std::min(max_bins, ranked.size());
  std::partial_sort(ranked.begin(), ranked.begin() + static_cast<std::ptrdiff_t>(n_cand), ranked.end(),
                    [](const auto& a, const auto& b) { return a.first > b.first; });
  std::vector<PoseVote> out;
  out.reserve(n_cand);
  for (std::size_t c = 0; c < n_cand; ++c) {
    const Bin& b = *ranked[c].second;
    out.push_back({SE2(b.sx / b.n, b.sy / b.n, std::atan2(b.ss, b.sc)), b.votes, static_cast<std::size_t>(b.n)});
  }
  return out;
}

namespace {

// Candidates from the range profiles: the scan's profile (its nearest point in each sector of the
// robot frame, seen from the sensor) against every position's profile turned by each whole number
// of sectors. Per sector the mismatch |r_scan - r_map| / (0.3 m + 0.1 r_scan) counts, at most 1
// (clutter, open doors, a grid position 0.1 m off); sectors without a scan point (outside the
// field of view, no return) do not count. Returns the `k` positions with the lowest total, each
// at its best turn. Two passes: every position at a third of the angular resolution (the nearest
// obstacle of three sectors), then the best 32 k positions at full resolution. Brute force over the
// positions (vectorised; about 2 M operations for the 7000 positions of a building's database).
struct Observed {
  std::size_t bin;
  float range, inv_scale;
};

std::vector<Observed> observedSectors(const Points2& pts, const Eigen::Vector2d& sensor, std::size_t bins) {
  std::vector<float> q(bins, std::numeric_limits<float>::infinity());
  for (const auto& p : pts) {
    const Eigen::Vector2d v = p - sensor;
    const double r = v.norm();
    if (!(r > 0) || !std::isfinite(r)) continue;
    float& nearest = q[sectorOf(std::atan2(v.y(), v.x()), bins)];
    nearest = std::min(nearest, static_cast<float>(r));
  }
  std::vector<Observed> seen;
  for (std::size_t b = 0; b < bins; ++b)
    if (std::isfinite(q[b])) seen.push_back({b, q[b], 1.0f / (0.3f + 0.1f * q[b])});
  return seen;
}

// Lowest mismatch over all turns of one doubled profile, and that turn.
std::pair<float, std::size_t> bestTurn(const float* doubled, std::size_t bins, const std::vector<Observed>& seen,
                                       std::vector<float>& cost) {
  std::fill(cost.begin(), cost.begin() + static_cast<std::ptrdiff_t>(bins), 0.0f);
  for (const Observed& o : seen) {
    const float* d = doubled + o.bin;  // robot sector b at turn t is world sector b + t
    for (std::size_t t = 0; t < bins; ++t) cost[t] += std::min(std::abs(o.range - d[t]) * o.inv_scale, 1.0f);
  }
  const auto it = std::min_element(cost.begin(), cost.begin() + static_cast<std::ptrdiff_t>(bins));
  return {*it, static_cast<std::size_t>(it - cost.begin())};
}

std::vector<PoseVote> profileCandidates(const Database& database, const Points2& pts, const Eigen::Vector2d& sensor,
                                        std::size_t k) {
  const Database::Impl& db = database.impl();
  if (k == 0 || db.doubled.empty()) return {};
  const auto B = static_cast<std::size_t>(db.options.profile_bins);
  const std::size_t C = B / db.coarse_factor;
  const std::vector<Observed> fine = observedSectors(pts, sensor, B);
  const std::vector<Observed> coarse = observedSectors(pts, sensor, C);
  if (fine.size() < std::max<std::size_t>(4, B / 16)) return {};  // too little of the circle seen
  const std::size_t P = db.positions.size();
  std::vector<float> cost(B);
  std::vector<std::pair<float, std::size_t>> ranked(P);  // (cost, position)
  for (std::size_t p = 0; p < P; ++p) ranked[p] = {bestTurn(db.coarse_doubled.data() + 2 * p * C, C, coarse, cost).first, p};
  const std::size_t shortlist = std::min(P, 32 * k);
  std::partial_sort(ranked.begin(), ranked.begin() + static_cast<std::ptrdiff_t>(shortlist), ranked.end());
  std::vector<std::pair<float, std::size_t>> best(shortlist);  // (cost, position * B + turn)
  for (std::size_t c = 0; c < shortlist; ++c) {
    const std::size_t p = ranked[c].second;
    const auto [v, turn] = bestTurn(db.doubled.data() + 2 * p * B, B, fine, cost);
    best[c] = {v, p * B + turn};
  }
  const std::size_t n = std::min(k, shortlist);
  std::partial_sort(best.begin(), best.begin() + static_cast<std::ptrdiff_t>(n), best.end());
  std::vector<PoseVote> out;
  const double w = kTwoPi / static_cast<double>(B);
  for (std::size_t c = 0; c < n; ++c) {
    const std::size_t p = best[c].second / B, turn = best[c].second % B;
    const double theta = wrapAngle(static_cast<double>(turn) * w);
    const Eigen::Vector2d t = Eigen::Vector2d(db.positions[p].x, db.positions[p].y) - SE2(0, 0, theta) * sensor;
    out.push_back({SE2(t.x(), t.y(), theta), 0.0, 0});
  }
  return out;
}

}  // namespace

LocalizationResult Localizer::localize(const LaserScan& scan, const SE2& T_robot_laser) const {
  return localize(scan.toPoints(T_robot_laser), T_robot_laser.translation());
}

LocalizationResult Localizer::localize(const Points2& points_robot, const Eigen::Vector2d& sensor_robot) const {
  using Clock = std::chrono::steady_clock;
  const auto ms = [](Clock::time_point a, Clock::time_point b) {
    return std::chrono::duration<double, std::milli>(b - a).count();
  };
  const auto t0 = Clock::now();
  const LocalizerOptions& o = s_->options;
  LocalizationResult res;

  Points2 pts;
  pts.reserve(points_robot.size());
  for (const auto& p : points_robot)
    if (p.allFinite() && p.norm() <= o.max_range_m) pts.push_back(p);
  res.num_points = pts.size();
  auto finish = [&](const char* reason) {
    res.reason = reason;
    res.total_ms = ms(t0, Clock::now());
    return res;
  };
  if (pts.size() < 10) return finish("no points");

  // 1. Describe: lines of the scan (robot frame), from every point; and its range profile's
  // candidates (the second signature, for scans whose lines give no usable pair).
  std::vector<Line> lines = extractLines(pts, o.lines);
  const auto t_lines = Clock::now();
  std::vector<PoseVote> from_profiles = profileCandidates(s_->db, pts, sensor_robot, o.profile_candidates);
  const auto t_profiles = Clock::now();
  // Verification needs no more than max_verify_points (evenly subsampled) to score and refine.
  if (pts.size() > o.max_verify_points) {
    Points2 thin;
    const double stride = static_cast<double>(pts.size()) / static_cast<double>(o.max_verify_points);
    for (std::size_t k = 0; k < o.max_verify_points; ++k) thin.push_back(pts[static_cast<std::size_t>(k * stride)]);
    pts = std::move(thin);
  }
  if (lines.size() > o.max_query_lines) lines.resize(o.max_query_lines);
  res.num_lines = lines.size();
  const auto t1 = Clock::now();
  res.describe_ms = ms(t0, t1);

  // 2. Look up every ordered pair; each hit gives a pose that votes for a bin.
  std::vector<PoseVote> ranked = voteLinePairs(s_->db, lines, o, o.max_candidates, &res.num_hits);
  res.num_profile_candidates = from_profiles.size();
  ranked.insert(ranked.end(), from_profiles.begin(), from_profiles.end());
  const std::size_t n_cand = ranked.size();
  const auto t2 = Clock::now();
  res.lookup_ms = ms(t1, t2) + ms(t_lines, t_profiles);
  res.describe_ms -= ms(t_lines, t_profiles);

  // 3. Verify in three stages of decreasing count and increasing cost: (A) every candidate bin's
  // mean pose against the likelihood field on a subsample of the points, (B) the best distinct ones
  // with the free-space term, (C) the best of those refined and scored on all (verification) points.
  Points2 sub;
  const std::size_t stride_pts = std::max<std::size_t>(1, pts.size() / o.prescore_points);
  for (std::size_t i = 0; i < pts.size(); i += stride_pts) sub.push_back(pts[i]);
  struct Pre {
    SE2 guess;
    double pre = 0;
    double votes = 0;
  };
  std::vector<Pre> pre;
  pre.reserve(n_cand);
  // Stage A: a smooth kernel of the field value (so that near-ties are ordered by how close the
  // points are, not just whether they are within a tolerance).
  const double pre_sigma = 2.0 * o.hit_distance_m;
  for (std::size_t c = 0; c < n_cand; ++c) {
    const SE2& guess = ranked[c].T_world_robot;
    double acc = 0;
    for (const auto& p : sub) {
      const double v = s_->field.sample(guess * p, 0).value / pre_sigma;
      acc += v < 1.0 ? 1.0 - v * v : 0.0;
    }
    pre.push_back({guess, acc / static_cast<double>(sub.size()), ranked[c].votes});
  }
  std::sort(pre.begin(), pre.end(), [](const Pre& a, const Pre& b) { return a.pre > b.pre; });
  // Stage B: the best distinct ones (neighbouring bins of one pose suppressed, so that distinct
  // hypotheses such as symmetric rooms all get through) scored with the free-space term.
  std::vector<Pre> stage_b;
  for (std::size_t c = 0; c < pre.size() && stage_b.size() < o.max_free_space_checked; ++c) {
    const SE2& guess = pre[c].guess;
    bool dup = false;
    for (const Pre& q : stage_b)
      dup = dup || ((q.guess.translation() - guess.translation()).norm() < 2.0 * o.vote_bin_m &&
                    std::abs(angleDiff(q.guess.theta(), guess.theta())) < 2.0 * o.vote_bin_rad);
    if (dup) continue;
    stage_b.push_back({guess, score(sub, guess, sensor_robot) + 1e-3 * pre[c].pre, pre[c].votes});
  }
  std::sort(stage_b.begin(), stage_b.end(), [](const Pre& a, const Pre& b) { return a.pre > b.pre; });
  // Stage C: refine the best against the likelihood field and score them on every point.
  std::vector<Candidate> cands;
  for (std::size_t c = 0; c < stage_b.size() && c < o.max_refined; ++c) {
    const SE2& guess = stage_b[c].guess;
    const registration::Result r = registration::matchLikelihoodField(s_->field, pts, guess, s_->lf_options);
    SE2 T = r.T_target_source;
    if (!T.isFinite() || (T.translation() - guess.translation()).norm() > 0.5) T = guess;
    double sc = score(pts, T, sensor_robot);
    const double sc_guess = score(pts, guess, sensor_robot);
    if (sc_guess > sc) {
      T = guess;
      sc = sc_guess;
    }
    cands.push_back({T, sc, stage_b[c].votes});
  }
  res.num_candidates = cands.size();

  auto bestOf = [&] {
    std::sort(cands.begin(), cands.end(), [](const Candidate& a, const Candidate& b) { return a.score > b.score; });
  };
  bestOf();
  if ((cands.empty() || cands.front().score < o.min_score) && o.fallback_branch_and_bound && s_->grid) {
    const registration::CorrelativeResult r =
        registration::matchCorrelativeGlobal(*s_->grid, pts, s_->corr_options, &s_->field);
    if (r.T_target_source.isFinite()) {
      cands.push_back({r.T_target_source, score(pts, r.T_target_source, sensor_robot), 0.0});
      res.used_fallback = true;
      bestOf();
    }
  }
  const auto t3 = Clock::now();
  res.verify_ms = ms(t2, t3);

  if (cands.empty()) return finish(lines.size() < 2 ? "no lines" : "no candidate");
  const Candidate& best = cands.front();
  res.T_world_robot = best.T_world_robot;
  res.score = best.score;
  auto distinct = [&](const SE2& a, const SE2& b) {
    return (a.translation() - b.translation()).norm() > o.distinct_distance_m ||
           std::abs(angleDiff(a.theta(), b.theta())) > o.distinct_angle_rad;
  };
  for (std::size_t c = 1; c < cands.size(); ++c) {
    if (cands[c].score < o.min_score) break;
    if (!distinct(cands[c].T_world_robot, best.T_world_robot)) continue;
    bool seen = false;
    for (const auto& a : res.alternatives) seen = seen || !distinct(cands[c].T_world_robot, a.T_world_robot);
    if (!seen) res.alternatives.push_back(cands[c]);
  }
  if (best.score < o.min_score) return finish("low score");
  if (!res.alternatives.empty() && res.alternatives.front().score >= o.ambiguity_ratio * best.score)
    return finish("ambiguous");
  res.declined = false;
  res.total_ms = ms(t0, Clock::now());
  return res;
}

}  // namespace lidar2d::localization
