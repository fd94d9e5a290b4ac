#pragma once
/// @file
/// One entry point for every scan matcher: pick a `Method` and a `Solver`, get a `Result`.
///
/// Frames: `target` and `source` are point sets in their own frames [m] (typically the robot frame
/// of two scans); the estimate is `T_target_source` with `p_target = T_target_source * p_source`.
/// Bad input (empty or degenerate point sets, a non-finite guess, bad options) never throws: the
/// `Result` says why it did not converge (see icp.hpp).

#include <memory>
#include <optional>
#include <string>

#include "lidar2d/core/laser_scan.hpp"
#include "lidar2d/core/se2.hpp"
#include "lidar2d/core/occupancy_image.hpp"
#include "lidar2d/registration/correlative.hpp"
#include "lidar2d/registration/icp.hpp"
#include "lidar2d/registration/likelihood_field.hpp"
#include "lidar2d/registration/result.hpp"

namespace lidar2d::registration {

/// Scan matching methods.
enum class Method {
  kP2P,              ///< point-to-point ICP
  kP2L,              ///< point-to-line ICP (Censi 2008)
  kLikelihoodField,  ///< likelihood-field matching
  kCorrelative,      ///< correlative search (Olson 2009) with branch-and-bound (Hess et al. 2016)
};
/// "p2p", "p2l", "lf" or "corr" (the names of `lidar2d match --method`).
const char* toString(Method m);
/// Inverse of toString(Method); std::nullopt for an unknown name.
std::optional<Method> parseMethod(const std::string& name);
/// Inverse of toString(Solver) ("gn", "ceres"); std::nullopt for an unknown name.
std::optional<Solver> parseSolver(const std::string& name);

/// Options of every method; each method reads its own member.
struct MatcherOptions {
  Method method = Method::kP2L;          ///< which matcher runs
  Solver solver = Solver::kGaussNewton;  ///< optimiser of the methods that offer several
  /// kP2P and kP2L. Its `metric` and `solver` fields are ignored: `method` and `solver` above win.
  IcpOptions icp;
  /// kLikelihoodField. Its `solver` field is ignored: `solver` above wins.
  LikelihoodFieldOptions lf;
  /// kCorrelative (search window, grid, and the likelihood-field refinement; `solver` above wins
  /// for the refinement too).
  CorrelativeOptions corr;
  /// PreparedTarget::fromMap: map cells with a value >= this are obstacles, for every method
  /// (it replaces `lf.occupied_min` and `corr.occupied_min` there), 1..100.
  int map_occupied_min = 65;
};

/// A target prepared once for matching several sources against it (the neighbour search and line normals
/// for ICP; the field or grids of the other methods). Movable, not copyable.
class PreparedTarget {
 public:
  /// Prepares `points_target` [m] for `options.method`. Never throws for bad points (the matches
  /// report them).
  PreparedTarget(const Points2& points_target, const MatcherOptions& options);
  /// Scan-to-map: prepares an occupancy map (world frame) for kLikelihoodField
  /// (`LikelihoodField::fromMap`) or kCorrelative (`CorrelativeGrid::fromMap`, refined by the
  /// map's field), so that the matches estimate T_world_source, the source scan's pose in the map.
  /// Obstacles are the cells with a value >= `options.map_occupied_min`. Matches against it run the
  /// field's Gauss-Newton with `LikelihoodFieldOptions::line_search` on (for the correlative
  /// search's refinement too): against a map's unsigned field it stops at the minimum instead of
  /// stepping across it until max_iterations.
  /// kP2P and kP2L give a target that every match reports as kInvalidInput: against the centres
  /// of a map's cells ICP is biased by up to half a cell (a wall on a cell border is drawn on one
  /// side of it; the field measures the distance to the cells' extent instead), and point-to-line
  /// finds few lines along walls drawn two or more cells thick. ICP scan-to-map matches a point
  /// map instead: an `IcpTarget` (k-d tree search) over the scan points of a local map, as the SLAM
  /// front end does.
  /// Never throws: out-of-domain options are reported by matchScans, like the constructor's.
  static PreparedTarget fromMap(const OccupancyImage& map, const MatcherOptions& options);
  ~PreparedTarget();
  PreparedTarget(PreparedTarget&&) noexcept;
  PreparedTarget& operator=(PreparedTarget&&) noexcept;
  PreparedTarget(const PreparedTarget&) = delete;
  PreparedTarget& operator=(const PreparedTarget&) = delete;

  /// The method it was prepared for.
  Method method() const { return method_; }
  /// The target points as given [m].
  const Points2& points() const { return points_; }
  /// The ICP target (kP2P, kP2L), else nullptr.
  const IcpTarget* icp() const { return icp_.get(); }
  /// The likelihood field (kLikelihoodField; kCorrelative with refinement), else nullptr.
  const LikelihoodField* field() const { return field_.get(); }
  /// The correlative score grid (kCorrelative), else nullptr.
  const CorrelativeGrid* grid() const { return grid_.get(); }
  /// Why preparing failed (out-of-domain options), or empty.
  const std::string& error() const { return error_; }
  /// True when prepared from an occupancy map (`fromMap`).
  bool isMap() const { return from_map_; }

 private:
  Method method_;
  Points2 points_;
  std::unique_ptr<IcpTarget> icp_;
  std::unique_ptr<LikelihoodField> field_;
  std::unique_ptr<CorrelativeGrid> grid_;
  std::string error_;  // why the target could not be prepared (bad options), reported by matchScans
  bool from_map_ = false;

  explicit PreparedTarget(Method method) : method_(method) {}
};

/// Matches `source` against a prepared target from `init_T_target_source`. When `options.method`
/// differs from the target's method, the result is kInvalidInput.
Result matchScans(const PreparedTarget& target, const Points2& source, const SE2& init_T_target_source,
                  const MatcherOptions& options);

/// Prepares `target` and matches `source` against it.
Result matchScans(const Points2& target, const Points2& source, const SE2& init_T_target_source,
                  const MatcherOptions& options);

}  // namespace lidar2d::registration
