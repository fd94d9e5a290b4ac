#pragma once
// What the ROS1 and ROS2 bag readers share once messages are decoded: topic choice, the laser
// mounting pose from tf, odometry interpolation at scan stamps, and LaserScan conversion. Only the
// bag readers include this.

#include <Eigen/Geometry>
#include <cstddef>
#include <cstdint>
#include <deque>
#include <map>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "lidar2d/core/error.hpp"
#include "lidar2d/core/frame.hpp"
#include "lidar2d/core/laser_mount.hpp"
#include "lidar2d/core/se2.hpp"
#include "lidar2d/io/frame_source.hpp"
#include "src/io/internal/ros_messages.hpp"

namespace lidar2d::io::internal {

/// A topic of a bag: name, message type as stored ("sensor_msgs/LaserScan" or
/// "sensor_msgs/msg/LaserScan") and number of messages.
struct RosTopicInfo {
  std::string name;
  std::string type;
  std::uint64_t count = 0;
};

/// Picks the topic to read among `topics` whose type is one of `types`.
/// - `requested` empty: the topic with the most messages (ties: the first listed); when there are
///   several, a note naming the choice is appended to `warnings`. Returns std::nullopt when there
///   is no such topic.
/// - `requested` "none" (only when `allow_none`): std::nullopt.
/// - otherwise the topic of that name; throws lidar2d::Error naming `path` and listing the topics
///   of the wanted types when it does not exist or has another type.
/// `what` names the kind in messages ("LaserScan", "Odometry"), `option` the override
/// ("--scan-topic").
std::optional<RosTopicInfo> chooseRosTopic(const std::vector<RosTopicInfo>& topics,
                                           const std::vector<std::string>& types, const std::string& requested,
                                           bool allow_none, const std::string& what, const std::string& option,
                                           const std::string& path, std::vector<std::string>& warnings);

/// The SourceNotes of a ROS reader: `base` plus the frame assembler's warnings and the counts of
/// negative ranges and zero header stamps (shared by the ROS1 and ROS2 readers).
SourceNotes rosNotes(SourceNotes base, std::vector<std::string> assembler_warnings, std::size_t negative_ranges,
                     std::size_t zero_stamps);

/// The LaserScan and Odometry topics of a bag (shared by the ROS1 and ROS2 readers): `chooseRosTopic`
/// for each, with `options.scan_topic` / `options.odom_topic`; a bag without a LaserScan topic is an
/// error naming `path` and listing every topic with its type.
struct RosTopicChoice {
  RosTopicInfo scan;
  std::optional<RosTopicInfo> odom;
};
RosTopicChoice chooseScanAndOdometry(const std::vector<RosTopicInfo>& topics, const std::string& scan_type,
                                     const std::string& odom_type, const ReaderOptions& options,
                                     const std::string& path, std::vector<std::string>& warnings);

/// `chooseScanAndOdometry` over a reader's own topic records (each with an `info` member): the
/// chosen scan topic's record and the odometry topic's, or nullptr when there is none. The records
/// must outlive the returned pointers. `lasers` (SourceNotes::lasers) receives every topic of
/// `scan_type` with its message count.
template <class Topic>
struct RosTopicPick {
  const Topic* scan = nullptr;
  const Topic* odom = nullptr;
};
template <class Topic>
RosTopicPick<Topic> pickScanAndOdometry(const std::vector<Topic>& topics, const std::string& scan_type,
                                        const std::string& odom_type, const ReaderOptions& options,
                                        const std::string& path, std::vector<std::string>& warnings,
                                        std::vector<std::string>& lasers) {
  std::vector<RosTopicInfo> infos;
  infos.reserve(topics.size());
  for (const auto& t : topics) {
    infos.push_back(t.info);
    if (t.info.type == scan_type) lasers.push_back(t.info.name + " (" + std::to_string(t.info.count) + " messages)");
  }
  const RosTopicChoice choice = chooseScanAndOdometry(infos, scan_type, odom_type, options, path, warnings);
  auto find = [&](const std::string& name) {
    for (const auto& t : topics)
      if (t.info.name == name) return &t;
    return static_cast<const Topic*>(nullptr);
  };
  RosTopicPick<Topic> pick{find(choice.scan.name), choice.odom ? find(choice.odom->name) : nullptr};
  if (!pick.scan || (choice.odom && !pick.odom)) throw badInput("internal: topic vanished", {path});
  return pick;
}

/// Planar projection of a 3D pose (odometry): (x, y, yaw), yaw from the quaternion (ZYX convention).
SE2 projectToPlane(const RosTransform3& t);

/// A tf tree built from tf2_msgs/TFMessage transforms (each child has one parent; a later transform
/// of the same child replaces the earlier one, as tf2's static buffer does).
class RosTfTree {
 public:
  /// `file` names the bag in errors.
  explicit RosTfTree(std::string file = {}) : file_(std::move(file)) {}
  void add(const RosTransformStamped& t);
  bool hasFrame(const std::string& frame) const;
  std::size_t size() const { return parent_of_.size(); }

