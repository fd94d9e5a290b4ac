#pragma once
/// @file
/// Global localization from one scan in a known occupancy map.
///
/// **Database** (built once per map): virtual 360-degree scans are ray-cast from a grid of free
/// positions; the lines of each virtual scan are extracted (lines.hpp) and kept in the
/// world-oriented frame of the position, as (phi_w, d). Every pair of non-parallel lines (i, j) of a
/// position is indexed by the rotation-invariant key (d_i, d_j, k * wrap(phi_j - phi_i)) in a k-d
/// tree: the two perpendicular distances from the sensor and the angle of line j relative to the
/// reference line i. Every line serves as a reference in turn, so no single reference line has to be
/// found again in the query.
///
/// **Query** (one scan, no guess): lines of the scan (robot frame), every ordered pair of them looked
/// up in the tree within a radius (sub-linear; no loop over the database). A hit pairs two scan lines
/// with two map lines, which fixes the pose in closed form: theta from the normal directions, the
/// translation from the two line equations. Hits vote for (x, y, theta) bins (one vote per scan pair
/// and bin), so missing lines, extra lines (clutter) and a partial field of view only remove or add
/// a few votes. The best-voted bins are verified: the scan is refined against the map's likelihood
/// field (registration::matchLikelihoodField) and scored as the fraction of its points that land on
/// an obstacle. The result is the best pose, its score and the distinct alternatives; the localizer
/// declines when nothing scores well enough or a distinct alternative scores nearly as well (a
/// symmetric building). A second signature finds the scans whose lines give no pair (corridors,
/// clutter): each position's range profile (nearest obstacle per sector of the circle), compared
/// with the scan's at every whole-sector turn; its best positions join the line candidates.
/// Optionally, when nothing scores, it falls back to branch-and-bound over the whole map
/// (registration::matchCorrelativeGlobal).
///
/// Frames: the map's world frame; results are `T_world_robot` for points given in the robot frame.

#include <Eigen/Core>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <numbers>
#include <string>
#include <vector>

#include "lidar2d/core/laser_scan.hpp"
#include "lidar2d/core/occupancy_image.hpp"
#include "lidar2d/core/se2.hpp"
#include "lidar2d/localization/lines.hpp"

namespace lidar2d::localization {

/// Options of the database build (stored in the database file). `validate()` throws
/// `lidar2d::Error` (kInvalidArgument) naming the first field out of its domain.
struct DatabaseOptions {
  double step_m = 0.2;                      ///< spacing of the grid of positions [m], > 0
  int beams = 720;                          ///< beams of each virtual scan, 8..100000
  double fov_rad = 2.0 * std::numbers::pi;  ///< field of view of the virtual scans, centred on +x [rad], in (0, 2 pi]
  double max_range_m = 30.0;                ///< range of the virtual scans [m], > 0
  double clearance_m = 0.25;                ///< positions keep this distance from occupied and unknown cells [m], 0..100 (and at most 500 cells of the map)
  int occupied_min = 65;                    ///< map cells >= this are obstacles, 1..100
  int free_max = 25;                        ///< map cells 0..free_max are free, 0..99, < occupied_min
  std::size_t max_lines = 24;               ///< longest lines kept per position, 2..64
  /// Weight of the relative angle in the pair key (d_i, d_j, k * angle) [m/rad], > 0
  double key_angle_scale_m_per_rad = 2.0;
  double min_pair_angle_rad =
      20.0 * std::numbers::pi / 180.0;  ///< pairs closer to parallel are not indexed [rad], in [0, pi/2]
  /// Second signature, for scans with too few lines: each position's range profile, the nearest
  /// obstacle of its virtual scan in each of this many equal sectors of the circle (world-oriented);
  /// 0 = none, else 8..720.
  int profile_bins = 72;
  /// Line extraction of the virtual scans: more permissive than the query's (shorter lines, fewer
  /// points), so that the database holds a superset of what a real scan extracts.
  LineExtractionOptions lines = permissiveLines();
  void validate() const;
  static LineExtractionOptions permissiveLines() {
    LineExtractionOptions l;
    l.min_points = 3;
    l.min_length_m = 0.25;
    return l;
  }
};

/// Progress of a long build: called with (done, total) positions; must be cheap.
using ProgressCallback = void (*)(std::size_t done, std::size_t total, void* user);

/// The descriptor database of one map: positions, their lines, and the k-d tree over line pairs.
/// Movable, not copyable.
class Database {
 public:
  /// One grid position and its lines (a range of `lines()`).
  struct Position {
    float x = 0, y = 0;            ///< world frame [m]
    std::uint32_t first_line = 0;  ///< index of its first line in lines()
    std::uint32_t num_lines = 0;
  };
  /// One line seen from a position, in the world-oriented frame centred on the position.
  struct LineFeature {
    float normal_angle = 0;  ///< phi_w [rad]
    float distance = 0;      ///< d [m]
    float length = 0;        ///< [m]
  };

