#pragma once
/// @file
/// Occupancy maps built by inserting laser scans at known poses. Three models share one interface:
/// log-odds, hit/miss counting, and a 2D truncated signed distance field (TSDF). All store their
/// cells in a sparse `TiledGrid` and trace beams exactly (`traceRay`).

#include <array>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>
#include <utility>
#include <vector>

#include "lidar2d/core/laser_scan.hpp"
#include "lidar2d/core/se2.hpp"
#include "lidar2d/mapping/ray_trace.hpp"
#include "lidar2d/mapping/tiled_grid.hpp"

namespace lidar2d::mapping {

enum class MapModel { kLogOdds, kCount, kTsdf };

/// Printable name ("logodds", "count", "tsdf").
const char* toString(MapModel m);

/// Three-valued cell classification used for export (values as in nav_msgs/OccupancyGrid).
enum class CellState : std::int8_t { kUnknown = -1, kFree = 0, kOccupied = 100 };

/// How beams are inserted, common to all models.
struct InsertOptions {
  double max_range_m = 30.0;  ///< returns farther than this are treated as "no return" [m]
  /// Beams without a return (>= range_max, +inf, or beyond max_range_m) clear free space up to
  /// this distance and mark nothing occupied; 0 ignores them [m].
  double no_return_clear_m = 5.0;
  /// Surface guard (log-odds and count): a scan does not clear the cells that a surface it saw
  /// passes through. Its surfaces are the segments between neighbouring returns that belong to one
  /// surface (one is the other's nearer neighbour, see surface_neighbor_max_m), at most this long
  /// [m]; and past the edge of an occluding surface (a return nearer than its neighbour by more than
  /// 2 sqrt(2) cells, or beside a beam with no return), the surface's continuation to where the
  /// next beam passes it, at most 2 sqrt(2) cells. A cell those segments pass through and no beam
  /// of the scan ends in is left as it was by that scan (neither hit nor cleared). Without the
  /// guard, beams that graze a wall, or pass the edge of an obstacle, clear the cells the surface
  /// passes through (docs/mapping.md). 0 disables the guard.
  double surface_guard_max_m = 1.0;
  /// The surface guard takes a return and its nearer neighbouring return as one surface when they
  /// lie at most this far apart [m] (the farther neighbour is more likely across a depth jump).
  double surface_neighbor_max_m = 1.0;
  std::size_t cell_budget = 1'000'000'000;  ///< most cells the map may span [cells]
  /// Threads inserting one scan: 1 = the calling thread only; 2 = the calling thread and one
  /// worker thread owned by the map, splitting the scan's cells by a line (each cell is updated by
  /// one thread, in the single-threaded order, so the map is identical). Scans too small or too
  /// lopsided to split run on the calling thread, and so do the next scans after a split that
  /// was slower than one thread (busy cores). Larger values currently use 2 threads.
  /// The default is 1 because on two cores the split does not pay: it costs extra work (walking to
  /// the split line, the clipped traversal) and the second core is busy reading the log.
  unsigned threads = 1;
  /// With threads > 1: after a split scan that took longer than one thread would have (cores busy
  /// with other work, so the worker got its time slice late), insert the next scans on one thread
  /// (8 at first, doubling up to 1024 while it recurs). False splits every scan worth splitting.
  bool adaptive_threads = true;
};

/// Log-odds model. Defaults follow Cartographer's 2D probability grid.
struct LogOddsOptions {
  double hit_probability = 0.55;   ///< probability added by a hit (as log-odds)
  double miss_probability = 0.49;  ///< probability added by a pass (as log-odds)
  double min_probability = 0.12;   ///< clamp [probability]
  double max_probability = 0.97;   ///< clamp [probability]
  /// The classic integer scheme instead of the probabilities above: cells start at 50 (unknown),
  /// +2 per hit, -1 per pass, clamped to 1..100; probability = value / 100.
  bool classic_integer = false;
  /// Exported occupied when probability > this. The default classifies by the more likely state
  /// (maximum a posteriori).
  double occupied_threshold = 0.5;
  double free_threshold = 0.5;  ///< exported free when probability < this
};

/// Hit/miss counting: probability = hits / (hits + misses).
struct CountOptions {
  double occupied_threshold = 0.25;  ///< exported occupied when hits/(hits+misses) >= this
};

/// 2D TSDF: signed distance along each beam (positive in front of the surface), truncated.
struct TsdfOptions {
  double truncation_m = 0.3;  ///< |signed distance| is clamped to this [m]
  /// How far behind each return cells are updated (with negative distances) [m]; at most the
  /// truncation. Shorter than the truncation because walls are thinner: a long negative band
  /// reaches the room behind the wall and cancels its zero crossing.
  double behind_surface_m = 0.15;
  double max_weight = 100.0;  ///< cap of the running-average weight, a whole number (older data keeps 1/cap influence)
};

struct MapOptions {
  double resolution_m = 0.05;  ///< cell size [m]
  InsertOptions insert;
  LogOddsOptions logodds;
  CountOptions count;
  TsdfOptions tsdf;
};

/// A sub-cell surface point of the TSDF (a zero crossing between two adjacent cells).
struct SurfacePoint {
  Eigen::Vector2d p_world;  ///< [m]
  double weight = 0.0;      ///< smaller of the two cells' weights
};

/// Base class of the three models. Non-copyable; options are fixed at construction. With
/// `InsertOptions::threads` > 1 the map owns a worker thread (started by the first scan worth
/// splitting, joined by the destructor); a map is still used by one thread at a time.
class OccupancyMap {
 public:
  virtual ~OccupancyMap();
  OccupancyMap(const OccupancyMap&) = delete;
  OccupancyMap& operator=(const OccupancyMap&) = delete;

