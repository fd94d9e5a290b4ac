#pragma once
/// @file
/// An occupancy map from a stream of frames at known poses: the pose of each frame (its own truth or
/// odometry, or a trajectory's), and a pipeline in which a second thread reads and prepares the
/// scans a few ahead while the calling thread inserts them. The map is the same as inserting every
/// frame with `OccupancyMap::insert(frame.scan, T_world_robot * frame.T_robot_laser)` in order.

#include <cstddef>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "lidar2d/core/frame.hpp"
#include "lidar2d/core/se2.hpp"
#include "lidar2d/core/trajectory.hpp"
#include "lidar2d/mapping/occupancy_map.hpp"

namespace lidar2d::mapping {

/// Which of a frame's own poses places it in the map.
enum class PoseSource {
  kAuto,      ///< the truth (`Frame::T_world_robot`) when the frame has one, else its odometry
  kTruth,     ///< `Frame::T_world_robot`
  kOdometry,  ///< `Frame::T_odom_robot`
};

/// The pose T_world_robot of each frame: one of the frame's own poses, or a trajectory's.
class FramePoses {
 public:
  /// Each frame's own pose of `source`. `hint`, when not empty, is appended in parentheses to the
  /// error of a frame lacking that pose (the caller's advice on giving poses another way).
  static FramePoses fromFrames(PoseSource source = PoseSource::kAuto, std::string hint = {});
  /// The poses of `trajectory`: for a frame, the pose at its `Frame::index` when that pose's time is
  /// within `max_dt_s` of the frame's (so that logs whose timestamps repeat stay unambiguous), else
  /// the pose of the nearest time within `max_dt_s` (`TimeIndex`). `name` names the trajectory in
  /// errors (e.g. its file). A negative or NaN `max_dt_s` matches no pose.
  static FramePoses fromTrajectory(Trajectory trajectory, double max_dt_s, std::string name = {});

  /// T_world_robot of `frame`. Throws `lidar2d::Error` (kBadInput) when there is none: from the
  /// frame's poses, "scan N (time T) has no truth|odometry pose" with no file (the caller names the
  /// frames' source; `MapBuilder` does); from a trajectory, "has no pose within D s of scan N (time
  /// T)" at the trajectory's name, field "timestamp".
  SE2 T_world_robot(const Frame& frame) const;

 private:
  FramePoses() = default;
  PoseSource source_ = PoseSource::kAuto;
  std::string hint_;
  // With a trajectory:
  std::shared_ptr<const Trajectory> trajectory_;  // (shared: copies of the poses share it)
  std::shared_ptr<const TimeIndex> index_;
  double max_dt_s_ = 0.0;
  std::string name_;
};

/// Options of `MapBuilder`.
struct MapBuilderOptions {
  std::string source_name;      ///< names the frames' source in errors (e.g. the log's path)
  std::size_t read_ahead = 16;  ///< scans read and prepared ahead of the one being inserted (>= 1)
};

/// Inserts every frame of a stream into a map at its pose (`FramePoses`). A second thread pulls the
/// frames, looks up their poses and prepares them (`OccupancyMap::prepare`, which reads no map
/// state), up to `read_ahead` scans ahead; the calling thread inserts them in stream order, so the
/// map is identical to inserting each frame in turn. Prepared scans are recycled (their buffers,
/// and the beam directions while the scan angles stay the same). Non-copyable; use from one thread.
class MapBuilder {
 public:
  /// The next frame of the stream, or std::nullopt at its end (e.g. a log reader's `next()`).
  /// Called on the builder's second thread, one call at a time.
  using FrameStream = std::function<std::optional<Frame>()>;
  /// Called on the calling thread after each inserted scan with the number inserted so far by
  /// this `insert` call.
  using Progress = std::function<void(std::size_t scans_inserted)>;

  /// `map` must outlive the builder; the builder is its only user while `insert` runs.
  MapBuilder(OccupancyMap& map, FramePoses poses, MapBuilderOptions options = {});
  ~MapBuilder();
  MapBuilder(const MapBuilder&) = delete;
  MapBuilder& operator=(const MapBuilder&) = delete;

  /// Inserts every frame of `frames` at T_world_robot * T_robot_laser; returns the number of
  /// scans inserted (0 for an empty stream). Errors: an exception `frames` throws is rethrown as
  /// is; a frame without a pose throws the `FramePoses` error, with `source_name` as its file when
  /// it has none; a scan the map rejects (a pose not finite or too far out, an extent over the cell
  /// budget) throws the map's `lidar2d::Error` at `source_name`, field "scan N (time T) <field>".
  /// The scans before the failing one stay inserted.
  std::size_t insert(const FrameStream& frames, const Progress& progress = {});

  const OccupancyMap& map() const { return map_; }

 private:
  OccupancyMap& map_;
  const FramePoses poses_;
  const MapBuilderOptions options_;
  std::vector<std::unique_ptr<OccupancyMap::PreparedScan>> spare_;  // prepared scans to reuse
};

}  // namespace lidar2d::mapping