  Database();
  ~Database();
  Database(Database&&) noexcept;
  Database& operator=(Database&&) noexcept;
  Database(const Database&) = delete;
  Database& operator=(const Database&) = delete;

  /// Builds the database of `map` (multi-threaded over positions, `threads` = 0: hardware
  /// concurrency). Throws `lidar2d::Error`: kInvalidArgument for bad options, kBadInput (field
  /// "free space") when the map has no free cell with the clearance, kBadInput (field "step") when
  /// the grid of positions over the map would exceed 10^7 (the message names a step that fits),
  /// kBadInput (field "resolution") for a map coarser than 0.2 m per cell.
  /// `progress(done, total, user)` is called from the calling thread as positions are indexed.
  static Database build(const OccupancyImage& map, const DatabaseOptions& options = {}, unsigned threads = 0,
                        ProgressCallback progress = nullptr, void* progress_user = nullptr);
  /// Assembles a database from stored parts (what a reader loaded) and builds its index.
  /// `profiles`: empty (no range profiles), or options.profile_bins ranges [m] per position,
  /// position by position (see profiles()). Throws `lidar2d::Error` (kBadInput) when the parts are
  /// inconsistent (line ranges out of bounds, non-finite or negative values, a profile size that
  /// does not match).
  static Database fromParts(const DatabaseOptions& options, std::uint64_t map_checksum, std::vector<Position> positions,
                            std::vector<LineFeature> lines, std::vector<float> profiles = {});

  const DatabaseOptions& options() const;
  std::uint64_t mapChecksum() const;  ///< mapChecksum() of the map it was built from
  const std::vector<Position>& positions() const;
  const std::vector<LineFeature>& lines() const;
  /// Range profiles: options().profile_bins values per position (empty when there are none); bin k
  /// of a position holds the range [m] of the nearest obstacle its virtual scan saw at world angles
  /// [-pi + k w, -pi + (k + 1) w), w = 2 pi / bins (max_range_m when it saw none).
  const std::vector<float>& profiles() const;
  std::size_t numPairs() const;     ///< indexed line pairs
  /// Share of the map's free cells whose square of the grid of positions (step x step) holds an
  /// indexed position, in [0, 1]: free space near walls and unknown cells, and passages narrower
  /// than twice the clearance, are not indexed (scans there may be declined). NaN for a database
  /// assembled with fromParts (a file does not store it).
  double coverage() const;
  std::size_t memoryBytes() const;  ///< approximate heap use, index included
  bool empty() const;

  /// Internal: the index (defined in the implementation).
  struct Impl;
  const Impl& impl() const { return *impl_; }

