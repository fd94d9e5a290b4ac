#pragma once
/// @file
/// Likelihood-field scan matching: the target (a scan or an occupancy map) is turned once into a
/// truncated distance field on a grid, at several resolutions; a source scan is aligned by
/// minimising the sum of squared field values at its transformed points (Thrun et al.,
/// "Probabilistic Robotics", section 6.4, with the Gaussian likelihood replaced by its negative
/// log, i.e. the squared distance, so that Gauss-Newton applies directly).
///
/// The field is sampled at grid nodes and interpolated bilinearly together with its analytic
/// gradient (no rounding to the nearest cell). Why a *signed* distance for scans: the bilinear
/// interpolant of an unsigned distance |d| is piecewise linear across a wall and so has its minima
/// at grid nodes, which biases the estimate by up to half a cell; the signed distance to a wall is
/// itself linear and is reproduced exactly by bilinear interpolation, so sub-cell accuracy is
/// unbiased. A scan's consecutive points closer than `connect_max_gap_m` are joined into segments
/// whose side facing the sensor is positive; isolated points and occupancy-map cells give an
/// unsigned distance.
///
/// Frames: the field lives in the target frame (the scan's frame, or the map's world frame); the
/// matchers estimate `T_target_source` (`p_target = T_target_source * p_source`).

#include <Eigen/Core>
#include <cstddef>
#include <numbers>
#include <vector>

#include "lidar2d/core/laser_scan.hpp"
#include "lidar2d/core/se2.hpp"
#include "lidar2d/core/occupancy_image.hpp"
#include "lidar2d/registration/result.hpp"

namespace lidar2d::registration {

/// Which solver minimises the field cost.
enum class LfSolver {
  kGaussNewton,  ///< hand-written Gauss-Newton with analytic Jacobians and IRLS robust weights
  kCeres,        ///< Ceres trust region, all points in one analytic-derivative residual block per level
                 ///< (the loss applied per point inside it: the same cost as a block per point)
};

/// Robust loss applied to the per-point residuals (metres).
enum class LfLoss { kNone, kHuber, kCauchy };

/// Options of the likelihood field (construction and matching). Out-of-domain values make the
/// functions below throw `lidar2d::Error` (kInvalidArgument) naming the field.
struct LikelihoodFieldOptions {
  // --- field construction ---
  double resolution_m = 0.05;     ///< node spacing of the finest level [m], > 0
  int levels = 3;                 ///< resolutions, each twice as coarse as the previous, 1..8
  /// The field is clamped to +-truncation at the finest level (scaled by 2^level on coarser levels);
  /// points whose interpolation cell touches the truncation are outliers [m], >= 2 * resolution_m.
  double truncation_m = 0.2;
  /// Consecutive target points closer than this are joined into a wall segment [m], >= 0 (0: never).
  double connect_max_gap_m = 1.0;
  int occupied_min = 65;          ///< map cells with value >= this are obstacles (fromMap), 1..100

  // --- matching ---
  LfSolver solver = LfSolver::kGaussNewton;
  LfLoss loss = LfLoss::kHuber;
  double loss_scale_m = 0.05;     ///< robust loss scale at the finest level [m] (x 2^level), > 0
  int max_iterations = 20;        ///< iterations per level, >= 1
  /// A level ends when a step (Ceres: an accepted one) is below both [m], >= 0; the finest level's
  /// ending so is `converged`. Coarse levels, which only seed the next, also end at steps under
  /// 0.005 of their cell. Gauss-Newton on the piecewise-bilinear field can instead cycle between
  /// two to four poses: a level then ends at the lowest-cost of them and their centroid, and at the
  /// finest level that counts as converged when they lie within a tenth of a cell of each other
  /// (else the match ends unconverged, kMaxIterations, its message giving the spread). Out of
  /// iterations, the finest level's estimate is the lowest-cost of its last five iterates.
  double min_translation_step_m = 1e-5;
  double min_rotation_step_rad = 1e-5;  ///< [rad], >= 0 (see min_translation_step_m)
  std::size_t min_points = 6;     ///< fewer valid source points (or inliers) fail the match, >= 3
  /// Gauss-Newton at the finest level: halve a step that raises the cost (all points, those outside
  /// the truncation counted at it), up to 4 times, and stop where none lowers it. Against a map's
  /// unsigned field, whose bilinear interpolant has kinks along the cells, plain Gauss-Newton keeps
  /// stepping across the minimum until max_iterations; with the search it stops there. It helps
  /// scan to map (more successes, converged matches) but not scan to scan (slightly fewer successes
  /// on intel): off by default, on for `PreparedTarget::fromMap` targets.
  bool line_search = false;

  /// Throws `lidar2d::Error` (kInvalidArgument) naming the first field out of its domain.
  void validate() const;
};

/// A prepared multi-resolution field of one target: build once, match many sources against it.
/// Movable, not copyable.
class LikelihoodField {
 public:
  /// One resolution level: node (i, j) sits at `origin + (i, j) * resolution`; `values` row-major
  /// (j * width + i).
  struct Level {
    Eigen::Vector2d origin = Eigen::Vector2d::Zero();  ///< position of node (0, 0) [m]
    double resolution = 0.0;                           ///< node spacing [m]
    double inv_resolution = 0.0;                       ///< 1 / resolution [1/m]
    double truncation = 0.0;                           ///< |value| clamp [m]
    int width = 0;
    int height = 0;
    std::vector<float> values;  ///< truncated (signed) distance at the nodes [m]
    float at(int i, int j) const { return values[static_cast<std::size_t>(j) * static_cast<std::size_t>(width) + static_cast<std::size_t>(i)]; }

