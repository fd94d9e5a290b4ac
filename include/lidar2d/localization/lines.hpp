#pragma once
/// @file
/// Line segments of one scan by split-and-merge (Nguyen et al., "A comparison of line extraction
/// algorithms using 2D laser rangefinder for indoor mobile robotics", IROS 2005) with a total
/// least-squares refit, and the infinite-line parameters the global localizer describes a scan by.
///
/// A line is described in the frame of the points (the sensor or robot frame) by its Hessian normal
/// form: the unit normal n = (cos phi, sin phi) pointing from the frame's origin towards the line and
/// the distance d >= 0, so that every point p of the line satisfies n . p = d. The foot of the
/// perpendicular from the origin is d * n. Rotating the frame by alpha adds alpha to phi and leaves d
/// unchanged; differences of phi between two lines are invariant to the rotation.

#include <Eigen/Core>
#include <cstddef>
#include <vector>

#include "lidar2d/core/laser_scan.hpp"

namespace lidar2d::localization {

/// Options of the line extractor. `validate()` throws `lidar2d::Error` (kInvalidArgument) naming
/// the first field out of its domain.
struct LineExtractionOptions {
  double split_threshold_m = 0.05;  ///< a run is split where a point is farther than this from its chord [m], > 0
  double max_gap_m = 0.5;           ///< consecutive points farther apart start a new run [m], > 0
  std::size_t min_points = 4;       ///< fewer points make no line, >= 2
  double min_length_m = 0.4;        ///< shorter segments are dropped [m], >= 0
  double max_rms_m = 0.04;          ///< refit residual RMS above this rejects the segment [m], > 0
  double min_distance_m = 0.3;      ///< lines passing closer to the origin have no usable normal [m], >= 0
  double merge_angle_rad = 0.05;  ///< segments of (nearly) the same infinite line are merged: normal angles [rad], >= 0
  double merge_distance_m = 0.08;  ///< ... and distances closer than this [m], >= 0
  void validate() const;
};

/// One extracted line (frame of the input points).
struct Line {
  double normal_angle = 0.0;  ///< phi: direction of the normal from the origin to the line [rad], in (-pi, pi]
  double distance = 0.0;      ///< d: distance of the infinite line from the origin [m], >= 0
  double length = 0.0;        ///< total length of the segments merged into this line [m]
  Eigen::Vector2d a = Eigen::Vector2d::Zero();  ///< first endpoint of the longest segment (projected on the line) [m]
  Eigen::Vector2d b = Eigen::Vector2d::Zero();  ///< its last endpoint [m]
  std::size_t num_points = 0;                   ///< points supporting the line
  double rms_m = 0.0;                           ///< RMS distance of those points from the line [m]
  /// Foot of the perpendicular from the origin, d * n [m].
  Eigen::Vector2d foot() const;
};

/// Extracts lines from `points` given in scan order (consecutive points are neighbouring beams, as
/// `LaserScan::toPoints` returns them); non-finite points are skipped. Segments of the same infinite
/// line (e.g. a wall interrupted by an obstacle) are merged. Returned longest first. Throws for
/// invalid options only; any input (empty, one point, all identical) gives a possibly empty list.
std::vector<Line> extractLines(const Points2& points, const LineExtractionOptions& options = {});

}  // namespace lidar2d::localization
