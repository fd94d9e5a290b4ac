#pragma once
/// @file
/// Iterative closest point (ICP) scan matching in the plane: point-to-point and point-to-line
/// (Censi 2008, "An ICP variant using a point-to-line metric", ICRA), each solved either by a
/// hand-written Gauss-Newton loop with analytic Jacobians or by Ceres with a robust loss.
///
/// Both estimate `T_target_source` (see result.hpp): `p_target = T_target_source * p_source`.
/// Every iteration pairs each transformed source point with its nearest target point (an exact
/// search structure built once per target, see `IcpTarget` and `NeighborSearch`: a bearing-sorted
/// index by default, or a nanoflann k-d tree), rejects pairs farther apart than
/// `max_correspondence_dist_m`, keeps the `trim_keep_fraction` closest of the rest (trimmed ICP,
/// Chetverikov et al. 2002), and minimises
///   point-to-point: sum_i rho(|T p_i - q_i|^2)
///   point-to-line:  sum_i rho((n_i . (T p_i - q_i))^2)
/// with q_i the nearest target point, n_i the unit normal of the line fitted to q_i's neighbours
/// (precomputed per target point) and rho the robust loss. Where q_i's neighbourhood fits no line
/// (a corner, clutter, a short noisy stretch of wall), n_i is the normal of the line through q_i
/// and whichever of its fitted neighbours is nearest to T p_i (`two_point_lines`, the default: as
/// Censi's PL-ICP uses the line through the two nearest target points); the reported information
/// leaves those pairs out (`Result::information`: their normals are partly noise). Without them
/// such pairs are dropped unless `point_pair_weight` > 0: then such a pair adds w (x, y) of
/// T p_i - q_i as two residuals (each with the robust loss), which pins the direction along a
/// corridor's walls that the line pairs leave free. It stops when the increment of the pose falls
/// below both `translation_eps_m` and `rotation_eps_rad` (by default 1 mm and 1 mrad for
/// point-to-line, a tenth of that for point-to-point: `IcpOptions::defaultTranslationEps`), or when
/// a search returns a set of pairs already solved in one of the last 8 iterations (a fixed point of
/// the correspondences, or a cycle through a few sets, where searching on cannot settle further);
/// both count as converged.
///
/// Bad input never throws and never yields a NaN pose: empty or too small point sets, all-NaN or
/// all-identical points, a non-finite initial guess and out-of-domain options give a `Result` with
/// `converged == false`, the matching `Status`, a message, and the initial guess as the pose (the
/// identity when the guess itself is not finite).

#include <cstddef>
#include <memory>
#include <optional>
#include <string>

#include "lidar2d/core/laser_scan.hpp"
#include "lidar2d/core/se2.hpp"
#include "lidar2d/registration/result.hpp"

namespace lidar2d::registration {

/// Which optimiser solves the least-squares problem of a matcher (shared by every matcher that
/// offers both).
enum class Solver {
  kGaussNewton,  ///< hand-written Gauss-Newton with analytic Jacobians (robust loss as IRLS weights)
  kCeres,        ///< Ceres Solver (dense QR, Levenberg-Marquardt) with the robust loss (Ceres's
                 ///< HuberLoss / CauchyLoss, applied per pair inside one residual block per search)
};
/// "gn" or "ceres".
const char* toString(Solver s);

/// A robust loss rho(s) of a squared residual s = r^2, with Ceres' definitions (the cost is
/// 0.5 * rho(s)). The Gauss-Newton solvers use the matching iteratively-reweighted least-squares
/// weight rho'(s), so both solvers minimise the same cost for fixed correspondences.
struct RobustLoss {
  enum class Kind {
    kNone,    ///< rho(s) = s (plain least squares)
    kHuber,   ///< rho(s) = s for s <= a^2, else 2 a sqrt(s) - a^2 (weight min(1, a / |r|))
    kCauchy,  ///< rho(s) = a^2 log(1 + s / a^2) (weight 1 / (1 + s / a^2))
  };
  Kind kind = Kind::kHuber;
  double scale_m = 0.05;  ///< a: residual size where the loss turns robust [m], > 0

