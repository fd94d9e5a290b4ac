#pragma once
/// @file
/// Simulated 2D worlds: a set of line segments and circular arcs in the world frame [m], with exact
/// ray casting accelerated by a uniform grid over the primitives.
///
/// Ray casting is exact in the sense that the accelerated caster returns the same value as a loop
/// over all primitives (`castRayBruteForce`, the test reference): the grid only decides *which*
/// primitives are tested, and every primitive is tested with the same closed-form intersection.

#include <Eigen/Core>
#include <cstdint>
#include <string>
#include <vector>

namespace lidar2d::sim {

/// A wall piece from `a` to `b` in the world frame [m]. Both ends belong to the segment (a ray
/// through an endpoint hits it). A ray parallel to the segment never hits it (a collinear ray hits
/// the walls that meet it instead).
struct Segment {
  Eigen::Vector2d a = Eigen::Vector2d::Zero();  ///< start point [m]
  Eigen::Vector2d b = Eigen::Vector2d::Zero();  ///< end point [m]
};

/// A circular arc: the points `center + radius * (cos(phi), sin(phi))` for phi in
/// [start_rad, start_rad + sweep_rad] (counter-clockwise). `sweep_rad >= 2*pi` is a full circle
/// (a pillar, a table leg). Both end points belong to the arc.
struct Arc {
  Eigen::Vector2d center = Eigen::Vector2d::Zero();  ///< [m]
  double radius_m = 0.0;                             ///< > 0 [m]
  double start_rad = 0.0;                            ///< angle of the first end point [rad]
  double sweep_rad = 0.0;                            ///< counter-clockwise extent, > 0 [rad]

  /// A full circle.
  static Arc circle(const Eigen::Vector2d& center, double radius_m);
};

/// Options of the ray-casting acceleration grid.
struct WorldOptions {
  /// Side of a grid cell [m]; 0 = automatic (about one primitive per cell, between 0.05 and 5 m,
  /// at most 4 million cells).
  double cell_size_m = 0.0;
};

/// An immutable set of primitives with its acceleration grid. Cheap to query from many threads.
class World {
 public:
  /// An empty world (every ray misses).
  World() = default;
  /// Checks the primitives (finite coordinates, segments of non-zero length, radius > 0,
  /// sweep > 0) and builds the grid. Throws `lidar2d::Error` (kInvalidArgument) naming the
  /// offending primitive.
  World(std::vector<Segment> segments, std::vector<Arc> arcs, std::string name = {},
        const WorldOptions& options = {});

  /// Distance [m] from `origin` along the unit direction `dir` (world frame) to the nearest
  /// primitive, if it is within [0, max_range_m]; +infinity otherwise. A ray starting on a
  /// primitive returns 0. Precondition: `dir` has unit length (debug-checked).
  double castRay(const Eigen::Vector2d& origin, const Eigen::Vector2d& dir, double max_range_m) const;
  /// Same, with the direction given as an angle in the world frame [rad].
  double castRay(const Eigen::Vector2d& origin, double angle_rad, double max_range_m) const;
  /// Reference implementation of `castRay`: tests every primitive. Used by the tests.
  double castRayBruteForce(const Eigen::Vector2d& origin, const Eigen::Vector2d& dir, double max_range_m) const;

  /// Euclidean distance [m] from `p` to the nearest primitive (+infinity in an empty world). Loops
  /// over all primitives; meant for path checks, not for inner loops.
  double distance(const Eigen::Vector2d& p) const;

  const std::vector<Segment>& segments() const { return segments_; }
  const std::vector<Arc>& arcs() const { return arcs_; }
  std::size_t numPrimitives() const { return segments_.size() + arcs_.size(); }
  const std::string& name() const { return name_; }
  /// Axis-aligned bounds of all primitives [m] (arcs: their whole circle; both zero in an empty world).
  const Eigen::Vector2d& boundsMin() const { return min_; }
  const Eigen::Vector2d& boundsMax() const { return max_; }
  /// Side of a grid cell [m] (0 in an empty world).
  double cellSize() const { return cell_; }

 private:
  double hitPrimitive(std::uint32_t id, const Eigen::Vector2d& origin, const Eigen::Vector2d& dir) const;

  std::vector<Segment> segments_;
  std::vector<Arc> arcs_;
  std::string name_;
  Eigen::Vector2d min_ = Eigen::Vector2d::Zero();
  Eigen::Vector2d max_ = Eigen::Vector2d::Zero();
  Eigen::Vector2d gmin_ = Eigen::Vector2d::Zero();  // grid box: primitives' bounds plus a margin, whole cells
  Eigen::Vector2d gmax_ = Eigen::Vector2d::Zero();
  double cell_ = 0.0;
  int nx_ = 0;
  int ny_ = 0;
  std::vector<std::uint32_t> cell_start_;  // CSR: primitives of cell c are ids_[cell_start_[c] .. cell_start_[c+1])
  std::vector<std::uint32_t> ids_;         // primitive id: segments first, then arcs
};

/// Intersection of the ray `origin + t * dir` (t >= 0) with a segment: the smallest such t, or
/// +infinity. Parallel rays miss.
double intersectSegment(const Segment& s, const Eigen::Vector2d& origin, const Eigen::Vector2d& dir);
/// Intersection of the ray `origin + t * dir` (t >= 0, `dir` of unit length) with an arc: the
/// smallest such t, or +infinity. A tangent ray hits at the tangent point.
double intersectArc(const Arc& a, const Eigen::Vector2d& origin, const Eigen::Vector2d& dir);

}  // namespace lidar2d::sim
