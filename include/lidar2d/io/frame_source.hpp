#pragma once
/// @file
/// One streaming interface over every log format, so that no algorithm knows where scans come from.

#include <cmath>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "lidar2d/core/frame.hpp"
#include "lidar2d/core/laser_mount.hpp"

namespace lidar2d::io {

enum class LogFormat {
  kCarmen,   ///< CARMEN text log (.log/.clf), plain or gzip-compressed
  kRosbag1,  ///< ROS1 bag, format 2.0 or 1.2
  kRosbag2,  ///< ROS2 bag: a folder with metadata.yaml (sqlite3 or MCAP storage, split or compressed
             ///< by rosbag2), or a single .db3 or .mcap file
  /// Plain range tables (a folder with poses.txt, angles.txt and ranges.txt, or the three files
  /// named in ReaderOptions::range_table): the layout robotics courses and MATLAB users keep.
  kRangeTable,
};

/// Printable name of a format ("carmen", "rosbag1", "rosbag2", "range-table").
const char* toString(LogFormat f);

/// How the pose triples of CARMEN laser messages are interpreted.
enum class CarmenPoses {
  /// TRUEPOS lines give truth when present. Otherwise, when the log also has ODOM lines whose motion
  /// disagrees with the laser messages' poses (logs corrected by a SLAM system, as in Radish), the
  /// robot's poses under those laser poses are taken as truth and odometry is interpolated from the
  /// ODOM lines; else the laser messages' odometry triple is odometry and there is no truth.
  /// FLASER/RLASER's first triple is the laser's pose: the robot's is that less the mounting.
  kAuto,
  kTruth,     ///< the laser messages' robot pose is ground truth; odometry from ODOM lines if any
  kOdometry,  ///< the laser messages' odometry triple is odometry; no truth unless TRUEPOS lines
};

/// The three files of a range table, each plain text (comma or blank separated numbers, '#'
/// comment lines and blank lines skipped, plain or gzip):
/// - `poses`: one robot pose `x y theta` [m, m, rad] per scan, in the world frame: the truth;
/// - `angles`: one line of beam angles [rad] in the laser frame, evenly spaced, increasing;
/// - `ranges`: one line of ranges [m] per scan, as many as there are angles; readings at or beyond
///   `range_max_m` mean no return, 0 is an error reading (both invalid). NaN, infinite or negative
///   values are errors.
/// The tables hold no times: scan k gets the time k / rate_hz. The laser sits at the robot's origin.
struct RangeTableFiles {
  std::string poses;
  std::string angles;
  std::string ranges;
  double rate_hz = 10.0;      ///< scan rate of the synthesized times [Hz], > 0
  double range_max_m = 30.0;  ///< readings >= this are "no return" [m] (a Hokuyo UTM-30LX's 30 m)
};

/// Options of every reader; each reader ignores what does not apply to its format.
struct ReaderOptions {
  std::string scan_topic;  ///< ROS: LaserScan topic; empty = the only/most frequent one
  std::string odom_topic;  ///< ROS: Odometry topic; empty = auto-detect, "none" = ignore odometry
  std::string carmen_laser;  ///< CARMEN: message to read ("FLASER", "RLASER", "ROBOTLASER1", ...);
                             ///< empty = the first laser message type found in the file
  CarmenPoses carmen_poses = CarmenPoses::kAuto;
  /// The laser's mounting on the robot for every frame, replacing what the log says (a ROS bag's
  /// tf, a CARMEN log's front-laser offset); std::nullopt keeps the log's. Only the mounting changes
  /// (and with it the scan when the laser is upside down or tilted, `LaserMount::project`): the
  /// odometry and truth poses stay as the log gives them. (For a log whose calibration is wrong or
  /// missing: the fr079 bag's tf puts the laser 4 cm ahead of base_link, the original CARMEN log
  /// 4 cm behind the robot's centre, docs/slam.md; CARMEN logs cannot say that a laser is upside
  /// down.) Its tilt is subject to the rule below like the log's.
  std::optional<LaserMount> laser_mount;
  /// A scan plane tilted from the robot's plane by at most this is taken as level: the mounting's
  /// tilt is dropped (`LaserMount::levelled`) [deg], in [0, 45].
  double max_laser_tilt_deg = 2.0;
  /// A laser tilted by more than max_laser_tilt_deg: false refuses the log (kBadInput naming the
  /// mounting), true projects its beams onto the robot's plane (`LaserMount::project`, each range
  /// shortened by the tilt) and says so in the notes' warnings.
  bool allow_tilted_laser = false;
  /// The laser's range max [m], replacing the log's (CARMEN FLASER/RLASER: 80 m or a PARAM;
  /// ROBOTLASER and ROS bags: each message's own): readings at or beyond it are no return, those
  /// below it (and above range_min) valid. Above the log's no-return code, that code becomes a
  /// return. Finite, in (0, kMaxLaserRangeMax]; std::nullopt: the log's, except where a CARMEN
  /// log's first 300 scans contradict it (1% of their beams or more read beyond it, and a no-return
  /// code lies above all of them: the range max becomes 99% of that code, and the notes' warnings
  /// say so; docs/file-formats.md). Where other readings beyond it remain, the notes warn
  /// (`beams_beyond_range_max`).
  std::optional<double> laser_range_max;
  /// A range table given file by file; when set, `openLog` reads it whatever its path argument.
  std::optional<RangeTableFiles> range_table;

