#pragma once
// The first stage of the CARMEN reader (private to io): a log's lines parsed into events (laser
// messages as scans, ODOM and TRUEPOS samples, the lidar2d writer's marker); carmen_reader.cpp
// turns the events into frames. Message layouts and the parsing rules: carmen_messages.cpp.

#include <cstddef>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "lidar2d/core/laser_scan.hpp"
#include "lidar2d/core/se2.hpp"

namespace lidar2d::io::internal {
class TextLineReader;
}  // namespace lidar2d::io::internal

namespace lidar2d::io::internal::carmen {

enum class LaserKind { kFront, kRear, kRobot, kRaw };

struct LaserType {
  std::string_view name;
  LaserKind kind;
  int number;  // RAWLASER/ROBOTLASER number; 1 = front, 2 = rear
};

// The laser message type of a message tag ("FLASER", ...), or nullptr for any other tag.
const LaserType* laserType(std::string_view tag);

inline bool hasPoseFields(const LaserType& t) { return t.kind != LaserKind::kRaw; }

struct OdomSample {
  double time = 0.0;
  SE2 pose;
};

struct LaserMsg {
  double time = 0.0;
  LaserScan scan;
  std::optional<SE2> pose;  // FLASER x y theta / ROBOTLASER robot pose
  std::optional<SE2> odom;  // FLASER odom triple / ROBOTLASER robot pose
  SE2 T_robot_laser;
};

// PARAM values that matter for FLASER/RLASER/RAWLASER (index 0 = front, 1 = rear).
struct Params {
  double offset_x[2] = {0.0, 0.0};
  double offset_y[2] = {0.0, 0.0};
  double offset_theta[2] = {0.0, 0.0};
  std::optional<double> resolution_deg[2];
  std::optional<double> fov_deg[2];
  std::optional<double> max_range[2];
};

// One line's meaning.
struct Event {
  enum Kind { kNone, kLaser, kOtherLaser, kOdom, kTruth, kMarker } kind = kNone;
  const LaserType* laser_type = nullptr;
  LaserMsg laser;
  OdomSample sample;  // ODOM pose, or TRUEPOS truth
  std::size_t line = 0;
};


// Reads a log line by line and turns the lines into events. `selected` is the laser message type
// to parse (others are skipped unparsed); when null, the first laser message type found is taken.
// PARAM lines set the mounting, beam angles and maximum range of the laser messages after them.
// Throws `lidar2d::Error` naming the file, line and field for a missing or unreadable file, binary
// content, corrupt compressed data and malformed messages.
class EventReader {
 public:
  EventReader(const std::string& path, const LaserType* selected);
  ~EventReader();
  EventReader(const EventReader&) = delete;
  EventReader& operator=(const EventReader&) = delete;

  // The next event (never kNone); false at the end of the log.
  bool next(Event& ev);
  const LaserType* selected() const { return selected_; }
  // Lines read so far (the number of the last line).
  std::size_t lineNo() const;

 private:
  bool classify(std::string_view line, Event& ev);

  std::string path_;
  std::unique_ptr<TextLineReader> in_;
  const LaserType* selected_;
  Params params_;
  std::vector<std::string_view> fields_;
};

}  // namespace lidar2d::io::internal::carmen