  struct Lookup {
    Eigen::Isometry3d T_from_to = Eigen::Isometry3d::Identity();  ///< pose of frame `to` in frame `from`, 3D
    std::vector<std::string> chain;  ///< frames visited from `from` to `to`
  };
  /// The transform from `from` to `to` through their common ancestor, composed in 3D (so a chain
  /// through an upside-down plate keeps its mirror), or std::nullopt when they are not connected.
  /// Throws lidar2d::Error (kBadInput, field "tf PARENT -> CHILD") when a transform on the chain has
  /// a non-finite value or a quaternion that is not of unit length (tf2's tolerance: |q|^2 within
  /// 0.01 of 1); such a transform elsewhere in the tree is ignored, as it does not matter here.
  std::optional<Lookup> lookup(const std::string& from, const std::string& to) const;

 private:
  struct Edge {
    std::string parent;
    RosTransform3 T_parent_child;
  };
  Eigen::Isometry3d checked(const std::string& child, const Edge& e) const;
  std::string file_;
  std::map<std::string, Edge> parent_of_;  // child -> parent edge
};

/// Finds the laser mounting in `tree`. Tries `robot_frames` in order; returns the first that is
/// connected to `laser_frame`, with a human-readable description of the chain. Identity and no
/// chain when `laser_frame` is one of the robot frames.
struct RosMount {
  LaserMount mount;         ///< the chain's 3D transform robot <- laser (tilt not yet ruled on)
  std::string robot_frame;
  std::string description;  ///< e.g. "base_link -> laser"; empty when not found
  bool found = false;
};
RosMount findRosMount(const RosTfTree& tree, const std::vector<std::string>& robot_frames,
                      const std::string& laser_frame);

/// The mounting a ROS reader's frames get: identity when `options.laser_mount` replaces the bag's
/// (openLog applies that one), else `mount.mount` under the tilt rule (applyTiltRule; an error
/// names `path` and the chain).
LaserMount rosFrameMount(const RosMount& mount, const ReaderOptions& options, const std::string& path,
                         std::vector<std::string>& warnings);

/// Fills `notes.scan_source` and, when `odom_topic` is not empty, `notes.odom_source` with the
/// topics, their message types, frames and mounting the reader found (shared by the ROS1 and ROS2 readers).
void describeRosSources(SourceNotes& notes, const std::string& scan_topic, const std::string& scan_type,
                        const std::string& laser_frame, const RosMount& mount, const std::string& odom_topic,
                        const std::string& odom_type, const std::string& robot_frame);
/// Completes `mount.description` with the topic it came from (`source`, e.g. "/tf_static") and
/// whether the laser is upside down, and appends to `warnings` when no mounting was found (identity
/// used). The tilt is ruled on by rosFrameMount.
void noteRosMount(RosMount& mount, const std::string& source, const std::vector<std::string>& robot_frames,
                  const std::string& laser_frame, std::vector<std::string>& warnings);

/// A scan message turned into checked lidar2d types; throws lidar2d::Error naming `ref` when the
/// scan violates LaserScan's invariants. `negative_ranges` is increased by the number of negative
/// finite ranges (kept as they are: LaserScan treats them as invalid since range_min >= 0).
LaserScan toLaserScan(const RosLaserScanMsg& m, double time, const RosMessageRef& ref, std::size_t& negative_ranges);

/// Turns time-ordered scan and odometry messages into Frames in scan order, with the odometry pose
/// interpolated at each scan's time. Memory is bounded: at most kMaxPendingScans scans wait for a
/// later odometry message, and odometry older than the oldest waiting scan (minus a margin) is
/// dropped.
///
/// Interpolation (documented once here, the test expectations use the same rule): with o0 the last
/// odometry message at or before the scan time t and o1 the first at or after it,
/// a = (t - t0) / (t1 - t0), x and y are linear in a and yaw = yaw0 + a * wrap(yaw1 - yaw0).
/// Before the first / after the last odometry message the nearest message's pose is used, and
/// scans more than kMaxOdomGapS away from it are counted in a warning.
class RosFrameAssembler {
 public:
  static constexpr std::size_t kMaxPendingScans = 512;
  static constexpr double kMaxOdomGapS = 0.5;

