#pragma once
/// @file
/// Correlative scan matching (Olson, "Real-time correlative scan matching", ICRA 2009) searched by
/// branch and bound over precomputed max-grids (Hess et al., "Real-time loop closure in 2D LIDAR
/// SLAM", ICRA 2016, section V). For large initial errors: it tries every pose of a discretised
/// window (translation steps of one grid cell, rotation steps from the scan's maximum range, Hess
/// eq. 7) and returns the best-scoring one, exactly, without visiting most of them. Optionally the
/// winner is refined by the likelihood-field matcher.
///
/// Score of a pose = mean over the source points of the score grid at the cell containing the
/// transformed point (0 outside the grid); grid values are in [0, 1].
/// Frames: the grid lives in the target frame; results are `T_target_source`.

#include <Eigen/Core>
#include <cstddef>
#include <limits>
#include <numbers>
#include <span>
#include <utility>
#include <vector>

#include "lidar2d/core/laser_scan.hpp"
#include "lidar2d/core/occupancy_image.hpp"
#include "lidar2d/core/se2.hpp"
#include "lidar2d/registration/likelihood_field.hpp"
#include "lidar2d/registration/result.hpp"

namespace lidar2d::registration {

/// Options of the correlative matcher (grid construction and search). Out-of-domain values make the
/// functions below throw `lidar2d::Error` (kInvalidArgument) naming the field.
struct CorrelativeOptions {
  // --- grid construction ---
  double resolution_m = 0.05;   ///< cell size of the score grid = translation step [m], > 0
  /// Target points (and wall segments) are blurred by exp(-d^2 / (2 sigma^2)) (Olson 2009, sec. III) [m], > 0
  double blur_sigma_m = 0.05;
  double connect_max_gap_m = 0.3;  ///< consecutive target points closer than this form a segment [m], >= 0
  int occupied_min = 65;        ///< map cells with value >= this score 1 (fromMap), 1..100
  int depth = 7;                ///< max-grid levels (tree depth of the branch and bound), 1..16

  // --- search ---
  double linear_window_m = 1.0;  ///< half-width of the translation window around the guess [m], >= 0
  double angular_window_rad = 30.0 * std::numbers::pi / 180.0;  ///< half-width of the rotation window [rad], in [0, pi]
  /// Rotation step [rad]; 0 derives it from the source's farthest point d_max so that it moves by
  /// at most one cell: acos(1 - r^2 / (2 d_max^2)) (Hess 2016, eq. 7). >= 0
  double angular_step_rad = 0.0;
  double min_score = 0.2;        ///< a best score below this fails the match (status kTooFewInliers), in [0, 1]
  std::size_t min_points = 6;    ///< fewer valid source points fail the match, >= 1

  // --- refinement ---
  bool refine = true;  ///< refine the winner with the likelihood-field matcher (when a field is given/built)
  LikelihoodFieldOptions refinement;  ///< options of that refinement

  /// Throws `lidar2d::Error` (kInvalidArgument) naming the first field out of its domain.
  void validate() const;
};

/// The score grid of one target and its max-grids; build once, search many sources. Movable, not
/// copyable. Cell (i, j) covers [origin + (i, j) * res, origin + (i + 1, j + 1) * res).
class CorrelativeGrid {
 public:
  CorrelativeGrid() = default;
  CorrelativeGrid(const CorrelativeGrid&) = delete;
  CorrelativeGrid& operator=(const CorrelativeGrid&) = delete;
  CorrelativeGrid(CorrelativeGrid&&) = default;
  CorrelativeGrid& operator=(CorrelativeGrid&&) = default;

  /// Grid of a scan's points (beam order, target frame), blurred; non-finite points are skipped.
  static CorrelativeGrid fromPoints(const Points2& target, const CorrelativeOptions& options = {});
  /// The same grid as `fromPoints`, built in place: it reuses this grid's memory, for a caller that
  /// rebuilds a grid of similar size again and again (SLAM's front end, at every node). Fresh
  /// memory costs a page fault per 4 KiB on first touch: on a long-range laser's local map that
  /// was a third of the front end's time.
  void rebuild(const Points2& target, const CorrelativeOptions& options = {});
  /// Grid of an occupancy map (world frame): obstacle cells score 1, blurred onto their neighbours.
  static CorrelativeGrid fromMap(const OccupancyImage& map, const CorrelativeOptions& options = {});