 private:
  std::unique_ptr<Impl> impl_;
};

/// FNV-1a 64 over the map's size, resolution, origin and cells: identifies the map a database
/// belongs to.
std::uint64_t mapChecksum(const OccupancyImage& map);

/// Options of the query. `validate()` throws `lidar2d::Error` (kInvalidArgument).
struct LocalizerOptions {
  LineExtractionOptions lines;       ///< line extraction of the query scan (defaults match the database's)
  std::size_t max_query_lines = 14;  ///< longest scan lines used, >= 2
  double key_radius_m = 0.3;  ///< search radius in key space (distances in m, angle scaled by key_angle_scale) [m], > 0
  double vote_bin_m = 0.3;    ///< translation bin of the pose vote [m], > 0
  double vote_bin_rad = 6.0 * std::numbers::pi / 180.0;  ///< rotation bin [rad], > 0
  std::size_t max_candidates =
      5000;  ///< best-voted bins pre-scored (field kernel on a subsample of points, no refinement), >= 1
  std::size_t max_free_space_checked =
      32;  ///< best distinct pre-scored candidates scored with the free-space term (subsample), >= 1
  std::size_t max_refined = 16;  ///< best of those refined and scored on every point, >= 1
  std::size_t max_verify_points =
      400;                           ///< refinement and score use at most this many points (evenly subsampled), >= 10
  std::size_t prescore_points = 60;  ///< points (evenly subsampled) of the pre-score, >= 10
  double hit_distance_m = 0.1;       ///< a scan point within this of an obstacle counts for the score [m], > 0
  double free_margin_m = 0.3;        ///< a beam crossing an obstacle cell farther than this before its endpoint counts
                                     ///< against the score [m], >= 0
  double max_range_m = 30.0;         ///< scan points beyond this are ignored [m], > 0
  double min_score = 0.5;            ///< a best score below this declines, in [0, 1]
  /// A distinct alternative scoring at least this fraction of the best declines the answer
  /// (ambiguous, e.g. a symmetric building), in [0, 1].
  double ambiguity_ratio = 0.95;
  /// ... and when the distinct candidates (LocalizationResult::candidates, whatever their score)
  /// together are at least as likely as the best: each one's odds against the best are
  /// exp(-ambiguity_nats_per_point x points scored x (best fit - its fit)), and they sum to 1 or
  /// more (many look-alike places, each a little worse than the best, as along a repetitive
  /// corridor or for a scan from a place the map lacks; a fit gap weighs more on a scan with more
  /// points). >= 0; 0 = off.
  double ambiguity_nats_per_point = 0.12;
  /// The same weight for a best pose scoring under `confident_score`, which leaves more of its scan
  /// unexplained: it must stand further above its rivals (a smaller weight per point makes each
  /// rival likelier). A scan from a place the map lacks is answered, if at all, by such a pose
  /// (BENCHMARK.md, global localization: other buildings and half maps). >= 0; used only while
  /// `ambiguity_nats_per_point` > 0.
  double unconfident_nats_per_point = 0.08;
  double distinct_distance_m = 1.0;  ///< alternatives farther than this from the best are distinct [m]
  double distinct_angle_rad = 20.0 * std::numbers::pi / 180.0;  ///< ... or turned by more than this [rad]
  /// Candidates from the range-profile signature (database positions whose profile, turned in
  /// steps of one sector, best matches the scan's), verified with the line candidates; they find
  /// the scans whose lines give no usable pair (corridors, clutter). 0 = off.
  std::size_t profile_candidates = 64;
  /// Cascade, stage D: when the descriptors give no confident answer (declined, a best score
  /// below `confident_score`, or a distinct runner-up within `confident_ratio`), the best `max_regions` candidate regions (distinct positions of the
  /// verified, pre-scored, range-profile and line-vote candidates, ranked in turn) are each searched
  /// by branch and bound over +-`region_half_window_m` and every heading; their best poses are
  /// refined and scored like the descriptor candidates. 0 = off.
  std::size_t max_regions = 24;
  double region_half_window_m = 0.6;  ///< half-width of each region's square translation window [m], > 0
  double confident_score = 0.8;  ///< answers scoring at least this skip stage D ..., in [0, 1]
  double confident_ratio = 0.9;  ///< ... when no distinct candidate's fit reaches this fraction of the best's, in [0, 1]
  /// Cell size of the branch-and-bound grids (the map's when coarser) [m], > 0; its max-grids give
  /// the coarser resolutions of the search (Hess 2016).
  double search_resolution_m = 0.1;
  /// Cascade, stage E, the last resort: when still no candidate scores at least min_score, the
  /// whole map is searched by branch and bound over every heading until the query has taken
  /// `budget_ms` in all (the best pose found by then is verified). 0 = no whole-map search.
  double budget_ms = 150.0;
  /// Stage E without the budget: the exhaustive whole-map search runs to its end (seconds per
  /// scan on a building-sized map).
  bool fallback_branch_and_bound = false;
  /// Threads of one query, >= 1: with 2 or more, the range profiles' candidates are found beside
  /// the line votes, and the candidates' scoring, their refinements and the region searches are
  /// shared between the threads (the answer is the same); 1: all on the calling thread.
  std::size_t threads = 2;
  void validate() const;
};

/// One bin of the descriptor vote: the mean pose of the hits that fell into it.
struct PoseVote {
  SE2 T_world_robot;      ///< mean pose of the bin's hits (database frame)
  double votes = 0.0;     ///< scan line pairs voting for the bin (one vote per pair and bin)
  std::size_t hits = 0;   ///< database pairs that fell into the bin
};

/// The descriptor lookup of the localizer without its map-based verification: every ordered pair
/// of `lines` (robot frame) is looked up in `database` within `options.key_radius_m`; each hit fixes
/// a pose that votes for an (x, y, theta) bin of `options.vote_bin_m` / `options.vote_bin_rad`.
/// Returns at most `max_bins` bins, most voted first; adds the database pairs matched to
/// `*num_hits` when given. Also usable on a database assembled with `Database::fromParts` from
/// real scans (SLAM describes its nodes this way). An empty database gives an empty list.
std::vector<PoseVote> voteLinePairs(const Database& database, const std::vector<Line>& lines,
                                    const LocalizerOptions& options, std::size_t max_bins,
                                    std::size_t* num_hits = nullptr);

/// One verified pose hypothesis.
struct Candidate {
  SE2 T_world_robot;   ///< refined pose
  double score = 0.0;  ///< Localizer::score of the pose, in [0, 1]
  double votes = 0.0;  ///< descriptor votes of its bin (0 for the branch-and-bound stages)
  /// How closely the points lie on the walls: mean of 1 - (d / hit_distance)^2 over the points
  /// (0 beyond hit_distance) minus the share of beams through walls and the share of points in
  /// known free space (Localizer::score), in [0, 1]. Candidates are ranked by it and the ambiguity
  /// test compares it (it separates poses with equal `score`).
  double fit = 0.0;
};

/// The answer for one scan.
struct LocalizationResult {
  bool declined = true;  ///< true: "unknown" (see reason); T_world_robot and score are then the best guess if any
  /// Why it declined: "no points" (fewer than 10 valid beams), "no lines" / "no candidate" (nothing
  /// to verify), "low score",
  /// "ambiguous" (a distinct pose scores nearly as well: `candidates` lists them).
  std::string reason;
  SE2 T_world_robot;     ///< best pose
  double score = 0.0;    ///< its score, in [0, 1]
  std::vector<Candidate> alternatives;  ///< distinct poses other than the best, best first (score >= min_score)
  /// Every verified candidate, best first, each distinct (LocalizerOptions::distinct_*) from those
  /// before it, whatever its score: the hypotheses a caller may track itself (the best is first).
  std::vector<Candidate> candidates;
  std::size_t num_points = 0;           ///< valid scan points used
  std::size_t num_lines = 0;            ///< scan lines used
  std::size_t num_hits = 0;             ///< database pairs matched
  std::size_t num_candidates = 0;       ///< candidates verified
  std::size_t num_profile_candidates = 0;  ///< of the pre-scored candidates, those from the range profiles
  std::size_t num_regions = 0;          ///< candidate regions searched by branch and bound (stage D)
  bool used_fallback = false;           ///< the whole-map search ran (stage E)
  bool fallback_complete = false;       ///< ... and finished within the budget
  double describe_ms = 0, lookup_ms = 0, verify_ms = 0, total_ms = 0;  ///< timings [ms]
};

/// Localizes single scans in one map. Holds the map, its likelihood field, its clearance grid (one
/// byte per cell: the free-space check's beams skip open floor) and the database; const methods
/// are thread-safe. Non-copyable.
class Localizer {
 public:
  /// Builds the database in memory (DatabaseOptions) and the likelihood field of `map`.
  explicit Localizer(const OccupancyImage& map, const LocalizerOptions& options = {},
                     const DatabaseOptions& db_options = {});
  /// Uses a prebuilt database. Throws `lidar2d::Error` (kBadInput, field "map checksum") when it was
  /// built from another map.
  Localizer(const OccupancyImage& map, Database database, const LocalizerOptions& options = {});
  ~Localizer();
  Localizer(const Localizer&) = delete;
  Localizer& operator=(const Localizer&) = delete;