  /// rho'(r^2): the IRLS weight of a residual r [m].
  double weight(double r) const;
  /// rho(r^2) [m^2].
  double rho(double r) const;
};
/// "none", "huber" or "cauchy".
const char* toString(RobustLoss::Kind k);

/// The residual ICP minimises.
enum class IcpMetric {
  kPointToPoint,  ///< |T p - q| (2 residuals per pair)
  kPointToLine,   ///< n . (T p - q), n the normal of the target's local line (Censi 2008)
};

/// How ICP finds each transformed source point's nearest target point. Both searches are exact
/// (they return the same nearest distance); they differ in speed only.
enum class NeighborSearch {
  /// The target sorted by bearing from its frame's origin; each query walks outwards from its own
  /// bearing and stops when no farther bearing can hold a closer point (the projective search of
  /// Censi 2008 made exact). No tree to build; a few points visited per query on scans.
  kBearingWalk,
  kKdTree,  ///< a nanoflann k-d tree over the target
};
/// "bearing" or "kdtree".
const char* toString(NeighborSearch s);

/// Options of ICP. Defaults suit indoor 2D scans (0.25 - 1 degree beam spacing, ranges up to tens
/// of metres) with initial errors up to ~0.3 m and ~10 degrees.
struct IcpOptions {
  IcpMetric metric = IcpMetric::kPointToLine;  ///< residual (set from `Method` by matchScans)
  Solver solver = Solver::kGaussNewton;        ///< optimiser (set from `Solver` by matchScans)
  double max_correspondence_dist_m = 1.0;  ///< pairs whose points are farther apart are rejected [m], > 0
  double trim_keep_fraction = 0.9;  ///< keep this fraction of the distance-gated pairs, the closest ones
                                    ///< (trimmed ICP), in (0, 1]
  int max_iterations = 50;          ///< outer iterations (correspondence searches), >= 1; the result's
                                    ///< `iterations` counts these
  /// Converged when the translation increment of an outer iteration is below this [m], >= 0; unset:
  /// the metric's default (`defaultTranslationEps`). See `defaultTranslationEps` for why they differ.
  std::optional<double> translation_eps_m;
  /// ... and the rotation increment below this [rad], >= 0; unset: `defaultRotationEps(metric)`.
  std::optional<double> rotation_eps_rad;
  RobustLoss loss;                  ///< robust loss of both solvers (IRLS weights for Gauss-Newton)
  std::size_t min_points = 10;      ///< fewer finite source or target points: kTooFewPoints, >= 3
  std::size_t min_inliers = 8;      ///< fewer surviving pairs in an iteration: kTooFewInliers, >= 3
  int normal_neighbors = 5;         ///< target points (itself included) fitted per line, >= 2
  double normal_max_radius_m = 1.0;  ///< neighbours farther than this from the point are not fitted [m], > 0
  double max_line_flatness = 0.2;   ///< a fit whose smaller/larger spread ratio (sqrt of the eigenvalue
                                    ///< ratio) exceeds this is no line: that target point gets no normal
                                    ///< and is not used by point-to-line, in [0, 1]
  NeighborSearch neighbor_search = NeighborSearch::kBearingWalk;  ///< nearest-neighbour structure of the target
                                                                  ///< (read by IcpTarget)
  /// Point-to-line: weight w of the point-to-point pairs of target points with no line (see the
  /// file comment; with `two_point_lines`, only those without a fitted neighbour), >= 0; 0 drops
  /// those pairs. The residuals are w times the x and y offsets [m], so the robust loss takes
  /// effect at scale_m / w of offset.
  double point_pair_weight = 0.0;
  /// Source points closer than this to the previous point kept, in the order given (a scan's: by
  /// bearing), are left out of the match [m], >= 0; 0 keeps them all. A 360-beam scan's returns
  /// near the laser lie a few millimetres apart, and their pairs cost time without pinning the pose
  /// any better than every third one does. When fewer than `min_points` would be left, all finite
  /// points are used. The reported information matrix sums the kept points' terms only.
  double min_source_spacing_m = 0.03;
  /// Point-to-line: pair a target point whose neighbourhood fits no line (a corner, clutter, or a
  /// short noisy stretch of wall) with the line through it and whichever of its fitted neighbours
  /// (the `normal_neighbors` nearest, within `normal_max_radius_m`; 8 at most) is nearest to the
  /// source point, as Censi's PL-ICP pairs every point with the line through its two nearest target
  /// points. false drops those pairs (or pairs them point to point: `point_pair_weight`). These
  /// pairs are left out of the reported information and covariance (see `finish` in icp_problem.cpp).
  /// They get more pairs right, at a cost in time on 360-beam scans, where many short fits fail the
  /// flatness test.
  bool two_point_lines = true;
  int gn_inner_iterations = 3;          ///< Gauss-Newton steps per set of correspondences, >= 1
  /// Ceres (Levenberg-Marquardt) iterations per set of correspondences, >= 1. As many as the
  /// Gauss-Newton steps: more only refine a set of pairs that the next search replaces.
  int ceres_max_inner_iterations = 3;

