#pragma once
/// @file
/// The SLAM state: what a run has built that cannot be recomputed (the options, every node with its
/// scan and estimates, the submaps' membership, the constraints and pose-graph edges, the sessions
/// and every scan's estimate), so that a later run can continue the map (`Slam(State, ...)`) and a
/// tracker can localize in it. Node points, lines, submap grids, ICP targets and descriptor indexes
/// are rebuilt on load by the code SLAM builds them with.
///
/// The file (state.l2d; layout in docs/file-formats.md): magic "L2DSLAMS", format version (u32),
/// the lidar2d version (string), payload length (u64, uncompressed), CRC-32 of the compressed
/// payload (u32), compressed length (u64), then the zlib-compressed payload. Little-endian.

#include <cstddef>
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "lidar2d/core/laser_scan.hpp"
#include "lidar2d/core/se2.hpp"
#include "lidar2d/mapping/occupancy_map.hpp"
#include "lidar2d/slam/pose_graph.hpp"
#include "lidar2d/slam/slam.hpp"
#include "lidar2d/slam/slam_options.hpp"

namespace lidar2d::slam {

/// The first 8 bytes of a state file.
inline constexpr std::string_view kStateMagic = "L2DSLAMS";
/// Current version of the state file format; files of any other version are refused.
inline constexpr std::uint32_t kStateFormatVersion = 1;

/// A saved SLAM run (one or more sessions).
struct State {
  /// One log mapped into the state, in order; its scans are `scans[first_scan, next session's first_scan)`.
  struct Session {
    std::string name;  ///< what the caller named it (the CLI: the log's path)
    std::size_t first_scan = 0;
  };
  /// One input scan: the node it hangs off and its pose relative to that node.
  struct Scan {
    std::size_t frame_index = 0;
    double time = 0.0;
    std::size_t node = 0;
    SE2 T_node_scan;
    bool is_node = false;
    bool matched = false;
    bool degenerate = false;
    double seconds = 0.0;
  };
  /// A node with what SLAM needs of its scan. The ranges are stored as 32-bit floats (their
  /// precision, ~1 micrometre at 30 m, is far below any laser's noise); intensities are not kept.
  struct NodeData {
    Node node;
    LaserScan scan;
    SE2 T_robot_laser;
    std::optional<SE2> T_odom_robot;  ///< trusted odometry pose (odometry constraints), if any
    std::size_t frame_index = 0;
    double path_m = 0.0;  ///< front-end path length from the first node [m]
  };
  struct Submap {
    std::size_t anchor = 0;
    std::vector<std::size_t> nodes;
    bool finished = false;
    std::optional<std::size_t> last_link_node;  ///< the latest node a loop closure tied to it
    SE2 last_link_T_anchor_node;
  };
  /// The odometry constraint across the latest lost track while its fragment is untied.
  struct RestartOdometry {
    std::size_t edge = 0, constraint = 0, node = 0;
  };

  SlamOptions options;
  std::vector<Session> sessions;
  std::vector<Scan> scans;
  std::vector<NodeData> nodes;
  std::vector<Submap> submaps;
  std::vector<Constraint> constraints;  ///< accepted and rejected (the report lists both)
  std::vector<PoseGraphEdge> edges;     ///< of the accepted constraints
  std::vector<std::size_t> restarts;    ///< nodes where the front end restarted (lost track or a new session)
  std::vector<Event> events;
  SlamStats stats;
  SE2 T_world_local;
  std::optional<std::size_t> last_loop_node;
  std::optional<std::size_t> untied_since;
  std::optional<RestartOdometry> restart_odometry;
  std::size_t nodes_since_optimization = 0;
  std::size_t loops_since_optimization = 0;
};

/// The state file's bytes (header and compressed payload). Deterministic: the same state gives the
/// same bytes.
std::string encodeState(const State& state);

/// The state in `bytes`, read from `source` (named in errors). Throws `lidar2d::Error` naming
/// `source` and the field: kBadInput for a wrong magic ("not a lidar2d SLAM state file"), a
/// truncated file, a payload length the compressed bytes cannot hold, a checksum mismatch, or
/// contents that do not hold together, whatever the checksum says (an index out of range, a
/// non-finite value, a position beyond 10^7 m, an invalid scan or option, records that contradict
/// each other: docs/file-formats.md); kUnsupported for another format version. Never allocates
/// more than the payload length its compressed bytes can hold.
State decodeState(std::string_view bytes, const std::string& source);

/// Reads and decodes the state file at `path` (decodeState); kIo when it cannot be read.
State readStateFile(const std::string& path);

/// Inserts the scans of the nodes of the first `sessions` sessions (all by default) into `map`, each
/// at its optimised pose (the laser's: `T_world_robot * T_robot_laser`): the saved map as an
/// occupancy grid, with the mapping code `lidar2d slam` writes map.pgm with. The nodes are the scans
/// the motion filter kept (every 0.25 m or 10 degrees by default), not every scan of the logs.
void insertNodeScans(const State& state, mapping::OccupancyMap& map, std::size_t sessions = SIZE_MAX);

}  // namespace lidar2d::slam
