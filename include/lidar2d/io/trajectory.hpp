#pragma once
/// @file
/// Trajectory files: one pose per line.
/// - `kPlain` (lidar2d's own): `timestamp x y theta` [s, m, m, rad]; `#` starts a comment line.
/// - `kTum`: `timestamp tx ty tz qx qy qz qw` (TUM RGB-D benchmark format), z = 0, rotation about z.
///
/// Also the two other pose files the evaluation reads:
/// - relations files (Kuemmerle et al. 2009, "On measuring the accuracy of SLAM algorithms"):
///   `t1 t2 dx dy dz droll dpitch dyaw` per line, the pose of t2 in the frame of t1;
/// - relative-pose files written by `lidar2d match`: `t_prev t_cur dx dy dtheta converged iterations`.
///
/// Every reader accepts `#` comment lines, blank lines, fields separated by one or more spaces or
/// tabs, and CRLF line ends. Numbers are parsed exactly (std::from_chars); NaN and infinities are
/// rejected. Errors are `lidar2d::Error` (kBadInput, or kIo when the file cannot be opened) whose
/// message names file, 1-based line and field, e.g. `poses.txt:12: field 3 (y): not a number: 'a'`.

#include <cstddef>
#include <string>
#include <vector>

#include "lidar2d/core/trajectory.hpp"

namespace lidar2d::io {

enum class TrajectoryFormat { kPlain, kTum };

/// Reads a trajectory file; the format is detected per file from the number of fields (4 plain,
/// 8 TUM) of the first pose line, and every other pose line must have the same count. TUM
/// quaternions must have unit norm within 1e-3 (they are then normalised); the yaw of the rotation
/// is kept and tz, roll and pitch are ignored. File order is kept (times may repeat or go back).
/// Throws `lidar2d::Error` naming file, line and field on malformed or non-finite values, on a wrong
/// field count, and when the file holds no pose at all.
Trajectory readTrajectory(const std::string& path);

/// Writes a trajectory atomically, with full precision: timestamps with 9 decimals (a time such as
/// 1134864629.895182 reads back to the same double), x, y with 9 decimals [m], theta with 9 decimals
/// [rad]. A `#` header line names the columns. Throws `lidar2d::Error` (kIo) when `path` cannot be
/// written; nothing appears at `path` then.
void writeTrajectory(const std::string& path, const Trajectory& trajectory,
                     TrajectoryFormat format = TrajectoryFormat::kPlain);

/// Reads a relations file: exactly 8 numeric fields per line. Throws `lidar2d::Error` naming file,
/// line and field on malformed values, a wrong field count, or a file without relations.
Relations readRelations(const std::string& path);

/// Reads a `match` output file: `t_prev t_cur dx dy dtheta converged iterations` per line (the last
/// two columns may be left out on every line). `converged` must be 0 or 1, `iterations` a
/// non-negative integer. Throws `lidar2d::Error` naming file, line and field on malformed content
/// or a file without pairs.
std::vector<RelativePose> readRelativePoses(const std::string& path);

/// What a file given as a trajectory or ground truth holds.
enum class PoseFileKind {
  kTrajectory,  ///< a trajectory file (plain or TUM)
  kRelations,   ///< a relations file
  kLog,         ///< not a pose file: a log for `openLog` (binary, compressed, a folder, or text whose
                ///< first data line does not start with a number, such as CARMEN)
};

/// Guesses what `path` holds without parsing all of it: folders, gzip, ROS bags and SQLite files are
/// logs; a text file is a relations file when its name ends in `.relations`, or when its first
/// data line has 8 numeric fields of which the last four do not form a unit quaternion within 1e-3
/// (so it cannot be TUM); a text file whose first data line starts with a number is a trajectory
/// (an empty one too: readTrajectory reports it); text whose first data line starts with an
/// upper-case word (a CARMEN message name such as PARAM or FLASER) is a log; any other text is a
/// malformed trajectory (kTrajectory, so that readTrajectory names the line and field). Throws `lidar2d::Error` (kIo) when `path` does not exist or cannot be read.
PoseFileKind detectPoseFile(const std::string& path);

}  // namespace lidar2d::io