  /// The convergence thresholds in effect: the ones set, else the metric's defaults.
  double translationEps() const { return translation_eps_m.value_or(defaultTranslationEps(metric)); }
  double rotationEps() const { return rotation_eps_rad.value_or(defaultRotationEps(metric)); }

  /// Default convergence thresholds per metric: 1 mm and 1 mrad for point-to-line, 0.1 mm and
  /// 0.1 mrad for point-to-point. Point-to-line is within a millimetre of its fixed point after a
  /// few iterations; from there on its nearest neighbours hop between adjacent target points (each
  /// with its own line fit) and the pose wanders by 0.2-2 mm per iteration without settling:
  /// stopping at 1 mm skips those iterations (about 30% of its time on freiburg-079) for one or two
  /// pairs of success per log, and still ends within 0.2 mm of the truth on noise-free simulated
  /// scans. Point-to-point converges only linearly, creeping along walls by about a millimetre per
  /// iteration: stopped at 1 mm it ends up to 5 mm short, so it keeps the finer threshold.
  static constexpr double defaultTranslationEps(IcpMetric m) { return m == IcpMetric::kPointToLine ? 1e-3 : 1e-4; }
  static constexpr double defaultRotationEps(IcpMetric m) { return m == IcpMetric::kPointToLine ? 1e-3 : 1e-4; }

  /// Empty when every option is in its domain, else a message naming the first bad field.
  std::string check() const;
};

/// A target point set prepared once for matching many sources against it: the finite target
/// points, a nearest-neighbour structure over them (`IcpOptions::neighbor_search`) and the unit
/// normal of each point's local line fit. Build it once
/// per target scan and reuse it (the tree and normals are never rebuilt during the iterations).
/// Movable, not copyable; thread-safe for concurrent `alignIcp` calls once built.
class IcpTarget {
 public:
  /// Keeps the finite points of `points_target` (in the target frame [m]) and fits their lines
  /// with `options.normal_neighbors`, `options.normal_max_radius_m` and `options.max_line_flatness`
  /// (with `options.two_point_lines`, also the lines to the neighbours of each point that fits
  /// none; a target built without them matches as if `two_point_lines` were false); builds the
  /// structure of `options.neighbor_search` (other fields are unused).
  /// Never throws for bad points: an empty or all-NaN set gives an empty target that every match
  /// reports as kTooFewPoints.
  explicit IcpTarget(const Points2& points_target, const IcpOptions& options = {});
  ~IcpTarget();
  IcpTarget(IcpTarget&&) noexcept;
  IcpTarget& operator=(IcpTarget&&) noexcept;
  IcpTarget(const IcpTarget&) = delete;
  IcpTarget& operator=(const IcpTarget&) = delete;

  /// Number of finite target points kept.
  std::size_t size() const;
  /// The finite target points [m], in input order.
  const Points2& points() const;
  /// Unit normal of each point's fitted line, or (0, 0) where the neighbourhood is no line.
  const Points2& normals() const;
  /// True when every kept point is the same point (within 1e-9 m): nothing can be matched.
  bool allIdentical() const;
  /// Index of the target point nearest to `p` and its squared distance [m^2]; size() when empty.
  std::size_t nearest(const Eigen::Vector2d& p, double* dist_sq) const;
  /// The nearest target point among those within sqrt(max_dist_sq) of `p` (index and squared
  /// distance), or size() and +inf when there is none; faster than `nearest` for a small radius.
  /// `hint` (optional, in and out) speeds up a series of queries: pass the same variable for
  /// queries at nearby bearings from the target's origin (successive points of a scan, or one
  /// point as it moves); any starting value. The answer does not depend on it.
  std::size_t nearestWithin(const Eigen::Vector2d& p, double max_dist_sq, double* dist_sq,
                            std::uint32_t* hint = nullptr) const;

  struct Impl;
  /// Internal: the search structures, for the correspondence search in icp_problem.cpp (an
  /// incomplete type elsewhere).
  const Impl& impl() const { return *impl_; }

 private:
  std::unique_ptr<Impl> impl_;
};

/// Aligns `points_source` (source frame [m]) to a prepared target, starting at
/// `init_T_target_source`. See the file comment for the method and for bad input.
Result alignIcp(const IcpTarget& target, const Points2& points_source, const SE2& init_T_target_source,
                const IcpOptions& options = {});

/// Convenience: prepares the target and aligns. Prefer `IcpTarget` when a target is reused.
Result alignIcp(const Points2& points_target, const Points2& points_source, const SE2& init_T_target_source,
                const IcpOptions& options = {});

}  // namespace lidar2d::registration
