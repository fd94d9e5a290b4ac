#pragma once
/// @file
/// Built-in worlds with a route through each, worlds made from map_server maps, and random walks
/// through a map's free space.
///
/// Built-in worlds (walls are zero-thickness segments; table legs and pillars are circles):
/// - `office`: 20 x 15 m, a 2 m wide east-west corridor (y 6.5..8.5) with four rooms to the south
///   and three to the north, each with a 1 m door, tables (four legs), cabinets, pillars and a
///   curved desk. The route drives the corridor and loops through all seven rooms.
/// - `corridor`: a featureless straight corridor 60 m long (x 0..60) and 2 m wide (y -1..1), open at
///   both ends into an 8 x 8 m room with a pillar, a cabinet and a table. Along the corridor a scan
///   constrains nothing in x: it is the degenerate case. The route loops through the west room,
///   drives the full corridor and loops through the east room.
/// - `symmetric`: a 12 x 12 m block of four identical 6 x 6 m rooms (centred on the origin), each
///   with the same furniture and doors in the same places: the world is invariant under a 90 degree
///   rotation about the origin, so a scan cannot tell the rooms apart. The route loops through all
///   four rooms.
/// - `open`: a 60 x 60 m open area (x, y in -30..30) without outer walls, with a dozen pillars, a
///   short wall and a kiosk; most beams return nothing. The route is a 16 x 16 m square.

#include <Eigen/Core>
#include <cstdint>
#include <string>
#include <vector>

#include "lidar2d/core/occupancy_image.hpp"
#include "lidar2d/sim/world.hpp"

namespace lidar2d::sim {

/// A world with a route through it.
struct Scenario {
  World world;
  std::vector<Eigen::Vector2d> waypoints;  ///< route for `samplePath` [m], world frame
  std::string description;
};

/// Names of the built-in worlds: "office", "corridor", "symmetric", "open".
std::vector<std::string> listWorlds();

/// A built-in world and its route. Throws `lidar2d::Error` (kInvalidArgument) for an unknown name,
/// listing the known ones.
Scenario builtinScenario(const std::string& name);

/// A world whose obstacles are the cells of `map` with value >= `occupied_min` (unknown cells are
/// treated as free space). The obstacles are represented exactly by the cell edges between
/// obstacle and non-obstacle cells (merged into maximal straight runs), so ray casting traverses
/// exactly the occupied cells. Cells on the map's border that are obstacles also get their outer
/// edges.
World worldFromMap(const OccupancyImage& map, int occupied_min = 65, const std::string& name = "map");

struct RandomWalkOptions {
  double length_m = 50.0;       ///< stop once the route is at least this long [m]
  double clearance_m = 0.4;     ///< minimum distance from any non-free cell (occupied or unknown) [m]
  double min_step_m = 1.0;      ///< shortest straight piece [m]
  double max_step_m = 3.0;      ///< longest straight piece [m]
  double heading_sigma_rad = 0.6;  ///< std of the heading change between pieces [rad]
  int free_max = 25;            ///< cells with 0 <= value <= free_max are free
  std::uint64_t seed = 1;
};

/// A route through the free space of `map`: straight pieces of random length and heading whose
/// every point keeps `clearance_m` from non-free cells. Starts at a random cell with that
/// clearance. May return a shorter route when the walk gets stuck (at least two waypoints).
/// Throws `lidar2d::Error` (kBadInput) when no free cell has the clearance.
std::vector<Eigen::Vector2d> randomWalk(const OccupancyImage& map, const RandomWalkOptions& options);

}  // namespace lidar2d::sim