  virtual MapModel model() const = 0;
  const MapOptions& options() const { return options_; }
  const GridGeometry& geometry() const { return geometry_; }

  /// Inserts one scan taken by a laser at `T_world_laser`. Invalid beams: NaN and returns at or
  /// below range_min are skipped; no-return beams clear free space (see InsertOptions). Throws
  /// `lidar2d::Error` when the scan would push the map beyond its cell budget or the pose is not
  /// finite; the map is unchanged in that case.
  void insert(const LaserScan& scan, const SE2& T_world_laser);

  class PreparedScan;
  /// The first half of `insert`: turns the scan into beams (and, for the surface guard, the lines
  /// they spare) in `out`, reading no map state, so that it may run on another thread while the
  /// map inserts an earlier scan (`MapBuilder` does). Throws as `insert` does for a bad pose.
  /// `out` keeps its buffers from scan to scan.
  void prepare(const LaserScan& scan, const SE2& T_world_laser, PreparedScan& out) const;
  /// The second half: inserts a scan `prepare` made for this map, exactly as `insert` would have;
  /// `prepared` is consumed (prepare into it again to reuse it). Throws `lidar2d::Error` for a scan
  /// not prepared by this map, or as `insert` does (the map is unchanged then).
  void insert(PreparedScan& prepared);

  /// Occupancy probability in [0, 1], or std::nullopt for a never-observed cell. (TSDF: 1 for
  /// surface cells, 0 for observed free cells, 0.5 otherwise.)
  virtual std::optional<double> probability(CellIndex c) const = 0;
  /// Exported classification of a cell.
  virtual CellState state(CellIndex c) const = 0;
  /// Box of all cells any inserted beam touched; empty before any insertion.
  const CellBox& bounds() const { return bounds_; }
  /// Total cell updates so far, for benchmarks. Log-odds and count update a cell at most once per
  /// scan (hits first); the TSDF once per beam.
  std::uint64_t cellUpdates() const { return cell_updates_; }
  /// Total cells visited by the beams' walks so far (each beam's walked cells, counted once per
  /// beam): the work measure of the ray tracing, for benchmarks. Log-odds and count do not walk the
  /// cells near the laser that neighbouring beams certainly pass (see `prepare`).
  std::uint64_t cellVisits() const { return cell_visits_; }
  /// Scans inserted by two threads so far (see `InsertOptions::threads`), for benchmarks and tests.
  std::uint64_t parallelScans() const { return parallel_scans_; }
  /// Memory held by the cells [bytes].
  virtual std::size_t memoryBytes() const = 0;

 protected:
  explicit OccupancyMap(const MapOptions& options);
  /// A beam of the scan being inserted (continuous cell coordinates).
  struct Beam {
    Eigen::Vector2d end;  ///< end of the traced segment [cells]
    /// The traversal to `end`, set up by `prepare`: from the origin, or for log-odds and count from
    /// where the beams around it stop covering its cells (see `prepare`).
    RayWalk walk;
    double range_cells;   ///< length of the beam up to the return [cells]
    bool hit;             ///< true: a return at `end`; false: no return (clear only)
  };
  /// The cells of one thread's share of a scan: those with coordinate `axis` (0 = x, 1 = y) in
  /// [lo, hi); axis -1 means all cells. Slabs are bounded by tile borders, so a tile is wholly
  /// inside one slab.
  struct Slab {
    int axis = -1;
    std::int32_t lo = 0, hi = 0;
    bool contains(CellIndex c) const {
      if (axis < 0) return true;
      const std::int32_t v = axis == 0 ? c.x : c.y;
      return v >= lo && v < hi;
    }
  };
  /// Called once per scan before any `insertBeams`: reserves `box` (every cell the scan touches)
  /// and starts the scan's per-cell bookkeeping. May throw (cell budget); the map is unchanged then.
  virtual void beginScan(const CellBox& box) = 0;
  /// Model-specific insertion of prepared beams (all in continuous cell coordinates), restricted to
  /// the cells in `slab`; returns the cell updates made. Two calls with disjoint slabs may run
  /// concurrently; `part` (0 or 1) tells them apart for per-thread scratch space.
  virtual std::uint64_t insertBeams(const Eigen::Vector2d& origin, const std::vector<Beam>& beams, const Slab& slab,
                                    int part) = 0;