  /// Every frame gets `mount` (already ruled on: rosFrameMount), its scan projected with it.
  RosFrameAssembler(LaserMount mount, bool use_odometry);

  /// A scan (already converted) with its frame time [s].
  void pushScan(LaserScan scan, double time);
  /// An odometry message at time `time` [s] with pose T_odom_robot.
  void pushOdometry(double time, const SE2& T_odom_robot);
  /// No more messages will come.
  void finish() { finished_ = true; }
  /// The next frame when it can be completed now.
  std::optional<Frame> pop();
  /// Warnings collected so far (odometry gaps, out-of-order odometry).
  std::vector<std::string> warnings() const;

 private:
  struct Pending {
    LaserScan scan;
    double time;
  };
  struct Odom {
    double time;
    SE2 pose;
  };
  std::optional<SE2> interpolate(double t);
  void prune();

  LaserMount mount_;
  bool use_odometry_;
  bool finished_ = false;
  std::deque<Pending> pending_;
  std::deque<Odom> odom_;  // sorted by time
  double newest_odom_time_ = 0.0;
  std::size_t next_index_ = 0;
  std::size_t gap_scans_ = 0;
  double max_gap_ = 0.0;
  std::size_t odom_out_of_order_ = 0;
  std::size_t forced_ = 0;
};

/// The part of a ROS bag reader that does not depend on the container (shared by the ROS1 and ROS2
/// readers): frames come from a RosFrameAssembler fed with the decoded scan and odometry messages;
/// a header stamp of 0 is replaced by the message's bag time (and counted). A reader implements
/// `feed()` (decode the next message of its container with `pushScan` / `pushOdometry`, or return
/// false at the end) and `format()`, and sets the protected members in its constructor.
class RosMessageSource : public FrameSource {
 public:
  std::optional<Frame> next() override;
  std::optional<std::size_t> sizeHint() const override { return size_hint_; }
  const std::string& path() const override { return path_; }
  SourceNotes notes() const override;

 protected:
  explicit RosMessageSource(std::string path) : path_(std::move(path)) {}
  /// Reads the next scan or odometry message into the assembler; false when there is none left.
  virtual bool feed() = 0;
  void pushScan(std::span<const std::uint8_t> bytes, RosWire wire, const RosMessageRef& ref, RosNanos bag_time);
  void pushOdometry(std::span<const std::uint8_t> bytes, RosWire wire, const RosMessageRef& ref, RosNanos bag_time);

  std::string path_;
  std::optional<std::size_t> size_hint_;
  RosFrameAssembler assembler_{LaserMount(), false};
  SourceNotes notes_;

 private:
  RosNanos stampOr(RosNanos stamp, RosNanos bag_time);

  std::size_t negative_ranges_ = 0, zero_stamps_ = 0;
  bool done_ = false;
};

}  // namespace lidar2d::io::internal