  /// Two or more lasers on one robot, merged into one scan per frame in the robot frame
  /// (io/laser_merge.hpp; docs/file-formats.md, "Two or more lasers"): their LaserScan topics (ROS
  /// bags) or CARMEN laser messages ("FLASER", "RLASER"), replacing scan_topic / carmen_laser. The
  /// first laser's scans give the frames (time, odometry, truth); each other laser contributes its
  /// scan nearest in time, within laser_sync_tolerance_s. Empty or one name: a single laser.
  std::vector<std::string> lasers;
  /// Empty, or one mounting per entry of `lasers` replacing the log's (as laser_mount does for one
  /// laser). Without them each laser's mounting must come from the log (tf; CARMEN's conventions).
  std::vector<LaserMount> laser_mounts;
  /// Largest time difference between the first laser's scan and another laser's scan merged into
  /// it [s], > 0; a scan of the first laser with no partner that close is left out (counted in the
  /// notes' warnings).
  double laser_sync_tolerance_s = 0.05;
  /// A ROS bag whose tf does not connect the robot to the laser is an error (kBadInput) instead of
  /// a warning with the identity mounting (set for each laser of a merge; a wrong mounting would
  /// misplace one laser's points against the other's).
  bool require_laser_mount = false;
};

/// The farthest a laser may be mounted from the robot's frame origin: `ReaderOptions::laser_mount`
/// beyond it is an error (a mistyped unit, not a robot) [m].
inline constexpr double kMaxLaserMountOffset = 100.0;
/// The largest `ReaderOptions::laser_range_max` accepted [m]: no 2D laser measures a kilometre.
inline constexpr double kMaxLaserRangeMax = 1000.0;

/// Whether a mounting offset (x, y) [m] is within kMaxLaserMountOffset on both axes (false for NaN).
inline bool laserMountOffsetOk(double x, double y) {
  return std::abs(x) <= kMaxLaserMountOffset && std::abs(y) <= kMaxLaserMountOffset;
}

/// Facts a reader learns about its log (some only once the stream is exhausted).
struct SourceNotes {
  std::string scan_source;   ///< e.g. "FLASER" or "/scan"
  std::string odom_source;   ///< e.g. "ODOM lines (interpolated)", "/odom", or empty if none
  /// e.g. "FLASER pose less the laser mounting (corrected log)", "TRUEPOS", or empty if none
  std::string truth_source;
  std::string container;     ///< how the log is stored when there is a choice, e.g. "mcap storage, 2 files"
  /// e.g. "timestamps repeat (12 times)"; openLog adds readings beyond the range max that are not
  /// the no-return code (1% of the beams or more) and timestamps that repeat or go backwards
  std::vector<std::string> warnings;
  /// Readings at or beyond their scan's range max other than the log's no-return code (the most
  /// frequent reading there): returns a declared range max too low discards (counted by openLog).
  std::size_t beams_beyond_range_max = 0;
  /// Every laser the log holds, with its message count, e.g. "/scan_front (120 messages)" (ROS bags:
  /// the LaserScan topics; CARMEN logs: the laser message types, complete once the log is read).
  std::vector<std::string> lasers;
};

/// A stream of frames in file order. Memory use does not grow with the log's length.
class FrameSource {
 public:
  virtual ~FrameSource() = default;
  FrameSource() = default;
  FrameSource(const FrameSource&) = delete;
  FrameSource& operator=(const FrameSource&) = delete;

  /// The next frame, or std::nullopt at the end of the log. Throws `lidar2d::Error` (naming file,
  /// line or message number, and field) on malformed content.
  virtual std::optional<Frame> next() = 0;
  virtual LogFormat format() const = 0;
  /// The path the source was opened with.
  virtual const std::string& path() const = 0;
  /// What was learned so far (complete once `next()` has returned std::nullopt).
  virtual SourceNotes notes() const = 0;
  /// How many frames the source expects to deliver, when it knows without reading them (ROS bags:
  /// the scan topic's message count in the index), else std::nullopt (CARMEN text logs). For
  /// progress display only: the stream may end earlier (a message that fails to decode throws).
  virtual std::optional<std::size_t> sizeHint() const { return std::nullopt; }
};

/// Detects the format from the file's first bytes (gzip magic -> CARMEN, "#ROSBAG V" -> ROS1,
/// SQLite header or a folder with metadata.yaml -> ROS2, a folder with poses.txt, angles.txt and
/// ranges.txt -> range table). Throws `lidar2d::Error` for a missing,
/// unreadable or empty file, a directory that is not a ROS2 bag, or unknown content.
LogFormat detectFormat(const std::string& path);

/// Opens any supported log. Throws `lidar2d::Error` as `detectFormat` and the readers do.
std::unique_ptr<FrameSource> openLog(const std::string& path, const ReaderOptions& options = {});

}  // namespace lidar2d::io
