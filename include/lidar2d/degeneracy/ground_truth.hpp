#pragma once
/// @file
/// Ground truth for degeneracy in simulated worlds: which primitives of the world the beams of a scan
/// hit, and whether those visible walls are all parallel (the scan cannot tell where along them the
/// robot is). Used by the evaluation of the detectors (bench/dataset/degeneracy_bench.cpp, tests).

#include <cstddef>
#include <limits>

#include "lidar2d/core/se2.hpp"
#include "lidar2d/sim/simulator.hpp"
#include "lidar2d/sim/world.hpp"

namespace lidar2d::degeneracy {

/// How a scan is labelled from the world geometry.
struct TruthOptions {
  /// A primitive is visible when at least this many beams hit it first (fewer hits are a glimpse that
  /// no matcher relies on: a table leg, a wall corner seen edge-on), >= 1.
  std::size_t min_hits_visible = 5;
  double parallel_tol_deg = 10.0;  ///< visible segments within this angle of each other are parallel [deg]
  std::size_t min_hits = 20;       ///< fewer hits in total: the label is "too few hits" (not judged)
};

/// The label of one scan.
struct TruthLabel {
  bool degenerate = false;   ///< every visible primitive is a segment, all parallel (at least one visible)
  bool enough_hits = false;  ///< at least `min_hits` beams hit something
  std::size_t hits = 0;      ///< beams that hit a primitive within range
  std::size_t visible = 0;   ///< primitives hit by at least `min_hits_visible` beams
  /// Direction of the visible walls in the robot frame, (-pi/2, pi/2] [rad] (NaN when not degenerate).
  double direction_rad = std::numeric_limits<double>::quiet_NaN();
};

/// Casts every beam of `laser` (mounted at `laser.T_robot_laser`) from the robot at `T_world_robot`
/// exactly (no noise), finds the primitive each beam hits first (a loop over all primitives), and
/// labels the scan. Arcs (pillars, table legs, curved furniture) are never "parallel walls".
TruthLabel labelFromWorld(const sim::World& world, const SE2& T_world_robot, const sim::LaserModel& laser,
                          const TruthOptions& options = {});

}  // namespace lidar2d::degeneracy
