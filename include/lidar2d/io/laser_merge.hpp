#pragma once
/// @file
/// Two or more lasers on one robot (front and rear, say) as one scan in the robot frame.
///
/// The merged scan is *resampled*: its beams are evenly spaced over the full circle around the
/// robot's origin, starting at -pi, with the finest angular step of the inputs rounded so that a
/// whole number of beams fills 2 pi; it is mounted at the robot's origin (T_robot_laser identity).
/// Every consumer (matching, mapping, degeneracy, localization) is written for evenly spaced beams,
/// so this keeps LaserScan as it is, as ROS's laserscan_multi_merger (ira_laser_tools) does. Beam k
/// holds the nearest return of every input point whose bearing from the robot's origin is closest to
/// its angle; the point then lies at its true range on a bearing off by at most half a step (a
/// sideways error of at most r * step / 2: 2.2 cm at 10 m for a 0.25 deg step). A beam with no return
/// but an input's "no return" in its direction reads range_max (mapping clears along it, as for one
/// laser); a beam no input covers reads NaN (invalid, an error reading: nothing is cleared).

#include <vector>

#include "lidar2d/core/laser_scan.hpp"
#include "lidar2d/core/se2.hpp"

namespace lidar2d::io {

/// One input of a merge: a scan in its upright laser frame and where that frame is on the robot at
/// the merged scan's time (the mounting, composed with the robot's motion between the two scans'
/// times when that is known: T_robot(t0)_robot(t) * T_robot_laser).
struct PlacedScan {
  const LaserScan* scan = nullptr;
  SE2 T_robot_laser;
};

/// The merged scan of `inputs` (at least one) at `time` [s], as described in the file comment:
/// angle_min -pi, n = ceil(2 pi / s - 0.001) beams for s the smallest |angle_increment| of the inputs,
/// increment 2 pi / n; range_min 0; range_max the largest input range_max plus that laser's distance
/// from the robot's origin. Intensities are kept when every input has them (the chosen return's).
/// Throws `lidar2d::Error` (kInvalidArgument) when `inputs` is empty or holds a null scan, or when
/// the merged scan would exceed LaserScan::kMaxBeams.
LaserScan mergeScans(const std::vector<PlacedScan>& inputs, double time);

}  // namespace lidar2d::io