  /// Localizes points given in the robot frame, in scan order (LaserScan::toPoints(T_robot_laser));
  /// `sensor_robot` is the laser's position in the robot frame (the origin of the beams, used by the
  /// free-space check of the score). Never throws for bad data: no valid points, no lines or nothing
  /// scoring give declined = true.
  LocalizationResult localize(const Points2& points_robot,
                              const Eigen::Vector2d& sensor_robot = Eigen::Vector2d::Zero()) const;
  /// Same for a scan: its valid beams through `T_robot_laser`.
  LocalizationResult localize(const LaserScan& scan, const SE2& T_robot_laser = {}) const;

  /// Score of a pose without refinement: (points within hit_distance of an obstacle - beams that
  /// cross an obstacle cell more than free_margin before their endpoint - 0.5 x the other points
  /// lying in known free space (map cells 0..free_max) at least free_margin from any obstacle) /
  /// points, clamped to [0, 1]. The second term rejects poses that explain the walls but see
  /// through other walls (a mirror image of the room, a partial view that fits elsewhere); the
  /// third, a scan from a place the map lacks put in a mapped room like it. Points in unknown
  /// space cost nothing (docs/localization.md).
  double score(const Points2& points_robot, const SE2& T_world_robot,
               const Eigen::Vector2d& sensor_robot = Eigen::Vector2d::Zero()) const;
  /// The same score, a point for which `also_explained` (world frame) holds counting as on an
  /// obstacle: what the map lacks but other evidence shows (the tracker's recent scans beyond the
  /// map's edge). Such a point in the map's known free space still counts half against the pose,
  /// and a beam through the map's obstacles fully.
  double score(const Points2& points_robot, const SE2& T_world_robot, const Eigen::Vector2d& sensor_robot,
               const std::function<bool(const Eigen::Vector2d&)>& also_explained) const;

  const Database& database() const;
  const LocalizerOptions& options() const;

  struct State;  ///< internal (defined in the implementation)

 private:
  std::unique_ptr<State> s_;
};

}  // namespace lidar2d::localization