  bool empty() const { return width_ == 0; }
  int width() const { return width_; }
  int height() const { return height_; }
  int depth() const { return static_cast<int>(max_grids_.size()); }
  double resolution() const { return resolution_; }
  const Eigen::Vector2d& origin() const { return origin_; }
  /// Score of cell (i, j), 0 outside the grid.
  float value(int i, int j) const { return maxValue(0, i, j); }
  /// Max-grid of height h (0 = the score grid): max of the scores over the cells
  /// [i, i + 2^h) x [j, j + 2^h) (0 outside the grid). Precondition 0 <= h < depth().
  float maxValue(int h, int i, int j) const {
    const auto& m = max_grids_[static_cast<std::size_t>(h)];
    const int ii = i + m.offset, jj = j + m.offset;
    if (ii < 0 || jj < 0 || ii >= m.width || jj >= m.height) return 0.0f;
    return m.values[static_cast<std::size_t>(jj) * static_cast<std::size_t>(m.width) + static_cast<std::size_t>(ii)];
  }
  /// The smallest box [lo, hi] holding every cell of `cells` (sumMaxValues' box; empty `cells`:
  /// lo above hi).
  static std::pair<Eigen::Vector2i, Eigen::Vector2i> boxOf(std::span<const Eigen::Vector2i> cells) {
    Eigen::Vector2i lo = Eigen::Vector2i::Constant(std::numeric_limits<int>::max());
    Eigen::Vector2i hi = Eigen::Vector2i::Constant(std::numeric_limits<int>::min());
    for (const auto& c : cells) {
      lo = lo.cwiseMin(c);
      hi = hi.cwiseMax(c);
    }
    return {lo, hi};
  }
  /// The sum of maxValue(h, c.x() + i, c.y() + j) over `cells`, whose coordinates all lie in
  /// [lo, hi] (boxOf): when the box shifted by (i, j) is inside the max-grid, without a bounds test per cell
  /// and in four running sums (the branch-and-bound searches' inner loop: its additions no longer
  /// wait on each other). The same sum to rounding; floats added in doubles are in practice exact.
  double sumMaxValues(int h, std::span<const Eigen::Vector2i> cells, int i, int j, const Eigen::Vector2i& lo,
                      const Eigen::Vector2i& hi) const {
    if (cells.empty()) return 0.0;
    const auto& m = max_grids_[static_cast<std::size_t>(h)];
    const int ii = i + m.offset, jj = j + m.offset;
    double sum = 0.0;
    if (lo.x() + ii >= 0 && lo.y() + jj >= 0 && hi.x() + ii < m.width && hi.y() + jj < m.height) {
      const float* base = m.values.data() + static_cast<std::ptrdiff_t>(jj) * m.width + ii;
      double s4[4] = {0.0, 0.0, 0.0, 0.0};
      std::size_t k = 0;
      for (; k + 4 <= cells.size(); k += 4)
        for (int q = 0; q < 4; ++q)
          s4[q] += base[static_cast<std::ptrdiff_t>(cells[k + q].y()) * m.width + cells[k + q].x()];
      for (; k < cells.size(); ++k) s4[0] += base[static_cast<std::ptrdiff_t>(cells[k].y()) * m.width + cells[k].x()];
      sum = (s4[0] + s4[1]) + (s4[2] + s4[3]);
    } else {
      for (const auto& c : cells) sum += maxValue(h, c.x() + i, c.y() + j);
    }
    return sum;
  }

 private:
  struct MaxGrid {
    int offset = 0;  // cells added below/left: index i maps to i + offset
    int width = 0, height = 0;
    std::vector<float> values;
  };
  void buildMaxGrids(int depth);  // levels 1.. from max_grids_[0]

  Eigen::Vector2d origin_ = Eigen::Vector2d::Zero();
  double resolution_ = 0.0;
  int width_ = 0, height_ = 0;
  std::vector<MaxGrid> max_grids_;
  friend struct CorrelativeGridBuilder;
};

/// A correlative result: the common Result plus the search's own numbers. `final_cost` holds the
/// best score too (in [0, 1], higher is better); with refinement, `information`, `covariance`,
/// `iterations` and `num_inliers` come from the likelihood-field refinement.
struct CorrelativeResult : Result {
  double score = 0.0;               ///< best score of the discretised search, in [0, 1]
  SE2 T_search;                     ///< the best pose of the discretised search (before refinement)
  std::size_t candidates_scored = 0;  ///< scores computed (all heights), a measure of the work
  bool refined = false;             ///< the refinement ran and its estimate was used
};

/// Searches the window (options.linear_window_m x options.angular_window_rad) around
/// `init_T_target_source` by branch and bound; refines with `refine_field` when given and
/// options.refine. Bad data (empty/too few points, non-finite guess, empty grid) gives
/// converged = false with a status and a finite pose; out-of-domain options throw.
CorrelativeResult matchCorrelative(const CorrelativeGrid& grid, const Points2& source, const SE2& init_T_target_source,
                                   const CorrelativeOptions& options = {}, const LikelihoodField* refine_field = nullptr);

/// Global search: the whole grid and all orientations (for global localization); no guess needed.
CorrelativeResult matchCorrelativeGlobal(const CorrelativeGrid& grid, const Points2& source,
                                         const CorrelativeOptions& options = {},
                                         const LikelihoodField* refine_field = nullptr);

/// Scan-to-scan convenience: builds the grid (and, with options.refine, the likelihood field) of
/// `target` and matches.
CorrelativeResult matchCorrelative(const Points2& target, const Points2& source, const SE2& init_T_target_source,
                                   const CorrelativeOptions& options = {});

/// The slow reference: scores every pose of the same discretised window as `matchCorrelative`
/// (no refinement). For tests and for checking the branch and bound.
CorrelativeResult matchCorrelativeExhaustive(const CorrelativeGrid& grid, const Points2& source,
                                             const SE2& init_T_target_source, const CorrelativeOptions& options = {});

}  // namespace lidar2d::registration