    /// The grid cell holding a point: its node below-left (`row0`; `row0 + width` the row above) and
    /// the point's fractions `fx`, `fy` within it. `row0` is null outside the grid (or for NaN).
    struct Cell {
      const float* row0 = nullptr;
      double fx = 0.0, fy = 0.0;
    };
    Cell cellAt(const Eigen::Vector2d& p) const {
      // Multiplying: a division per coordinate cost a fifth of the matchers' time.
      const double ux = (p.x() - origin.x()) * inv_resolution, uy = (p.y() - origin.y()) * inv_resolution;
      // The negated comparison also rejects NaN.
      if (!(ux >= 0.0 && uy >= 0.0 && ux < width - 1 && uy < height - 1)) return {};
      const int i = static_cast<int>(ux), j = static_cast<int>(uy);
      return {
          values.data() + static_cast<std::size_t>(j) * static_cast<std::size_t>(width) + static_cast<std::size_t>(i),
          ux - i, uy - j};
    }
    /// The bilinear interpolation of the cell's four nodes (c.row0 not null).
    double interpolate(const Cell& c) const {
      const double v00 = c.row0[0], v10 = c.row0[1], v01 = c.row0[width], v11 = c.row0[width + 1];
      const double fx = c.fx, fy = c.fy;
      return (1 - fx) * (1 - fy) * v00 + fx * (1 - fy) * v10 + (1 - fx) * fy * v01 + fx * fy * v11;
    }
  };

  /// Interpolated value and gradient at a point.
  struct Sample {
    double value = 0.0;                              ///< field value [m] (the truncation outside)
    Eigen::Vector2d gradient = Eigen::Vector2d::Zero();  ///< d value / d p [m/m]
    bool inlier = false;  ///< inside the grid and all four nodes of the cell below the truncation
  };

  LikelihoodField() = default;
  LikelihoodField(const LikelihoodField&) = delete;
  LikelihoodField& operator=(const LikelihoodField&) = delete;
  LikelihoodField(LikelihoodField&&) = default;
  LikelihoodField& operator=(LikelihoodField&&) = default;

  /// Field of a scan's points (in beam order, target frame), signed positive on the side of
  /// `sensor_origin` (the target scan's laser position in the target frame). Non-finite points are
  /// skipped. An empty field (no valid points) is allowed: every match against it fails cleanly.
  static LikelihoodField fromPoints(const Points2& target, const LikelihoodFieldOptions& options = {},
                                    const Eigen::Vector2d& sensor_origin = Eigen::Vector2d::Zero());
  /// Field of an occupancy map's obstacle cells (value >= options.occupied_min), in the world
  /// frame of the map (the image origin applied). Unsigned distance to the cell centres.
  static LikelihoodField fromMap(const OccupancyImage& map, const LikelihoodFieldOptions& options = {});

  bool empty() const { return levels_.empty(); }
  int numLevels() const { return static_cast<int>(levels_.size()); }
  const Level& level(int l) const { return levels_[static_cast<std::size_t>(l)]; }
  /// Bilinear interpolation of level `l` at `p_target` [m] with its analytic gradient.
  Sample sample(const Eigen::Vector2d& p_target, int l = 0) const;
  /// sample(p_target, l).value alone, inline: scoring loops that need no gradient (global
  /// localization's pre-scoring and scores sample millions of points per query).
  double value(const Eigen::Vector2d& p_target, int l = 0) const {
    const Level& lv = levels_[static_cast<std::size_t>(l)];
    const Level::Cell c = lv.cellAt(p_target);
    return c.row0 ? lv.interpolate(c) : lv.truncation;
  }

 private:
  std::vector<Level> levels_;
};

/// Aligns `source` (points in the source frame) to a prepared field, coarse to fine, starting from
/// `init_T_target_source`. Returns a Result (never throws for bad data: empty or too few points,
/// non-finite guess or an empty field give converged = false with a status and a finite pose).
/// `final_cost` is the mean squared residual of the inliers at the finest level [m^2]; `information`
/// is J^T W J of the last linearisation; `covariance` = sigma^2 H^-1 with sigma^2 = cost / (n - 3).
/// Throws `lidar2d::Error` (kInvalidArgument) for out-of-domain options.
Result matchLikelihoodField(const LikelihoodField& field, const Points2& source, const SE2& init_T_target_source,
                            const LikelihoodFieldOptions& options = {});

/// Scan-to-scan convenience: builds the field of `target` (sensor at the target frame's origin) and
/// matches. For many sources against one target, build the field once instead.
Result matchLikelihoodField(const Points2& target, const Points2& source, const SE2& init_T_target_source,
                            const LikelihoodFieldOptions& options = {});

}  // namespace lidar2d::registration
