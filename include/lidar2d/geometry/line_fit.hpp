#pragma once
/// @file
/// Total-least-squares line fit of a range of points, and the split of a chain of points (in scan
/// order) into pieces that each fit one line: the one implementation the line extractors of
/// localization (split-and-merge, Nguyen et al. 2005, "A comparison of line extraction algorithms
/// using 2D laser rangefinder for indoor mobile robotics", IROS) and of degeneracy (cluster lines)
/// use.
///
/// The options select between variants: the normal and residual variants agree in exact arithmetic
/// but round differently, the end points and split rules differ in what they compute. Each caller
/// keeps the variant its results (and the databases stored from them) were made with.
/// Points are in any 2D frame [m]; every result is in that frame.

#include <Eigen/Core>
#include <cstddef>
#include <limits>
#include <vector>

#include "lidar2d/core/laser_scan.hpp"

namespace lidar2d::geometry {

/// How the line's unit normal n is computed from the scatter S = sum (p - c)(p - c)^T of the
/// points about their centroid c (the normal is S's eigenvector of the smaller eigenvalue).
enum class LineNormal {
  /// The principal axis at the angle phi = atan2(2 S_xy, S_xx - S_yy) / 2; n = (-sin phi, cos phi).
  kPrincipalAngle,
  /// The eigenvector of S / num_points for its smaller eigenvalue in closed form (no trigonometry);
  /// the x axis when S is a multiple of the identity (e.g. all points on one spot).
  kMinorEigenvector,
};

/// How the RMS orthogonal residual is computed.
enum class LineResidual {
  kFromPoints,       ///< sqrt(mean over the points of (n . p - n . c)^2): a second pass over the points
  kMinorEigenvalue,  ///< sqrt(max(0, smaller eigenvalue of S / num_points)): no second pass
};

/// Which end points the fit reports.
enum class LineEnds {
  kFirstAndLast,  ///< the first and the last point of the range, projected onto the line (scan order)
  kExtremes,      ///< the extreme projections of all points onto the line (a at the smallest t along `direction`)
};

/// Options of `fitLine`.
struct LineFitOptions {
  LineNormal normal = LineNormal::kMinorEigenvector;
  LineResidual residual = LineResidual::kMinorEigenvalue;
  LineEnds ends = LineEnds::kExtremes;
  /// Flip n (and offset_m) so that offset_m >= 0, before the residual and the end points are
  /// computed: the Hessian normal form, n pointing from the frame's origin towards the line.
  bool normal_from_origin = false;
};

/// A total-least-squares line: the line through the centroid minimising the sum of squared
/// orthogonal distances of the points.
struct LineFit {
  Eigen::Vector2d centroid = Eigen::Vector2d::Zero();  ///< mean of the points [m]
  Eigen::Vector2d normal = Eigen::Vector2d::UnitY();  ///< unit normal n (its sign is arbitrary, see normal_from_origin)
  Eigen::Vector2d direction = Eigen::Vector2d::UnitX();  ///< unit direction, n turned by +90 deg: (-n_y, n_x)
  double offset_m = 0.0;    ///< n . centroid: the points of the line satisfy n . p = offset_m [m]
  double rms_m = 0.0;       ///< RMS orthogonal distance of the points from the line [m] (see LineResidual)
  double scatter_m2 = 0.0;  ///< S_xx + S_yy: the sum of squared distances from the centroid [m^2]; the
                            ///< normal is arbitrary when it is (nearly) 0 (all points on one spot)
  Eigen::Vector2d a = Eigen::Vector2d::Zero();  ///< first end point, on the line [m] (see LineEnds)
  Eigen::Vector2d b = Eigen::Vector2d::Zero();  ///< second end point, on the line [m]
  std::size_t num_points = 0;
};

/// Fits a line to `points[first, end)`. Preconditions: first < end <= points.size(), finite points
/// (debug-checked). Any such range gives a fit; one point or coincident points give scatter_m2 = 0.
LineFit fitLine(const Points2& points, std::size_t first, std::size_t end, const LineFitOptions& options = {});

/// When a piece of a chain is split.
enum class SplitRule {
  /// Douglas-Peucker (iterative end-point fit): split while a point of the piece is farther than
  /// `threshold_m` from the chord between its first and last point, at the farthest one, which then
  /// ends the left piece and starts the right one (the vertex of the polyline). The distance is
  /// |chord x v| / |chord| (v from the first point); from the first point itself when the chord is
  /// shorter than 1e-9 m (a closed piece). Pieces are fitted once no point is too far.
  kChordDistance,
  /// Fit and split: a piece whose fit has rms_m <= `threshold_m` is a line; otherwise it is split at
  /// the point farthest from its chord (ranked by |u x v| with the unit chord u), which starts the
  /// right piece only; at the middle point when the chord is shorter than 1e-9 m.
  kFitResidual,
};

/// Options of `splitIntoLines`.
struct LineSplitOptions {
  SplitRule rule = SplitRule::kFitResidual;
  double threshold_m = 0.04;   ///< see SplitRule [m], > 0
  std::size_t min_points = 4;  ///< pieces with fewer points are neither fitted nor split further, >= 2
  int max_depth = std::numeric_limits<int>::max();  ///< pieces made by this many splits are not split again, >= 0
  LineFitOptions fit;                               ///< how pieces are fitted
};

/// One piece of a split chain: the points [first, end) of the input.
struct LinePiece {
  enum class Kind {
    kLine,          ///< fits one line (by the split rule): `fit` holds it
    kTooFewPoints,  ///< fewer than min_points: not fitted
    kTooDeep,       ///< kFitResidual only: no line at max_depth splits (`fit` holds the rejected fit)
  };
  Kind kind = Kind::kTooFewPoints;
  std::size_t first = 0, end = 0;
  LineFit fit;
};

/// Splits the chain `points[first, end)` (consecutive points are neighbours, e.g. beams in scan
/// order) into pieces by `options.rule` and appends them to `*out` in chain order; the pieces cover
/// the chain (for kChordDistance, neighbouring pieces share their common point). Preconditions:
/// first < end <= points.size(), finite points, options as documented (debug-checked).
void splitIntoLines(const Points2& points, std::size_t first, std::size_t end, const LineSplitOptions& options,
                    std::vector<LinePiece>* out);

}  // namespace lidar2d::geometry