  const MapOptions options_;
  const GridGeometry geometry_;
  /// The surface guard's segments of the current scan [cells] (see InsertOptions::
  /// surface_guard_max_m): log-odds and count leave the cells they pass through, end cells
  /// included, as they were unless a beam of the scan ends in them.
  struct Surface {
    Eigen::Vector2d from, to;
  };
  std::vector<Surface> surfaces_;

 private:
  struct Worker;
  // The split of a scan between two threads, or std::nullopt to insert it on one thread.
  std::optional<std::pair<Slab, Slab>> chooseSplit(const Eigen::Vector2d& origin, const CellBox& box);
  std::uint64_t insertParallel(const Eigen::Vector2d& origin, const Slab& mine, const Slab& theirs);

  std::uint64_t cell_updates_ = 0;
  std::uint64_t cell_visits_ = 0;
  std::uint64_t parallel_scans_ = 0;
  CellBox bounds_;
  std::vector<Beam> beams_;  // the current scan's beams (swapped in from a PreparedScan)
  std::unique_ptr<PreparedScan> prepared_;  // scratch of insert(scan, pose)
  std::vector<double> split_sums_;  // scratch of chooseSplit
  std::unique_ptr<Worker> worker_;  // started on the first scan inserted by two threads
  std::uint32_t backoff_ = 0;      // scans to insert single-threaded after a split that did not pay
  std::uint32_t single_left_ = 0;  // scans still to insert single-threaded
};

/// A scan made ready for insertion by `OccupancyMap::prepare` (opaque; keeps its buffers).
class OccupancyMap::PreparedScan {
 public:
  PreparedScan() = default;

 private:
  friend class OccupancyMap;
  const OccupancyMap* model_ = nullptr;  // the map that prepared it
  bool ready_ = false;                   // prepared and not yet inserted
  Eigen::Vector2d origin_ = Eigen::Vector2d::Zero();  // the laser [cells]
  CellBox box_;                                       // every cell the beams touch
  CellBox reserve_;  // the surface guard's edge segment ends, which may lie outside box_ (reserved with it)
  std::vector<Beam> beams_;
  std::vector<Surface> surfaces_;
  // Scratch: beam directions and returns (laser frame; the returns for the surface guard), which
  // beams have a return, and each return's nearer neighbour on its surface (n: none).
  std::vector<Eigen::Vector2d> units_, points_;
  double units_angle_min_ = 0.0, units_angle_increment_ = 0.0;  // the angles `units_` was computed for
  std::vector<double> reach_per_width_;  // per level of covering beams, with `units_` (see `prepare`)
  std::vector<std::uint8_t> hits_;
  std::vector<std::size_t> neighbors_;
  std::vector<double> lengths_;  // each beam's length [cells] (0: not traced)
};

/// Creates a map of the given model. Throws `lidar2d::Error` (kInvalidArgument, naming the field)
/// for out-of-domain options (resolution, probabilities outside (0, 1) or min > max, truncation <= 0).
std::unique_ptr<OccupancyMap> makeMap(MapModel model, const MapOptions& options = {});

/// The TSDF's zero crossings with sub-cell interpolation. Throws kInvalidArgument unless `map` is a
/// TSDF map.
std::vector<SurfacePoint> tsdfSurface(const OccupancyMap& map);

/// A dense classified raster of a map's bounds (row 0 = lowest y), for export.
struct ClassifiedGrid {
  CellBox box;                    ///< cells covered
  double resolution_m = 0.05;     ///< cell size [m]
  std::vector<CellState> cells;   ///< width * height, row-major, row 0 = box.min.y
  std::int64_t width() const { return box.width(); }
  std::int64_t height() const { return box.height(); }
  CellState at(CellIndex c) const {
    return cells[static_cast<std::size_t>((c.y - box.min.y) * width() + (c.x - box.min.x))];
  }
};

/// Classifies every cell in `map.bounds()` (optionally padded by `pad_cells`).
ClassifiedGrid classify(const OccupancyMap& map, int pad_cells = 0);

}  // namespace lidar2d::mapping
